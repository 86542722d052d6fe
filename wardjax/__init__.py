"""wardjax: measure Ward BRDF parameters from photographs, with honest uncertainties.

The package namespace is the public API; everything is re-exported explicitly.
Importing wardjax never changes global JAX settings: fits run in float64 inside
a scoped ``jax.enable_x64(True)``.
"""

from ._status import Status as Status
from .fit import CombinedFit as CombinedFit
from .fit import ScanlineFit as ScanlineFit
from .fit import fit_scanlines as fit_scanlines
from .simulate import ScanlineData as ScanlineData
from .simulate import ScanlineRig as ScanlineRig
from .simulate import simulate_scanlines as simulate_scanlines
from .texture import extract_rho_d as extract_rho_d
from .ward import NORMALIZATIONS as NORMALIZATIONS
from .ward import WardParams as WardParams
from .ward import ward_brdf as ward_brdf
from .ward import ward_brdf_angles as ward_brdf_angles

__version__ = "0.1.0"
