"""Reports people read: a batch of fits as one executed notebook, in HTML or ``.ipynb``."""

from ._collect import CaptureResult as CaptureResult
from ._collect import flag_outliers as flag_outliers
from ._collect import load_fits as load_fits
from ._render import write_report as write_report
from ._sections import batch_section as batch_section
from ._sections import capture_section as capture_section

__all__ = [
    "CaptureResult",
    "flag_outliers",
    "load_fits",
    "write_report",
    "batch_section",
    "capture_section",
]
