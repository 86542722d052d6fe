"""Fresnel reflectance and the specular reflectance ρs of the smartphone method.

Exact Fresnel equations for unpolarised light arriving from air (n₀ = 1) on a smooth
interface with complex refractive index ``ñ = n + i k`` (``k = 0`` for a dielectric):

.. math::

    g = \\sqrt{\\tilde n^2 - \\sin^2\\theta}, \\quad
    r_s = \\frac{\\cos\\theta - g}{\\cos\\theta + g}, \\quad
    r_p = \\frac{\\tilde n^2\\cos\\theta - g}{\\tilde n^2\\cos\\theta + g}, \\quad
    F(\\theta) = \\tfrac12\\left(|r_s|^2 + |r_p|^2\\right)

(principal complex square root; for ``k ≥ 0`` it is the branch with a decaying
transmitted wave). At normal incidence ``F(0) = ((n−1)² + k²)/((n+1)² + k²)``.

The smartphone paper (section 3.3, its Figure 4) takes ρs as the nearly constant value of
F below 60°. :func:`specular_from_fresnel` makes that a definition: the mean of F over
incidence directions within 60° of the normal, weighted by projected solid angle,

.. math::

    \\rho_s = \\frac{\\int_0^{\\theta_{max}} F(\\theta)\\cos\\theta\\sin\\theta\\,d\\theta}
                 {\\int_0^{\\theta_{max}} \\cos\\theta\\sin\\theta\\,d\\theta},

which is 0.0500 for n = 1.5, the paper's value. For metals the same mean is taken per
wavelength over tabulated ``n, k`` (``calibration/metal_ior.csv``) and turned into RGB
(sRGB primaries, white E) through CIE 1931 colour matching under illuminant E.
"""

from __future__ import annotations

import csv
from functools import lru_cache

import colour
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike
from numpy.typing import NDArray

from .._data import calibration_path

__all__ = [
    "METALS",
    "fresnel_reflectance",
    "metal_ior",
    "specular_from_fresnel",
    "specular_rgb_metal",
]

METALS: tuple[str, ...] = ("gold", "silver", "copper", "aluminium")

_GL_NODES, _GL_WEIGHTS = np.polynomial.legendre.leggauss(64)


def fresnel_reflectance(cos_theta: ArrayLike, n: ArrayLike, k: ArrayLike = 0.0) -> Array:
    """Unpolarised Fresnel reflectance from air onto ``n + i k`` (exact; see module docstring).

    Parameters
    ----------
    cos_theta
        Cosine of the incidence angle, in [0, 1]; any shape.
    n, k
        Real and imaginary parts of the refractive index (``n > 0``, ``k ≥ 0``);
        broadcast against ``cos_theta``.

    Returns
    -------
    Array
        F in [0, 1], the broadcast shape. jit/vmap/grad friendly (complex arithmetic in jnp).
    """
    # One real dtype (JAX's default float) for all three, then one complex one: no implicit promotion.
    c, n, k = jnp.broadcast_arrays(*(jnp.asarray(x, dtype=float) for x in (cos_theta, n, k)))
    c = jnp.clip(c, 0.0, 1.0)
    eta = jax.lax.complex(n, k)
    eta2 = eta * eta
    c = c.astype(eta.dtype)
    s2 = 1.0 - c * c
    g = jnp.sqrt(eta2 - s2)
    rs = (c - g) / (c + g)
    rp = (eta2 * c - g) / (eta2 * c + g)
    return 0.5 * (jnp.abs(rs) ** 2 + jnp.abs(rp) ** 2)


def _check_ior(n, k):
    n_arr, k_arr = np.asarray(n, dtype=float), np.asarray(k, dtype=float)
    if not np.all(np.isfinite(n_arr)) or np.any(n_arr <= 0):
        raise ValueError(f"n (refractive index) must be finite and > 0; got {n!r}")
    if not np.all(np.isfinite(k_arr)) or np.any(k_arr < 0):
        raise ValueError(f"k (extinction coefficient) must be finite and ≥ 0; got {k!r}")
    return n_arr, k_arr


def specular_from_fresnel(n: ArrayLike = 1.5, k: ArrayLike = 0.0, *, max_angle_deg: float = 60.0) -> float | np.ndarray:
    """ρs as the projected-solid-angle mean of Fresnel reflectance over 0–``max_angle_deg``.

    Parameters
    ----------
    n, k
        Refractive index ``n + i k`` of the surface (dielectric: ``k = 0``). Arrays broadcast.
    max_angle_deg
        Upper incidence angle of the mean, in (0, 90]; the paper's 60° by default.

    Returns
    -------
    float or ndarray
        ρs (0.0500 for n = 1.5). Computed in float64 (64-point Gauss–Legendre in θ).
    """
    n_arr, k_arr = _check_ior(n, k)
    if not 0.0 < max_angle_deg <= 90.0:
        raise ValueError(f"max_angle_deg must be in (0, 90]; got {max_angle_deg}")
    tmax = np.deg2rad(max_angle_deg)
    theta = 0.5 * tmax * (_GL_NODES + 1.0)
    w = 0.5 * tmax * _GL_WEIGHTS * np.cos(theta) * np.sin(theta)
    with jax.enable_x64(True):
        shape = np.broadcast_shapes(n_arr.shape, k_arr.shape) + theta.shape
        f = fresnel_reflectance(
            np.broadcast_to(np.cos(theta), shape),
            np.broadcast_to(n_arr[..., None], shape),
            np.broadcast_to(k_arr[..., None], shape),
        )
        rho = np.asarray(f) @ w / np.sum(w)
    return float(rho) if rho.ndim == 0 else rho


@lru_cache(maxsize=1)
def _metal_table() -> dict[str, np.ndarray]:
    with open(calibration_path("metal_ior.csv"), encoding="utf-8") as fh:
        rows = list(csv.DictReader(r for r in fh if not r.startswith("#")))
    out: dict[str, list] = {}
    for row in rows:
        out.setdefault(row["metal"], []).append((float(row["wavelength_nm"]), float(row["n"]), float(row["k"])))
    return {m: np.array(v) for m, v in out.items()}


def metal_ior(metal: str, wavelength_nm: ArrayLike) -> tuple[NDArray | np.floating, NDArray | np.floating]:
    """Tabulated ``(n, k)`` of ``metal`` (one of :data:`METALS`), linearly interpolated in wavelength."""
    table = _metal_table()
    if metal not in table:
        raise ValueError(f"metal must be one of {tuple(table)}; got {metal!r}")
    wl = np.asarray(wavelength_nm, dtype=float)
    t = table[metal]
    if np.any(wl < t[0, 0]) or np.any(wl > t[-1, 0]):
        raise ValueError(f"wavelength_nm must lie in [{t[0, 0]:.0f}, {t[-1, 0]:.0f}] nm for {metal}")
    return np.interp(wl, t[:, 0], t[:, 1]), np.interp(wl, t[:, 0], t[:, 2])


def specular_rgb_metal(metal: str, *, max_angle_deg: float = 60.0) -> np.ndarray:
    """RGB ρs of a metal (sRGB primaries, white E) from its tabulated spectral ``n, k``.

    The spectral ρs(λ) of :func:`specular_from_fresnel` on 360–830 nm (5 nm) is integrated
    against the CIE 1931 2° colour-matching functions under illuminant E (so a spectrally
    flat ρs gives R = G = B = ρs), then taken to RGB with the sRGB primaries and white E.
    """
    wl = np.arange(360.0, 831.0, 5.0)
    n, k = metal_ior(metal, wl)
    rho = np.asarray(specular_from_fresnel(n, k, max_angle_deg=max_angle_deg))  # (λ,): an array in, an array out
    cmfs = colour.MSDS_CMFS["CIE 1931 2 Degree Standard Observer"].copy().align(colour.SpectralShape(360, 830, 5))
    xyz_bar = cmfs.values
    xyz = (rho[:, None] * xyz_bar).sum(0) / xyz_bar[:, 1].sum()
    white_e = colour.CCS_ILLUMINANTS["CIE 1931 2 Degree Standard Observer"]["E"]
    npm = colour.normalised_primary_matrix(colour.RGB_COLOURSPACES["sRGB"].primaries, white_e)
    return np.linalg.solve(npm, xyz)
