"""Renders: the capture rig, a sphere under an environment and a phone screen reflected in a sample, each by
Radiance (through pyradiance) and by a small differentiable JAX renderer; slanted-edge MTFs and grating spectra."""

from ._radiance import RTRACE_SETTINGS as RTRACE_SETTINGS
from ._radiance import from_radiance_rgb as from_radiance_rgb
from ._radiance import radiance_render_rig as radiance_render_rig
from ._radiance import rig_rays as rig_rays
from ._radiance import rig_scene as rig_scene
from ._radiance import texture_grid as texture_grid
from ._jax import render_rig as render_rig
from ._mtf import EdgeMTF as EdgeMTF
from ._mtf import slanted_edge_mtf as slanted_edge_mtf
from ._scenes import LUMINOUS_EFFICACY as LUMINOUS_EFFICACY
from ._scenes import DistantSources as DistantSources
from ._scenes import PhoneScene as PhoneScene
from ._scenes import ScreenSources as ScreenSources
from ._scenes import camera_rays as camera_rays
from ._scenes import environment_sources as environment_sources
from ._scenes import phone_scene as phone_scene
from ._scenes import sky_environment as sky_environment
from ._scenes import square_wave as square_wave
from ._jax_scenes import render_phone as render_phone
from ._jax_scenes import render_sphere as render_sphere
from ._radiance_scenes import SCENE_SETTINGS as SCENE_SETTINGS
from ._radiance_scenes import phone_radiance_scene as phone_radiance_scene
from ._radiance_scenes import radiance_render_phone as radiance_render_phone
from ._radiance_scenes import radiance_render_sphere as radiance_render_sphere
from ._radiance_scenes import sphere_radiance_scene as sphere_radiance_scene
from ._spectra import GratingSpectrum as GratingSpectrum
from ._flash_views import FlashViews as FlashViews
from ._flash_views import flash_views as flash_views
from ._flash_views import flash_views_scene as flash_views_scene
from ._flash_views import radiance_render_flash_views as radiance_render_flash_views
from ._flash_views import rectified_geometry as rectified_geometry
from ._flash_views import render_flash_views as render_flash_views
from ._spectra import grating_spectrum as grating_spectrum

__all__ = [
    "RTRACE_SETTINGS",
    "from_radiance_rgb",
    "radiance_render_rig",
    "rig_rays",
    "rig_scene",
    "texture_grid",
    "render_rig",
    "EdgeMTF",
    "slanted_edge_mtf",
    "LUMINOUS_EFFICACY",
    "DistantSources",
    "PhoneScene",
    "ScreenSources",
    "camera_rays",
    "environment_sources",
    "phone_scene",
    "sky_environment",
    "square_wave",
    "render_phone",
    "render_sphere",
    "SCENE_SETTINGS",
    "phone_radiance_scene",
    "radiance_render_phone",
    "radiance_render_sphere",
    "sphere_radiance_scene",
    "GratingSpectrum",
    "grating_spectrum",
    "FlashViews",
    "flash_views",
    "flash_views_scene",
    "radiance_render_flash_views",
    "rectified_geometry",
    "render_flash_views",
]
