"""Synthetic data, the mirror image of the flow: one forward model, scanlines, whole capture folders."""

from ._capture import default_rig as default_rig
from ._capture import framed_camera as framed_camera
from ._capture import SensorNoise as SensorNoise
from ._capture import simulate_capture as simulate_capture
from ._capture import write_capture_toml as write_capture_toml
from ._forward import capture_radiance as capture_radiance
from ._flash_views import FlashNoise as FlashNoise
from ._flash_views import flash_noise_sigma as flash_noise_sigma
from ._flash_views import flash_views_data as flash_views_data
from ._flash_views import FlashViewsData as FlashViewsData
from ._flash_views import simulate_flash_views as simulate_flash_views
from ._forward import TABLE_REFLECTANCE as TABLE_REFLECTANCE
from ._forward import ward_values as ward_values
from ._procedural import plane_texture as plane_texture
from ._procedural import PLANE_TEXTURES as PLANE_TEXTURES
from ._procedural import procedural_texture as procedural_texture
from ._procedural import TEXTURE_KINDS as TEXTURE_KINDS
from ._scanlines import scanline_directions as scanline_directions
from ._scanlines import scanline_positions as scanline_positions
from ._scanlines import ScanlineData as ScanlineData
from ._scanlines import ScanlineRig as ScanlineRig
from ._scanlines import simulate_scanlines as simulate_scanlines
from ._scanlines import x_offset_for_slope as x_offset_for_slope

__all__ = [
    "default_rig",
    "framed_camera",
    "SensorNoise",
    "simulate_capture",
    "write_capture_toml",
    "capture_radiance",
    "TABLE_REFLECTANCE",
    "ward_values",
    "plane_texture",
    "PLANE_TEXTURES",
    "procedural_texture",
    "TEXTURE_KINDS",
    "scanline_directions",
    "scanline_positions",
    "ScanlineData",
    "ScanlineRig",
    "simulate_scanlines",
    "x_offset_for_slope",
    "FlashNoise",
    "flash_noise_sigma",
    "flash_views_data",
    "FlashViewsData",
    "simulate_flash_views",
]
