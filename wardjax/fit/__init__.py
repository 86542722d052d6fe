"""Fitting Ward: scanlines (per-scanline fits, the joint refit, texture-field errors) and the pixels of a few photos."""

from ._joint import CombinedFit as CombinedFit
from ._pixel_heldphoto import HeldOutPhoto as HeldOutPhoto
from ._pixel_heldphoto import heldout_pixels as heldout_pixels
from ._pixels import PixelFit as PixelFit
from ._pixels import PixelParams as PixelParams
from ._pixels import fit_pixels as fit_pixels
from ._pixels import predict_pixels as predict_pixels
from ._scanline import ScanlineFit as ScanlineFit
from ._scanline import fit_scanlines as fit_scanlines
from ._texture_field import TextureErrors as TextureErrors
from ._texture_field import placement_covariance as placement_covariance
from ._texture_field import plane_covariance as plane_covariance
from ._texture_field import texture_field_covariance as texture_field_covariance
from ._texture_field import with_texture_errors as with_texture_errors

__all__ = [
    "CombinedFit",
    "ScanlineFit",
    "fit_scanlines",
    "TextureErrors",
    "texture_field_covariance",
    "with_texture_errors",
    "PixelFit",
    "PixelParams",
    "fit_pixels",
    "predict_pixels",
    "HeldOutPhoto",
    "heldout_pixels",
    "placement_covariance",
    "plane_covariance",
]
