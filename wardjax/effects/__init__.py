"""Missing-effect discovery: find where model and data disagree, name the effect, add it.

An :class:`Effect` is a named, documented extension of a forward model (extra
parameters with an absent value, the forward change, the residual signature).
:func:`discover` fits a baseline, measures the gap (reduced χ²), fits every
candidate extension, adds the one the evidence (BIC and a boundary-corrected
likelihood ratio) justifies, repeats, and reports what remains unexplained.
See "Missing effects" in DESIGN.md.
"""

from ._discover import discover as discover
from ._effect import Effect as Effect
from ._effect import Param as Param
from ._library import LIBRARY as LIBRARY
from ._library import get_effect as get_effect
from ._library import library as library
from ._models import ScanlineData as ScanlineData
from ._models import ScanlineModel as ScanlineModel
from ._models import ThresholdData as ThresholdData
from ._models import ThresholdModel as ThresholdModel
from ._models import scanline_data as scanline_data
from ._models import threshold_data as threshold_data
from ._screen import SCREEN_EFFECTS as SCREEN_EFFECTS
from ._screen import ScreenData as ScreenData
from ._screen import ScreenModel as ScreenModel
from ._screen import screen_data as screen_data
from ._report import Candidate as Candidate
from ._report import DiscoveryReport as DiscoveryReport
from ._report import Step as Step
from ._report import VariogramRead as VariogramRead
from ._report import gap_figure as gap_figure
from ._structure import covariate_label as covariate_label
from ._photo_discover import PHOTO_EFFECTS as PHOTO_EFFECTS
from ._photo_discover import discover_photo as discover_photo
from ._photo_model import PhotoData as PhotoData
from ._photo_report import PhotoDiscoveryReport as PhotoDiscoveryReport

__all__ = [
    "discover",
    "Effect",
    "Param",
    "LIBRARY",
    "get_effect",
    "library",
    "ScanlineData",
    "ScanlineModel",
    "ThresholdData",
    "ThresholdModel",
    "scanline_data",
    "threshold_data",
    "SCREEN_EFFECTS",
    "ScreenData",
    "ScreenModel",
    "screen_data",
    "Candidate",
    "DiscoveryReport",
    "Step",
    "VariogramRead",
    "gap_figure",
    "covariate_label",
    "PHOTO_EFFECTS",
    "discover_photo",
    "PhotoData",
    "PhotoDiscoveryReport",
]
