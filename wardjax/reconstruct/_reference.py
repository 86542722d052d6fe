"""Measured pixel values → absolute BRDF values, with the reasons a value is unusable.

Image-based paper, section 3, eq. "f_r,measured":

.. math::

    f_r = \\frac{v - v_{bg,1}}{v_{std} - v_{bg,2}} \\cdot \\frac{\\rho_{std}}{\\pi}

``v`` is the (linear) camera value of a probe pixel with the lamp on,
``v_bg,1`` the same pixel with the lamp off, ``v_std`` and ``v_bg,2`` the
values at the mirror point on the diffuse reflectance standard. The lamp's
irradiance, its directionality and any vignetting symmetric about the
stripline cancel in the ratio; so does the camera's exposure.
"""

from __future__ import annotations

import enum

import numpy as np

__all__ = ["MaskReason", "reconstruct_brdf", "sample_bilinear"]


class MaskReason(enum.IntFlag):
    """Why a reconstructed value is unusable (bit flags, per pixel and channel).

    ``OFF_STANDARD``
        The mirror point of the pixel is not on the standard (or outside the image).
    ``SATURATED``
        The lit value of the pixel or of its mirror point is clipped.
    ``BELOW_NOISE``
        The lamp's signal ``v − v_bg`` or ``v_std − v_std_bg`` is below the noise floor.
    ``NONFINITE``
        An input is NaN or infinite.
    """

    OFF_STANDARD = 1
    SATURATED = 2
    BELOW_NOISE = 4
    NONFINITE = 8


def reconstruct_brdf(
    v,
    v_bg,
    v_std,
    v_std_bg,
    rho_standard=0.99,
    *,
    on_standard=None,
    saturation: float | None = None,
    saturated=None,
    noise_floor: float = 0.0,
    return_flags: bool = False,
):
    """BRDF values from probe and standard pixel values, eq. "f_r,measured".

    Parameters
    ----------
    v, v_bg
        ``(..., 3)`` linear values of the probe pixels, lamp on and lamp off
        (``v_bg`` may be ``None`` or 0 when there is no background frame).
    v_std, v_std_bg
        ``(..., 3)`` linear values at the mirror points on the standard, lamp on and off.
    rho_standard
        Reflectance of the standard, scalar or RGB, in ``(0, 1]`` (0.99 for
        barium sulfate / Spectralon).
    on_standard
        ``(...)`` booleans: the mirror point lies on the standard. ``False``
        gives :attr:`MaskReason.OFF_STANDARD`.
    saturation
        Linear level at or above which a lit value (``v`` or ``v_std``) is
        clipped, e.g. 1.0 for full scale; ``None`` checks nothing.
    saturated
        ``(...)`` or ``(..., 3)`` booleans already known to be clipped.
    noise_floor
        Lamp signals ``v − v_bg`` or ``v_std − v_std_bg`` below this (same
        units as ``v``) are :attr:`MaskReason.BELOW_NOISE`.
    return_flags
        Also return the ``(..., 3)`` ``uint8`` :class:`MaskReason` flags.

    Returns
    -------
    f_r : ndarray ``(..., 3)`` float64
        BRDF values (sr⁻¹), NaN where any flag is set.
    flags : ndarray ``(..., 3)`` uint8, only with ``return_flags=True``.
    """
    v = np.asarray(v, np.float64)
    v_std = np.asarray(v_std, np.float64)
    v_bg = np.zeros(()) if v_bg is None else np.asarray(v_bg, np.float64)
    v_std_bg = np.zeros(()) if v_std_bg is None else np.asarray(v_std_bg, np.float64)
    rho = np.asarray(rho_standard, np.float64)
    if rho.shape not in ((), (3,)) or not np.all((rho > 0) & (rho <= 1)):
        raise ValueError(f"rho_standard must be a number or RGB triple in (0, 1], got {rho_standard!r}")
    shape = np.broadcast_shapes(v.shape, v_bg.shape, v_std.shape, v_std_bg.shape)
    if shape[-1:] != (3,):
        raise ValueError(f"pixel values must end in an RGB axis of 3, got shape {shape}")
    num = v - v_bg
    den = v_std - v_std_bg
    flags = np.zeros(shape, np.uint8)
    finite = np.isfinite(num) & np.isfinite(den)
    flags |= np.where(finite, 0, MaskReason.NONFINITE).astype(np.uint8)
    if on_standard is not None:
        off = ~np.asarray(on_standard, bool)
        flags |= np.where(off[..., None], MaskReason.OFF_STANDARD, 0).astype(np.uint8)
    with np.errstate(invalid="ignore"):
        if saturation is not None:
            sat = (v >= saturation) | (v_std >= saturation)
            flags |= np.where(sat, MaskReason.SATURATED, 0).astype(np.uint8)
        if saturated is not None:
            s = np.asarray(saturated, bool)
            s = s[..., None] if s.shape == shape[:-1] else s
            flags |= np.where(s, MaskReason.SATURATED, 0).astype(np.uint8)
        low = finite & ((num < noise_floor) | (den < noise_floor) | (den <= 0))
    flags |= np.where(low, MaskReason.BELOW_NOISE, 0).astype(np.uint8)
    ok = flags == 0
    f_r = np.where(ok, num / np.where(ok, den, 1.0) * (rho / np.pi), np.nan)
    return (f_r, flags) if return_flags else f_r


def sample_bilinear(image: np.ndarray, uv: np.ndarray, *, reduce_max: np.ndarray | None = None):
    """Bilinear interpolation of an ``(H, W, C)`` image at pixel coordinates ``uv (..., 2)``.

    Pixel centres are at integer ``(u, v)`` = (column, row). Coordinates
    outside ``[0, W−1] × [0, H−1]`` or NaN give NaN.

    Parameters
    ----------
    reduce_max
        Optional ``(H, W, C)`` boolean image; its logical OR over the four
        neighbours used is returned as well (e.g. "a neighbour is clipped").
    """
    h, w = image.shape[:2]
    u = uv[..., 0]
    v = uv[..., 1]
    with np.errstate(invalid="ignore"):
        ok = np.isfinite(u) & np.isfinite(v) & (u >= 0) & (u <= w - 1) & (v >= 0) & (v <= h - 1)
    us = np.where(ok, u, 0.0)
    vs = np.where(ok, v, 0.0)
    u0 = np.minimum(np.floor(us).astype(np.intp), max(w - 2, 0))
    v0 = np.minimum(np.floor(vs).astype(np.intp), max(h - 2, 0))
    u1 = np.minimum(u0 + 1, w - 1)
    v1 = np.minimum(v0 + 1, h - 1)
    fu = (us - u0)[..., None]
    fv = (vs - v0)[..., None]
    i00, i01, i10, i11 = image[v0, u0], image[v0, u1], image[v1, u0], image[v1, u1]
    out = (i00 * (1 - fu) + i01 * fu) * (1 - fv) + (i10 * (1 - fu) + i11 * fu) * fv
    out = np.where(ok[..., None], out, np.nan)
    if reduce_max is None:
        return out
    m = reduce_max
    anym = (m[v0, u0] | m[v0, u1] | m[v1, u0] | m[v1, u1]) & ok[..., None]
    return out, anym
