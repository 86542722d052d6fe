"""The capture folder: ``capture.toml`` (both methods) and its images, validated on load."""

from ._errors import CAPTURE_FILE as CAPTURE_FILE
from ._errors import CaptureError as CaptureError
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

__all__ = [
    "CAPTURE_FILE",
    "CaptureError",
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
]
