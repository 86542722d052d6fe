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

# --- smartphone method (issue 4): colour, Fresnel, gratings and the α model
from .color import delta_E_CIE1976 as delta_E_CIE1976
from .color import delta_E_CIE2000 as delta_E_CIE2000
from .color import diffuse_from_srgb as diffuse_from_srgb
from .fresnel import fresnel_reflectance as fresnel_reflectance
from .fresnel import specular_from_fresnel as specular_from_fresnel
from .fresnel import specular_rgb_metal as specular_rgb_metal
from .psychophysics import AlphaModel as AlphaModel
from .psychophysics import AlphaPosterior as AlphaPosterior
from .psychophysics import NotConvergedError as NotConvergedError
from .psychophysics import cpd_to_ppb as cpd_to_ppb
from .psychophysics import fit_smartphone as fit_smartphone
from .psychophysics import ppb_to_cpd as ppb_to_cpd
from .psychophysics import write_gratings as write_gratings
# --- end smartphone method

# --- capture pipeline (issue 3): capture folders, geometry, reconstruction, fit, exports, batches
from .batch import BatchItem as BatchItem
from .batch import run_batch as run_batch
from .capture import Capture as Capture
from .capture import CaptureError as CaptureError
from .capture import load_capture as load_capture
from .capture_sim import SensorNoise as SensorNoise
from .capture_sim import simulate_capture as simulate_capture
from .export import radiance_material as radiance_material
from .export import radiance_metal as radiance_metal
from .export import radiance_rgb as radiance_rgb
from .export import write_capture_outputs as write_capture_outputs
from .geometry import Camera as Camera
from .geometry import PixelGeometry as PixelGeometry
from .geometry import Rig as Rig
from .geometry import pixel_geometry as pixel_geometry
from .pipeline import CaptureFit as CaptureFit
from .pipeline import fit_capture as fit_capture
from .reconstruct import MaskReason as MaskReason
from .reconstruct import reconstruct_brdf as reconstruct_brdf
# --- end capture pipeline

# --- texture analysis and synthesis (issue 6)
from .synthesis import SteerablePyramid as SteerablePyramid
from .synthesis import SynthesisResult as SynthesisResult
from .synthesis import TextureModel as TextureModel
from .synthesis import analyze_texture as analyze_texture
from .synthesis import build_steerable_pyramid as build_steerable_pyramid
from .synthesis import largest_valid_rectangle as largest_valid_rectangle
from .synthesis import match_histogram as match_histogram
from .synthesis import periodic_smooth_decomposition as periodic_smooth_decomposition
from .synthesis import reconstruct_steerable_pyramid as reconstruct_steerable_pyramid
from .synthesis import synthesize_texture as synthesize_texture
# --- end texture

# --- missing-effect discovery (issue 5)
from . import effects as effects
# --- end missing-effect discovery

__version__ = "0.1.0"
