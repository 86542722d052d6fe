"""The one forward model of a measurement: Ward values, and the radiance a rig's camera records.

:func:`ward_values` evaluates :func:`wardjax.ward_brdf` in float64 on NumPy
directions; everything that makes synthetic data (scanlines, captures, the
hidden-effect bench) evaluates the model through it. :func:`capture_radiance`
is the image-based rig (Fig. 2 of the paper) seen by its camera:

* probe (``x > 0``): ``L = f_r(ωi, ωo; ρd(P)) · E(P)``
* standard (``x < 0``): ``L = ρ_std / π · E(P)``
* elsewhere (the table): ``L = 0.05 / π · E(P)``

with ``E(P) = I · D(P) · cos θi / r²`` (a point lamp of intensity ``I`` and a
cos³ directivity ``D`` about its axis, symmetric about the plane ``x = 0``) and
vignetting ``V = cos⁴`` of the ray's angle to the optical axis.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from ..geometry import Rig, pixel_geometry, to_material_frame
from ..ward import WardParams, ward_brdf

__all__ = ["TABLE_REFLECTANCE", "capture_radiance", "ward_values"]

TABLE_REFLECTANCE = 0.05


def ward_values(params: WardParams, wi, wo, normalization: str = "ward1992") -> np.ndarray:
    """``f_r`` (sr⁻¹, ``(..., 3)`` float64 NumPy) of ``params`` for directions ``wi``, ``wo`` ``(..., 3)``.

    Evaluated under a scoped ``jax.enable_x64(True)``; the parameters' leaves
    broadcast against the directions' batch axes as in :func:`wardjax.ward_brdf`.
    """
    with jax.enable_x64(True):
        p = jax.tree_util.tree_map(lambda x: jnp.asarray(np.asarray(x, np.float64)), params)
        return np.asarray(
            ward_brdf(p, jnp.asarray(wi, jnp.float64), jnp.asarray(wo, jnp.float64), normalization=normalization)
        )


def capture_radiance(params: WardParams, rig: Rig, rho_d_map, tangent, rho_standard, normalization, rows) -> tuple:
    """Noise-free radiance (per unit lamp intensity) and local reflectance for pixel rows."""
    cam = rig.camera
    u, v = np.meshgrid(np.arange(cam.width, dtype=np.float64), rows.astype(np.float64))
    g = pixel_geometry(rig, u, v)
    x, y = g.points[..., 0], g.points[..., 1]
    rho_d = rho_d_map(np.nan_to_num(x), np.nan_to_num(y))  # (..., 3)
    wi = to_material_frame(g.wi, tangent)
    wo = to_material_frame(g.wo, tangent)
    p = WardParams.from_estimate(  # per pixel: the texture's ρd under the checked material
        rho_d=rho_d,
        rho_s=np.asarray(params.rho_s, float),
        alpha_x=np.asarray(params.alpha_x, float),
        alpha_y=np.asarray(params.alpha_y, float),
    )
    f = ward_values(p, np.nan_to_num(wi), np.nan_to_num(wo), normalization)
    rho_std = np.broadcast_to(np.asarray(rho_standard, float), (3,))
    local = np.full(g.points.shape, TABLE_REFLECTANCE)
    local = np.where(g.in_standard[..., None], rho_std, local)
    local = np.where(g.in_probe[..., None], rho_d, local)
    brdf = local / np.pi
    brdf = np.where(g.in_probe[..., None], f, brdf)
    # Lamp directivity: a cos³ falloff about the lamp's axis, which points at the
    # origin from within the plane x = 0, so it is symmetric about that plane.
    lamp = np.asarray(rig.lamp, float)
    to_p = np.nan_to_num(g.points) - lamp
    cos_axis = -(to_p @ lamp) / (np.linalg.norm(to_p, axis=-1) * np.linalg.norm(lamp))
    e = g.irradiance * np.clip(cos_axis, 0, 1) ** 3
    # Vignetting cos⁴ of the ray's angle to the optical axis.
    fx, fy = cam.focal
    cx, cy = cam.principal
    tan2 = ((u - cx) / fx) ** 2 + ((v - cy) / fy) ** 2
    vig = 1.0 / (1.0 + tan2) ** 2
    hit = np.isfinite(g.points[..., 0])
    radiance = np.where(hit[..., None], brdf * e[..., None] * vig[..., None], 0.0)
    ambient = np.where(hit[..., None], local * vig[..., None], 0.0)
    truth = np.where(g.in_probe[..., None], rho_d, np.nan)
    return radiance, ambient, truth, g.in_probe | g.in_standard
