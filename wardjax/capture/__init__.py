"""The capture folder: ``capture.toml`` (both methods) and its images, validated on load."""

from ._errors import CAPTURE_FILE as CAPTURE_FILE
from ._errors import CaptureError as CaptureError
from ._images import CaptureImages as CaptureImages
from ._images import ImageSource as ImageSource
from ._images import Window as Window
from ._load import IMAGE_SUFFIXES as IMAGE_SUFFIXES
from ._load import Capture as Capture
from ._load import load_capture as load_capture
from ._schema import CaptureFile as CaptureFile
from ._schema import parse_capture_file as parse_capture_file
from ._setup import MM_PER_IN as MM_PER_IN
from ._setup import Display as Display
from ._setup import Viewing as Viewing
from ._setup import load_display as load_display
from ._setup import load_viewing as load_viewing
from ._smartphone import SmartphoneCapture as SmartphoneCapture
from ._smartphone import SmartphoneCaptureFile as SmartphoneCaptureFile
from ._smartphone import grid_boxes as grid_boxes
from ._exif import Exif as Exif
from ._exif import read_exif as read_exif
from ._exif import relative_exposure as relative_exposure
from ._photo import PhotoCapture as PhotoCapture
from ._photo_schema import FlashFile as FlashFile
from ._photo_schema import MultiviewFile as MultiviewFile
from ._vignetting import Vignetting as Vignetting
from ._vignetting import fit_vignetting as fit_vignetting
from ._import import import_capture as import_capture
from .._rules import MAX_CLIPPED_FRACTION as MAX_CLIPPED_FRACTION
from .._rules import RuleError as RuleError
from .._rules import check_focal_px as check_focal_px
from .._rules import check_image_pair as check_image_pair
from .._rules import check_lit_exposure as check_lit_exposure
from .._rules import check_photo_region as check_photo_region
from .._rules import check_position as check_position
from .._rules import check_rho_d_map as check_rho_d_map
from .._rules import check_ward_params as check_ward_params
from .._rules import one_line as one_line

__all__ = [
    "CAPTURE_FILE",
    "CaptureError",
    "CaptureImages",
    "ImageSource",
    "Window",
    "IMAGE_SUFFIXES",
    "Capture",
    "load_capture",
    "CaptureFile",
    "parse_capture_file",
    "MM_PER_IN",
    "Display",
    "Viewing",
    "load_display",
    "load_viewing",
    "SmartphoneCapture",
    "SmartphoneCaptureFile",
    "grid_boxes",
    "Exif",
    "read_exif",
    "relative_exposure",
    "PhotoCapture",
    "FlashFile",
    "MultiviewFile",
    "Vignetting",
    "fit_vignetting",
    "import_capture",
    "MAX_CLIPPED_FRACTION",
    "RuleError",
    "check_focal_px",
    "check_image_pair",
    "check_lit_exposure",
    "check_photo_region",
    "check_position",
    "check_rho_d_map",
    "check_ward_params",
    "one_line",
]
