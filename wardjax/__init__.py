"""wardjax: measure Ward BRDF parameters from photographs, with honest uncertainties.

The package namespace is the public API; everything is re-exported explicitly
from the stage packages, in the order of the flow: ``capture`` → ``reconstruct``
→ ``fit`` → ``texture`` → ``smartphone`` → ``export`` → ``render`` (Radiance and
JAX renders of the rig, the slanted-edge MTF), with ``simulate`` the mirror image
of the flow, ``effects`` on top, and ``run`` (end-to-end fits, batches, the CLI)
over all of them. Importing wardjax never changes global JAX settings:
fits run in float64 inside a scoped ``jax.enable_x64(True)``.

Names are imported on first use (PEP 562 ``__getattr__``), so that ``import wardjax``
and ``wardjax --help`` do not import JAX; ``from wardjax import X`` and ``wardjax.X``
work as if everything had been imported up front.
"""

import importlib as _importlib
from importlib.metadata import PackageNotFoundError as _PackageNotFoundError
from importlib.metadata import version as _version
from typing import TYPE_CHECKING

if TYPE_CHECKING:  # the API as the type checker and the reader see it
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
    from .smartphone import delta_E_CIE1976 as delta_E_CIE1976
    from .smartphone import delta_E_CIE2000 as delta_E_CIE2000
    from .smartphone import diffuse_from_srgb as diffuse_from_srgb
    from .smartphone import fresnel_reflectance as fresnel_reflectance
    from .smartphone import specular_from_fresnel as specular_from_fresnel
    from .smartphone import specular_rgb_metal as specular_rgb_metal
    from .smartphone import AlphaModel as AlphaModel
    from .smartphone import AlphaPosterior as AlphaPosterior
    from .smartphone import NotConvergedError as NotConvergedError
    from .smartphone import cpd_to_ppb as cpd_to_ppb
    from .smartphone import fit_smartphone as fit_smartphone
    from .smartphone import ppb_to_cpd as ppb_to_cpd
    from .smartphone import write_gratings as write_gratings
    from .run import BatchItem as BatchItem
    from .run import run_batch as run_batch
    from .capture import Capture as Capture
    from .capture import CaptureError as CaptureError
    from .capture import load_capture as load_capture
    from .simulate import SensorNoise as SensorNoise
    from .simulate import simulate_capture as simulate_capture
    from .export import radiance_material as radiance_material
    from .export import radiance_metal as radiance_metal
    from .export import radiance_rgb as radiance_rgb
    from .export import write_capture_outputs as write_capture_outputs
    from .geometry import Camera as Camera
    from .geometry import PixelGeometry as PixelGeometry
    from .geometry import Rig as Rig
    from .geometry import pixel_geometry as pixel_geometry
    from .run import CaptureFit as CaptureFit
    from .run import fit_capture as fit_capture
    from .reconstruct import MaskReason as MaskReason
    from .reconstruct import reconstruct_brdf as reconstruct_brdf
    from .texture import SteerablePyramid as SteerablePyramid
    from .texture import SynthesisResult as SynthesisResult
    from .texture import TextureModel as TextureModel
    from .texture import analyze_texture as analyze_texture
    from .texture import build_steerable_pyramid as build_steerable_pyramid
    from .texture import largest_valid_rectangle as largest_valid_rectangle
    from .texture import match_histogram as match_histogram
    from .texture import periodic_smooth_decomposition as periodic_smooth_decomposition
    from .texture import reconstruct_steerable_pyramid as reconstruct_steerable_pyramid
    from .texture import synthesize_texture as synthesize_texture
    from .smartphone import lobe_sd_from_gonio as lobe_sd_from_gonio
    from .render import radiance_render_rig as radiance_render_rig
    from .render import render_rig as render_rig
    from .render import slanted_edge_mtf as slanted_edge_mtf
    from . import effects as effects
    from .fit import PixelFit as PixelFit
    from .fit import fit_pixels as fit_pixels
    from .fit import predict_pixels as predict_pixels
    from .fit import heldout_pixels as heldout_pixels
    from .capture import PhotoCapture as PhotoCapture
    from .capture import import_capture as import_capture
    from .run import PhotoFit as PhotoFit

# Each public name → the module defining it, imported on first use (PEP 562).
_API = {
    "Status": "._status",
    "CombinedFit": ".fit",
    "ScanlineFit": ".fit",
    "fit_scanlines": ".fit",
    "ScanlineData": ".simulate",
    "ScanlineRig": ".simulate",
    "simulate_scanlines": ".simulate",
    "extract_rho_d": ".texture",
    "NORMALIZATIONS": ".ward",
    "WardParams": ".ward",
    "ward_brdf": ".ward",
    "ward_brdf_angles": ".ward",
    "delta_E_CIE1976": ".smartphone",
    "delta_E_CIE2000": ".smartphone",
    "diffuse_from_srgb": ".smartphone",
    "fresnel_reflectance": ".smartphone",
    "specular_from_fresnel": ".smartphone",
    "specular_rgb_metal": ".smartphone",
    "AlphaModel": ".smartphone",
    "AlphaPosterior": ".smartphone",
    "NotConvergedError": ".smartphone",
    "cpd_to_ppb": ".smartphone",
    "fit_smartphone": ".smartphone",
    "ppb_to_cpd": ".smartphone",
    "write_gratings": ".smartphone",
    "BatchItem": ".run",
    "run_batch": ".run",
    "Capture": ".capture",
    "CaptureError": ".capture",
    "load_capture": ".capture",
    "SensorNoise": ".simulate",
    "simulate_capture": ".simulate",
    "radiance_material": ".export",
    "radiance_metal": ".export",
    "radiance_rgb": ".export",
    "write_capture_outputs": ".export",
    "Camera": ".geometry",
    "PixelGeometry": ".geometry",
    "Rig": ".geometry",
    "pixel_geometry": ".geometry",
    "CaptureFit": ".run",
    "fit_capture": ".run",
    "MaskReason": ".reconstruct",
    "reconstruct_brdf": ".reconstruct",
    "SteerablePyramid": ".texture",
    "SynthesisResult": ".texture",
    "TextureModel": ".texture",
    "analyze_texture": ".texture",
    "build_steerable_pyramid": ".texture",
    "largest_valid_rectangle": ".texture",
    "match_histogram": ".texture",
    "periodic_smooth_decomposition": ".texture",
    "reconstruct_steerable_pyramid": ".texture",
    "synthesize_texture": ".texture",
    "lobe_sd_from_gonio": ".smartphone",
    "radiance_render_rig": ".render",
    "render_rig": ".render",
    "slanted_edge_mtf": ".render",
    "effects": ".effects",
    "PixelFit": ".fit",
    "fit_pixels": ".fit",
    "predict_pixels": ".fit",
    "heldout_pixels": ".fit",
    "PhotoCapture": ".capture",
    "import_capture": ".capture",
    "PhotoFit": ".run",
}
__all__ = [
    "Status",
    "CombinedFit",
    "ScanlineFit",
    "fit_scanlines",
    "ScanlineData",
    "ScanlineRig",
    "simulate_scanlines",
    "extract_rho_d",
    "NORMALIZATIONS",
    "WardParams",
    "ward_brdf",
    "ward_brdf_angles",
    "delta_E_CIE1976",
    "delta_E_CIE2000",
    "diffuse_from_srgb",
    "fresnel_reflectance",
    "specular_from_fresnel",
    "specular_rgb_metal",
    "AlphaModel",
    "AlphaPosterior",
    "NotConvergedError",
    "cpd_to_ppb",
    "fit_smartphone",
    "ppb_to_cpd",
    "write_gratings",
    "BatchItem",
    "run_batch",
    "Capture",
    "CaptureError",
    "load_capture",
    "SensorNoise",
    "simulate_capture",
    "radiance_material",
    "radiance_metal",
    "radiance_rgb",
    "write_capture_outputs",
    "Camera",
    "PixelGeometry",
    "Rig",
    "pixel_geometry",
    "CaptureFit",
    "fit_capture",
    "MaskReason",
    "reconstruct_brdf",
    "SteerablePyramid",
    "SynthesisResult",
    "TextureModel",
    "analyze_texture",
    "build_steerable_pyramid",
    "largest_valid_rectangle",
    "match_histogram",
    "periodic_smooth_decomposition",
    "reconstruct_steerable_pyramid",
    "synthesize_texture",
    "lobe_sd_from_gonio",
    "radiance_render_rig",
    "render_rig",
    "slanted_edge_mtf",
    "effects",
    "PixelFit",
    "fit_pixels",
    "predict_pixels",
    "heldout_pixels",
    "PhotoCapture",
    "import_capture",
    "PhotoFit",
]


def __getattr__(name: str):
    """Import the module behind ``name`` on first use and keep the value in the namespace."""
    try:
        module = _API[name]
    except KeyError:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}") from None
    obj = _importlib.import_module(module, __name__)
    value = obj if module == f".{name}" else getattr(obj, name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_API))


try:
    __version__ = _version("wardjax")
except _PackageNotFoundError:  # a source tree that was never installed
    __version__ = "0+unknown"
