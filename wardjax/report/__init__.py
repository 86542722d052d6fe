"""Reports people read: a batch of fits as one executed notebook, in HTML or ``.ipynb``."""

from ._collect import CaptureResult as CaptureResult
from ._collect import flag_outliers as flag_outliers
from ._collect import load_chains as load_chains
from ._collect import load_fits as load_fits
from ._collect import split_rhat as split_rhat
from ._render import write_report as write_report
from ._sections import batch_section as batch_section
from ._sections import capture_section as capture_section

__all__ = [
    "CaptureResult",
    "flag_outliers",
    "load_chains",
    "load_fits",
    "split_rhat",
    "write_report",
    "batch_section",
    "capture_section",
]
