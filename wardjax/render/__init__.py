"""Renders of the capture rig: Radiance (through pyradiance) and a small differentiable JAX renderer."""

from ._radiance import RTRACE_SETTINGS as RTRACE_SETTINGS
from ._radiance import from_radiance_rgb as from_radiance_rgb
from ._radiance import radiance_render_rig as radiance_render_rig
from ._radiance import rig_rays as rig_rays
from ._radiance import rig_scene as rig_scene
from ._radiance import texture_grid as texture_grid
from ._jax import render_rig as render_rig
from ._mtf import EdgeMTF as EdgeMTF
from ._mtf import slanted_edge_mtf as slanted_edge_mtf

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
]
