"""The ρd texture: per-pixel extraction, steerable pyramid, histogram matching, analysis and synthesis."""

from ._analysis import analyze_texture as analyze_texture
from ._analysis import largest_valid_rectangle as largest_valid_rectangle
from ._extract import extract_rho_d as extract_rho_d
from ._histogram import match_histogram as match_histogram
from ._histogram import quantile_probabilities as quantile_probabilities
from ._images import read_rho_d as read_rho_d
from ._images import write_texture_image as write_texture_image
from ._model import TEXTURE_FORMAT_VERSION as TEXTURE_FORMAT_VERSION
from ._model import TextureModel as TextureModel
from ._steerable import SteerablePyramid as SteerablePyramid
from ._steerable import build_steerable_pyramid as build_steerable_pyramid
from ._steerable import periodic_smooth_decomposition as periodic_smooth_decomposition
from ._steerable import reconstruct_steerable_pyramid as reconstruct_steerable_pyramid
from ._synthesis import SynthesisResult as SynthesisResult
from ._synthesis import synthesize_texture as synthesize_texture

__all__ = [
    "analyze_texture",
    "largest_valid_rectangle",
    "extract_rho_d",
    "match_histogram",
    "quantile_probabilities",
    "read_rho_d",
    "write_texture_image",
    "TEXTURE_FORMAT_VERSION",
    "TextureModel",
    "SteerablePyramid",
    "build_steerable_pyramid",
    "periodic_smooth_decomposition",
    "reconstruct_steerable_pyramid",
    "SynthesisResult",
    "synthesize_texture",
]
