"""The pixel levels behind each reconstructed value, and an encoding mismatch applied to them.

A reconstructed value is a ratio of dark-subtracted pixels (image-based
paper, eq. "f_r,measured"), with ``s = ρ_std/π`` per channel::

    y = s (L_p − D_p) / (L_s − D_s)

``L`` lit, ``D`` dark, ``p`` the probe pixel, ``s`` its mirror point on the
standard (smoothed, as the ratio used it); every level is the file's code
decoded as the capture declares (``images.encoding``), full scale 1. A map
``g`` from the decoded levels to the true linear signal (the identity when
the declaration is right) changes the ratio to::

    f = s (g(L_p) − g(D_p)) / (g(L_s) − g(D_s)),   L_p = D_p + y (L_s − D_s)/s

(:func:`encoding_to_ratio`, ``df/dy = g'(L_p)(L_s − D_s)/(g(L_s) − g(D_s))``),
and back (:func:`encoding_from_ratio`)::

    L_p = g⁻¹(g(D_p) + (f/s)(g(L_s) − g(D_s))),   y = s (L_p − D_p)/(L_s − D_s)

For the encoding mismatch ``g_t(L) = L + t (h(L) − L)``, ``h`` the other
encoding's reading of a level (:class:`~wardjax.effects._library.EncodingMismatch`),
``h`` and ``h'`` are evaluated once per value, at the levels observed
(:func:`alternative_levels`): the effect is then linear in ``t`` inside the
fit, and ``g_t⁻¹`` one Newton step from the observed probe level.

The probe's dark level ``D_p`` inside ``g`` is the dark frame's *level*,
neither its noisy pixel nor a smoothed one. With the pixel, the fit regresses
the residuals (which hold the dark pixel's noise, subtracted in ``y``) on
``t (h(D_p) − D_p)``, which holds it too: an untouched wood desk read ``t`` at
Δχ² 729. Smoothed, the level loses the probe's texture, which the dark frame
holds at the ambient level, and ``t`` explains the texture's fine structure
instead (Δχ² 43 on the same capture). The level is the smoothed dark frame
times the texture the lit frame shows at that pixel, ``D̄_p = G*D · y/(G*y)``
(``G`` a Gaussian of the standard's smoothing, at least 1.5 px): its noise is
the lit value's relative noise times ``D_p``, a tenth of the dark pixel's.

The library's γ acts on the ratios alone (``f_std (f/f_std)^{1+ε}``). A power
of every level, lit and dark, ``g(L) = L^{1/(1+ε)}`` in the formulas above, is
a camera's response more exactly: on the Radiance bench's power response (a
dark frame at 2 % of full scale) it read ρs on the truth where the ratio's
power leaves it 3 % low (z −12 to −15). It is not the library's: through the
dark level's log term it gains a signature that varies with the dark frame
across the probe, and named γ on 4 of 24 untouched wardjax-drawn captures
(none with the ratio's power), on a metal at Δχ² 99.

The levels are measured by :func:`pixel_levels` for the values of a capture
(:func:`~wardjax.effects.capture_data`) and carried in
:attr:`~wardjax.effects.ScanlineData.pixels`.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable
from typing import cast

import jax.numpy as jnp
import numpy as np

__all__ = ["alternative_levels", "encoding_from_ratio", "encoding_to_ratio", "pixel_levels"]

_DARK_SMOOTH_PX = 1.5  # the dark frame's level: smoothed at least this much (Gaussian SD, pixels)
_ROOM_PX = 10.0  # the room's light on the probe: the dark frame smoothed this much (Gaussian SD, pixels)
_FLOOR_SHARE = 1.5  # a lit value up to this times its column's 10th percentile shows the texture, not the lobe
_TINY = 1e-9  # the standard's lit − dark is clamped here: a division, never by zero


def _levels(ctx):
    return ctx["lit_std"], ctx["dark_std"], ctx["dark_probe"], ctx["ref"]


def _alternative(t, ctx):
    """``g_t`` at the standard's and the dark probe's levels, and at the observed probe level with its slope."""
    ls, ds, dp, _ = _levels(ctx)

    def mix(x, hx):
        return x + t * (hx - x)

    return (
        mix(ls, ctx["alt_lit_std"]),
        mix(ds, ctx["alt_dark_std"]),
        mix(dp, ctx["alt_dark_probe"]),
        mix(ctx["lit_probe"], ctx["alt_lit_probe"]),
        1.0 + t * (ctx["alt_slope_probe"] - 1.0),
    )


def encoding_to_ratio(t, y, ctx):
    """The ratio ``f`` the true levels give under ``g_t``, and ``df/dy``, for ratios ``y`` ``(S, N, C)``.

    ``h`` at a probe level other than the observed one is taken to first order about it (exact at the
    observed values; the levels' mean slope, :meth:`~wardjax.effects.ScanlineModel._level_slope`, asks for
    others).
    """
    ls, ds, dp, s = _levels(ctx)
    gls, gds, gdp, g0, dg = _alternative(t, ctx)
    span = jnp.maximum(ls - ds, _TINY)
    lp = dp + y * span / s
    den = gls - gds
    return s * (g0 + dg * (lp - ctx["lit_probe"]) - gdp) / den, dg * span / den


def encoding_from_ratio(t, f, ctx):
    """The ratio ``y`` ``(S, N, C)`` observed under ``g_t`` for true ratios ``f``: ``g_t⁻¹`` by one Newton step from
    the observed probe level (exact to second order in the residual, which is of the order of the noise)."""
    ls, ds, dp, s = _levels(ctx)
    gls, gds, gdp, g0, dg = _alternative(t, ctx)
    lp = ctx["lit_probe"] + (gdp + f / s * (gls - gds) - g0) / dg
    return s * (lp - dp) / jnp.maximum(ls - ds, _TINY)


def alternative_levels(levels: dict[str, np.ndarray], y: np.ndarray, encoding: str) -> dict[str, np.ndarray]:
    """The other encoding's reading ``h(L) = D'(E(L))`` of every level (``alt_*``), and ``h'`` at the probe's.

    ``E`` is the declared encoding (``"srgb"`` or ``"gamma2.2"``), ``D'`` the other one's decoding; the
    probe's lit level is the observed one, ``L_p = D_p + y (L_s − D_s)/s`` (``lit_probe``; ``y`` ``(S, N, C)``,
    NaN where missing), ``h'`` there by a central difference.
    """
    from .._files import decode_values, encode_values

    other = {"srgb": "gamma2.2", "gamma2.2": "srgb"}[encoding]

    def h(x) -> np.ndarray:
        return np.asarray(decode_values(encode_values(np.clip(x, 1e-6, 1.0), encoding), other), np.float64)

    ls, ds, dp, s = (levels[k] for k in ("lit_std", "dark_std", "dark_probe", "ref"))
    lp = np.clip(dp + np.where(np.isfinite(y), y, 0.0) * (ls - ds) / s, 1e-6, 1.0)
    step = 1e-5 * lp
    return {
        "lit_probe": lp,
        "alt_lit_probe": h(lp),
        "alt_slope_probe": (h(lp + step) - h(lp - step)) / (2 * step),
        "alt_lit_std": h(ls),
        "alt_dark_std": h(ds),
        "alt_dark_probe": h(dp),
    }


def _smooth_on(img: np.ndarray, on: np.ndarray, sigma: float) -> np.ndarray:
    """``img`` ``(h, w, C)`` smoothed by a Gaussian of SD ``sigma`` px over the pixels ``on`` alone."""
    from ..reconstruct._smooth import smooth_on

    return np.asarray(smooth_on(np.where(on[..., None], img, 0.0), on, sigma), np.float64)


def _dark_level(cap, f: np.ndarray, on: np.ndarray, box) -> np.ndarray:
    """The dark frame's level ``G*D · y/(G*y)`` (module docstring) over ``box`` (a crop holding the probe's
    pixels ``on``, with room for the kernel): ``f`` the reconstructed values there."""
    if cap.dark is None:
        return np.zeros(f.shape)
    from ..reconstruct._smooth import smooth_on

    sigma = max(float(cap.config.fit.smooth_standard_px), _DARK_SMOOTH_PX)
    ok = on & np.isfinite(f).all(-1)
    with np.errstate(divide="ignore", invalid="ignore"):  # a level of 0 (black) has no texture to read: 1 below
        texture = f / smooth_on(np.where(ok[..., None], f, 0.0), ok, sigma)
    # the diffuse floor only: across a highlight the ratio is the lobe's curvature, not the texture
    with warnings.catch_warnings():  # columns off the probe have no floor: all NaN
        warnings.simplefilter("ignore", RuntimeWarning)
        floor = np.nanpercentile(np.where(ok[..., None], f, np.nan), 10, axis=0, keepdims=True)
    diffuse = f <= _FLOOR_SHARE * floor
    texture = np.where(ok[..., None] & diffuse & np.isfinite(texture), np.clip(texture, 0.5, 2.0), 1.0)
    return smooth_on(np.asarray(cap.dark[box], np.float64), on, sigma) * texture


# the veiling glare's spread (:class:`~wardjax.effects._library.VeilingGlare`): a Gaussian whose SD is the image
# width over this
GLARE_WIDTH = 6.0
_GLARE_COARSE_PX = 8.0  # the glare's blur is taken on a grid this many of its cells to the Gaussian's SD


def glare_field(lit: np.ndarray) -> tuple[np.ndarray, int]:
    """The lit frame ``(H, W, C)`` blurred by a Gaussian of SD ``W/GLARE_WIDTH`` (edges repeated), on a grid
    ``step`` pixels to a cell: ``(field, step)``, read at pixel coordinates by :func:`glare_at`.

    The frame, its edges repeated over one cell beyond each side, is averaged over ``step × step`` blocks first
    (``step`` the largest that leaves :data:`_GLARE_COARSE_PX` cells to the SD; 1 below a 96-pixel width): a blur
    this wide is as smooth as the grid, and on a 4,000-pixel photograph it would otherwise run a 5,000-tap kernel
    over every pixel. Cell ``(i, j)`` is centred on pixel ``(step (j − ½) − ½, step (i − ½) − ½)``.
    """
    from scipy.ndimage import gaussian_filter

    h, w = lit.shape[:2]
    sd = w / GLARE_WIDTH
    step = max(1, int(sd // _GLARE_COARSE_PX))
    pad = [(step, step + (-n) % step) for n in (h, w)] + [(0, 0)] * (lit.ndim - 2)
    big = np.pad(np.asarray(lit, np.float64), pad, mode="edge")
    coarse = big.reshape(big.shape[0] // step, step, big.shape[1] // step, step, -1).mean(axis=(1, 3))
    return gaussian_filter(coarse, (sd / step, sd / step, 0), mode="nearest"), step


def glare_at(field: np.ndarray, step: int, uv: np.ndarray) -> np.ndarray:
    """``field`` (:func:`glare_field`) at full-frame pixel coordinates ``uv`` ``(..., 2)`` (column, row),
    bilinearly (NaN stays NaN)."""
    from ..reconstruct import sample_bilinear

    top = np.array([field.shape[1] - 1, field.shape[0] - 1], np.float64)
    cell = np.clip((np.asarray(uv, np.float64) + 0.5) / step + 0.5, 0.0, top)
    return cast(np.ndarray, sample_bilinear(field, cell))


def pixel_levels(cap, setup, rec, bins_of: Callable) -> dict[str, np.ndarray]:
    """The levels of every value of a capture: ``lit_std``, ``dark_std``, ``dark_probe``, ``ref`` ``(S, N, C)``;
    the lit frame blurred over :data:`GLARE_WIDTH` at the probe pixel and at the standard's mirror pixel,
    ``glare_probe``, ``glare_std``, for the veiling glare (:class:`~wardjax.effects._library.VeilingGlare`);
    and the dark frame's pixels at the probe, ``dark_pixel``, with the room's light under them, ``dark_room``
    (the dark frame smoothed over ``_ROOM_PX``), for the texture's check (:mod:`~wardjax.effects._dark_texture`).

    ``setup`` is the reconstruction's first pass (the standard cropped and
    smoothed as the ratio used it), ``rec`` the reconstruction; ``bins_of``
    bins an ``(H, W, K)`` image of probe pixels as the values were binned
    (NaN off the probe). The standard's levels are sampled at each probe
    pixel's mirror point, the dark frame's level at the pixel itself
    (:func:`_dark_level`; 0 without a dark frame), then binned like the values.
    Bins without a level (the probe covers less than half of them) take the
    standard's median levels and no dark: such values are masked anyway.
    ``ref`` is ``ρ_std/π`` per channel. Only the probe's box (and the
    smoothing's margin) is worked on.
    """
    from ..geometry import mirror_point, project
    from ..reconstruct import sample_bilinear
    from ..reconstruct._band import _bbox

    kern = setup.kernel
    w, h = (int(v) for v in np.asarray(kern["std_size"]))
    std = np.asarray(kern["std"], np.float64)[:h, :w, :6]
    origin = np.asarray(kern["offset"], np.float64)
    sigma = max(float(cap.config.fit.smooth_standard_px), _DARK_SMOOTH_PX)
    box = cast(tuple[slice, slice], _bbox(rec.probe, int(np.ceil(4 * sigma)) + 2))  # the probe is not empty here
    points = np.asarray(rec.points[box], np.float64)
    on = rec.probe[box] & np.isfinite(points).all(-1)
    uv, _ = project(cap.rig.camera, mirror_point(points[on]))
    sampled = cast(np.ndarray, sample_bilinear(std, uv - origin))  # (n, 6): no ``reduce_max``, one array
    dark = _dark_level(cap, np.asarray(rec.f_r[box], np.float64), on, box)[on]
    raw = np.zeros((*on.shape, 3)) if cap.dark is None else np.asarray(cap.dark[box], np.float64)
    room = raw if cap.dark is None else _smooth_on(raw, on, _ROOM_PX)
    field, step = glare_field(np.asarray(cap.lit))
    rows, cols = np.nonzero(on)
    at_probe = np.stack([cols + box[1].start, rows + box[0].start], axis=-1).astype(np.float64)
    glare = [glare_at(field, step, at_probe), glare_at(field, step, uv)]  # at the probe, at the standard
    img = np.full((*rec.f_r.shape[:2], 21), np.nan, np.float32)  # the levels' channels, binned in one pass
    img[box][on] = np.concatenate([sampled, dark, raw[on], room[on], *glare], axis=-1)
    both = np.asarray(bins_of(img), np.float64)
    out = {"lit_std": both[..., 0:3], "dark_std": both[..., 3:6], "dark_probe": both[..., 6:9]}
    out |= {"dark_pixel": both[..., 9:12], "dark_room": both[..., 12:15]}
    out |= {"glare_probe": both[..., 15:18], "glare_std": both[..., 18:21]}
    fill = {"lit_std": float(np.nanmedian(out["lit_std"])), "dark_std": float(np.nanmedian(out["dark_std"]))}
    fill |= {"dark_probe": 0.0, "dark_pixel": 0.0, "dark_room": 0.0, "glare_probe": 0.0, "glare_std": 0.0}
    ok = np.all([np.isfinite(v) for v in out.values()], axis=0)
    out = {k: np.where(ok, v, fill[k]) for k, v in out.items()}
    rho = np.broadcast_to(np.asarray(kern["rho"], np.float64), (3,))
    out["ref"] = np.broadcast_to(rho / np.pi, out["lit_std"].shape).copy()
    return out
