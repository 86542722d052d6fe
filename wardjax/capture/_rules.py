"""The rules of :mod:`wardjax._rules`, by the name the capture stage and its callers import them.

The rules live in the package's base, so that :class:`~wardjax.WardParams` and the file readers apply
them too; this module names them for ``capture.toml``'s loader and the stages after it.
"""

from .._rules import LIMITS as LIMITS
from .._rules import MAX_CLIPPED_FRACTION as MAX_CLIPPED_FRACTION
from .._rules import MAX_DISTANCE_MM as MAX_DISTANCE_MM
from .._rules import MAX_FOV_DEG as MAX_FOV_DEG
from .._rules import MAX_HELD_OUT_DELTA_E as MAX_HELD_OUT_DELTA_E
from .._rules import MAX_MESSAGE_CHARS as MAX_MESSAGE_CHARS
from .._rules import MAX_STRAY_FRACTION as MAX_STRAY_FRACTION
from .._rules import MIN_FOV_DEG as MIN_FOV_DEG
from .._rules import MIN_REGION_PIXELS as MIN_REGION_PIXELS
from .._rules import RHO_NOISE as RHO_NOISE
from .._rules import RuleError as RuleError
from .._rules import check_camera_correction as check_camera_correction
from .._rules import check_count as check_count
from .._rules import check_focal_px as check_focal_px
from .._rules import check_image_pair as check_image_pair
from .._rules import check_lit_exposure as check_lit_exposure
from .._rules import check_memory as check_memory
from .._rules import check_path_name as check_path_name
from .._rules import check_photo_region as check_photo_region
from .._rules import check_position as check_position
from .._rules import check_rho_d_map as check_rho_d_map
from .._rules import check_rho_sum as check_rho_sum
from .._rules import check_ward_arrays as check_ward_arrays
from .._rules import check_ward_params as check_ward_params
from .._rules import one_line as one_line
from .._rules import shorten as shorten

__all__ = [
    "LIMITS",
    "MAX_DISTANCE_MM",
    "MAX_HELD_OUT_DELTA_E",
    "MIN_REGION_PIXELS",
    "RHO_NOISE",
    "MAX_FOV_DEG",
    "MAX_CLIPPED_FRACTION",
    "MIN_FOV_DEG",
    "RuleError",
    "check_camera_correction",
    "check_count",
    "check_focal_px",
    "check_memory",
    "check_path_name",
    "check_rho_sum",
    "check_ward_arrays",
    "check_image_pair",
    "check_lit_exposure",
    "check_photo_region",
    "check_position",
    "check_rho_d_map",
    "check_ward_params",
    "one_line",
    "shorten",
]
