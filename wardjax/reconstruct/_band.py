"""The compiled reconstruction: every probe pixel's BRDF value, band by band.

Image-based paper, section 3: the value of a probe pixel ``p`` is
``f_r = (v − v_bg)/(v_std − v_std,bg) · ρ_std/π`` with ``v_std`` sampled at the
mirror point of ``p`` on the standard (eq. "f_r,measured"). This is the jitted
form of :func:`~wardjax.reconstruct.reconstruct_brdf` (the NumPy reference),
fused with the rig's per-pixel geometry.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Iterator
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from numpy.typing import DTypeLike

from .. import _shapes
from ..geometry import band_geometry_jnp, rig_constants
from ._reference import MaskReason
from ._smooth import smooth_on as _smooth_on

__all__ = ["BandSetup", "Reconstruction", "prepare_bands", "reconstruct_bands", "reconstruct_capture"]


def _bbox(mask: np.ndarray, pad: int) -> tuple[slice, slice] | None:
    """Row and column slices of ``mask``'s bounding box grown by ``pad`` (clipped to the image)."""
    rows = np.flatnonzero(mask.any(axis=1))
    if rows.size == 0:
        return None
    cols = np.flatnonzero(mask.any(axis=0))
    h, w = mask.shape
    return (
        slice(max(rows[0] - pad, 0), min(rows[-1] + 1 + pad, h)),
        slice(max(cols[0] - pad, 0), min(cols[-1] + 1 + pad, w)),
    )


class Reconstruction(NamedTuple):
    """Per-pixel BRDF values of a capture (image-based paper, section 3), on the image grid.

    Attributes
    ----------
    f_r
        ``(H, W, 3)`` reconstructed BRDF (sr⁻¹); NaN off the probe and where masked.
    flags
        ``(H, W)`` :class:`~wardjax.MaskReason` bits of each probe pixel.
    wi, wo
        ``(H, W, 3)`` directions to lamp and camera in the material frame (0 off the probe).
    points
        ``(H, W, 3)`` sample-plane positions (mm); NaN off the probe.
    probe
        ``(H, W)`` the pixel sees the probe.
    f_clip
        ``(H, W, 3)`` where the pixel's own lit value is clipped (and nothing
        else masks it), the clip level as a BRDF value: a lower bound on the
        true ``f_r`` there (``f_r`` itself is NaN, flagged ``SATURATED``); NaN
        elsewhere. ``None`` unless asked for (``clip_bounds=True``).
    """

    f_r: np.ndarray
    flags: np.ndarray
    wi: np.ndarray
    wo: np.ndarray
    points: np.ndarray
    probe: np.ndarray
    f_clip: np.ndarray | None = None

    @property
    def censored(self) -> np.ndarray | None:
        """``(H, W, 3)`` bool: :attr:`f_clip` holds a bound (a censored observation); ``None`` without it."""
        return None if self.f_clip is None else np.isfinite(self.f_clip)


def _sample_bilinear_jnp(image, uv, size):
    """:func:`~wardjax.reconstruct.sample_bilinear` in ``jnp``: values and "a neighbour is clipped".

    ``image`` is ``(h', w', C + 3)``: ``C`` values, then the 3 clipped flags
    as 0/1. Only its first ``size = (w, h)`` (int32, traced) columns and rows
    are the image; the rest is padding (see :func:`~wardjax._shapes.bucket`), never read.
    """
    c3 = image.shape[-1]
    w, h = size[0], size[1]
    u, v = uv[..., 0], uv[..., 1]
    wm1, hm1 = (w - 1).astype(u.dtype), (h - 1).astype(v.dtype)
    ok = jnp.isfinite(u) & jnp.isfinite(v) & (u >= 0) & (u <= wm1) & (v >= 0) & (v <= hm1)
    us, vs = jnp.where(ok, u, 0.0), jnp.where(ok, v, 0.0)
    u0 = jnp.minimum(jnp.floor(us).astype(jnp.int32), jnp.maximum(w - 2, 0))
    v0 = jnp.minimum(jnp.floor(vs).astype(jnp.int32), jnp.maximum(h - 2, 0))
    u1, v1 = jnp.minimum(u0 + 1, w - 1), jnp.minimum(v0 + 1, h - 1)
    fu, fv = (us - u0.astype(us.dtype))[..., None], (vs - v0.astype(vs.dtype))[..., None]
    i00, i01, i10, i11 = image[v0, u0], image[v0, u1], image[v1, u0], image[v1, u1]
    c = c3 - 3
    out = (i00[..., :c] * (1 - fu) + i01[..., :c] * fu) * (1 - fv) + (i10[..., :c] * (1 - fu) + i11[..., :c] * fu) * fv
    clip = jnp.maximum(jnp.maximum(i00[..., c:], i01[..., c:]), jnp.maximum(i10[..., c:], i11[..., c:])) > 0
    return jnp.where(ok[..., None], out, jnp.nan), clip & ok[..., None]


@functools.partial(jax.jit, static_argnames=("width", "height"))
def _masks_kernel(k, rows, *, width: int, height: int):
    """The probe and standard masks of a band (the rest of the geometry is compiled away)."""
    g = band_geometry_jnp(k, rows, width=width, height=height)
    return g.in_probe, g.in_standard


@functools.partial(jax.jit, static_argnames=("width", "height", "ncols"))
def _reconstruct_band(
    k,
    rows,
    col0,
    lit,
    dark,
    clipped,
    std,
    std_size,
    offset,
    rho,
    noise_floor,
    saturation,
    *,
    width: int,
    height: int,
    ncols: int,
):
    """Geometry, mirror sampling and eq. "f_r,measured" of a band of rows, fused (dtype of ``k``).

    The same computation as :func:`~wardjax.geometry.pixel_geometry`,
    :func:`~wardjax.reconstruct.sample_bilinear` and
    :func:`~wardjax.reconstruct.reconstruct_brdf` (the NumPy references,
    tested equal). ``std`` is the cropped standard ``(h', w', 9)``: lit,
    dark, clipped, of which the first ``std_size = (w, h)`` are real (the rest
    padding); ``offset`` its ``(u, v)`` origin in the image. Columns ``col0 …
    col0 + ncols − 1`` (those through the probe, and padding past them). The
    band's and the crop's shapes are bucketed (:func:`~wardjax._shapes.bucket`), so they
    and ``ncols`` vary little between captures of one rig.

    Also the clip bound of each probe pixel whose *own* lit value is clipped
    and which nothing else masks (its mirror point unclipped, on the
    standard, above the noise floor): the true lit value is at least
    ``saturation`` (the capture's clip level), so

    .. math:: f_r ≥ \frac{v_{sat} − v_{bg}}{v_{std} − v_{std,bg}} \frac{ρ_{std}}{π},

    a censored observation; NaN elsewhere. A clipped mirror point gives no
    bound (it underestimates the denominator).
    """
    pts, wi, wo, probe, _, muv, mok = band_geometry_jnp(k, rows, width=width, height=height, col0=col0, ncols=ncols)
    sampled, clip_std = _sample_bilinear_jnp(std, muv - offset[None, None, :], std_size)
    v_std, v_std_bg = sampled[..., :3], sampled[..., 3:]
    num = lit.astype(k.dtype) - dark.astype(k.dtype)
    den = v_std - v_std_bg
    finite = jnp.isfinite(num) & jnp.isfinite(den)
    u8 = lambda cond, reason: jnp.where(cond, jnp.uint8(reason), jnp.uint8(0))
    fl = (
        u8(~finite, MaskReason.NONFINITE)
        | u8(~mok[..., None], MaskReason.OFF_STANDARD)
        | u8(clipped | clip_std, MaskReason.SATURATED)
        | u8(finite & ((num < noise_floor) | (den < noise_floor) | (den <= 0)), MaskReason.BELOW_NOISE)
    )
    ok = (fl == 0) & probe[..., None]
    f_r = jnp.where(ok, num / jnp.where(ok, den, 1.0) * (rho / jnp.pi)[None, None, :], jnp.nan)
    num_sat = saturation - dark.astype(k.dtype)
    bound = (clipped & ~clip_std & (fl == MaskReason.SATURATED) & (num_sat >= noise_floor)) & probe[..., None]
    f_clip = jnp.where(bound, num_sat / jnp.where(bound, den, 1.0) * (rho / jnp.pi)[None, None, :], jnp.nan)
    flags = jnp.where(probe, fl[..., 0] | fl[..., 1] | fl[..., 2], jnp.uint8(0))
    pts = jnp.where(probe[..., None], pts, jnp.nan)
    wi = jnp.where(probe[..., None], wi, 0.0)
    wo = jnp.where(probe[..., None], wo, 0.0)
    return f_r, flags, wi, wo, pts, f_clip  # which pixels see the probe: the first pass already has it


class BandSetup(NamedTuple):
    """What the band pass of :func:`reconstruct_bands` needs, from the first pass over a capture.

    Attributes
    ----------
    probe
        ``(H, W)`` bool: the pixel sees the probe.
    box
        Row and column slices of the probe's bounding box, ``None`` if no pixel sees it.
    kernel
        The constant arguments of the band kernel (rig, cropped standard, …), in ``dtype``.
    dtype
        Storage and precision of the reconstruction.
    """

    probe: np.ndarray
    box: tuple[slice, slice] | None
    kernel: dict
    dtype: np.dtype


def prepare_bands(cap, *, band_rows: int = 512, dtype: DTypeLike = np.float32) -> BandSetup:
    """The first pass of :func:`reconstruct_capture`: the probe, its box and the standard, cropped and smoothed.

    Which pixels see the probe and the standard, band by band (one compiled
    program); the standard's image is cropped there and smoothed
    (``fit.smooth_standard_px``) for the mirror sampling of every band.
    """
    cfg, rig = cap.config, cap.rig
    h, w = rig.camera.height, rig.camera.width
    dtype = np.dtype(dtype)
    hb = max(1, min(band_rows, h))
    probe = np.zeros((h, w), bool)
    on_std = np.empty((h, w), bool)
    dims = {"width": w, "height": h}
    with jax.enable_x64(dtype == np.float64):
        k = jnp.asarray(rig_constants(rig, cap.tangent), dtype)
        for r0 in range(0, h, hb):
            r1 = min(r0 + hb, h)
            pm, sm = _masks_kernel(k, np.arange(r0, r0 + hb, dtype=dtype), **dims)
            probe[r0:r1], on_std[r0:r1] = np.asarray(pm)[: r1 - r0], np.asarray(sm)[: r1 - r0]
        pbox = _bbox(probe, 0)
        if pbox is None:
            return BandSetup(probe, None, {}, dtype)
        sigma = cfg.fit.smooth_standard_px
        box = _bbox(on_std, int(math.ceil(4 * sigma)) + 2) or (slice(0, min(2, h)), slice(0, min(2, w)))
        lit_std, dark_std, clip_std = cap.window(*box)  # the standard's crop only is read
        dark_std = np.zeros_like(lit_std) if dark_std is None else dark_std
        if sigma > 0:
            std_mask = on_std[box] & ~clip_std.any(axis=-1)
            lit_std = _smooth_on(lit_std, std_mask, sigma)
            dark_std = dark_std if cap.images.dark is None else _smooth_on(dark_std, std_mask, sigma)
        std = np.concatenate([lit_std, dark_std, clip_std.astype(np.float32)], -1)
        del lit_std, dark_std, clip_std
        kernel = {
            "k": k,
            "std_size": jnp.asarray([std.shape[1], std.shape[0]], jnp.int32),
            "std": jnp.asarray(
                _shapes.pad_to_shape(std, (_shapes.bucket(std.shape[0]), _shapes.bucket(std.shape[1]))), dtype
            ),
            "offset": jnp.asarray([box[1].start, box[0].start], dtype),
            "rho": jnp.asarray(np.broadcast_to(cap.rho_standard, (3,)), dtype),
            "noise_floor": jnp.asarray(cfg.fit.noise_floor, dtype),
            "saturation": jnp.asarray(cap.saturation, dtype),
        }
    return BandSetup(probe, pbox, kernel, dtype)


def reconstruct_bands(cap, setup: BandSetup, step: int) -> Iterator[tuple[slice, tuple]]:
    """The second pass of :func:`reconstruct_capture`, one band of ``step`` rows of the probe's box at a time.

    Yields ``(rows, (f_r, flags, wi, wo, points, f_clip))``: the image rows
    of the band and the band's values over the box's columns (see
    :class:`Reconstruction`), so that a caller keeps only what it needs of
    each band (:func:`wardjax.fit_capture` bins them for the fit and extracts
    ρd from them; a whole image of each need not exist). The images are read
    the same way: each band's rows of lit and dark only
    (:meth:`~wardjax.Capture.window`). The kernel sees every band padded to
    one bucketed shape (one compiled program).
    """
    if setup.box is None:
        return
    dtype, kern = setup.dtype, setup.kernel
    h, w = setup.probe.shape
    rows_p, cols = setup.box
    step = max(1, min(step, rows_p.stop - rows_p.start))
    bucket, pad = _shapes.bucket, _shapes.pad_to_shape
    band = (bucket(step), bucket(cols.stop - cols.start))
    zeros = np.zeros(band + (3,), np.float32)
    for r0 in range(rows_p.start, rows_p.stop, step):
        r1 = min(r0 + step, rows_p.stop)
        n, m = r1 - r0, cols.stop - cols.start
        lit, dark, clipped = cap.window(slice(r0, r1), cols)  # the band's rows only are read and decoded
        dark = zeros if dark is None else pad(dark, band)
        with jax.enable_x64(dtype == np.float64):
            out = _reconstruct_band(
                kern["k"],
                np.arange(r0, r0 + band[0], dtype=dtype),
                jnp.asarray(cols.start, dtype),
                pad(lit, band),
                dark,
                pad(clipped, band),
                kern["std"],
                kern["std_size"],
                kern["offset"],
                kern["rho"],
                kern["noise_floor"],
                kern["saturation"],
                width=w,
                height=h,
                ncols=band[1],
            )
            values = tuple(np.asarray(o)[:n, :m] for o in out)
        yield slice(r0, r1), values  # outside the x64 scope: the caller's code runs between bands


def reconstruct_capture(
    cap,
    *,
    band_rows: int = 512,
    dtype: DTypeLike = np.float32,
    clip_bounds: bool = False,
    setup: BandSetup | None = None,
) -> Reconstruction:
    """Reconstruct ``f_r`` for every probe pixel of a ``method = "scanline"`` capture.

    Two passes over bands of ``band_rows`` rows, each one compiled program
    (``jnp``, in ``dtype``). First, which pixels see the probe and the standard; the standard's image
    is cropped there and smoothed (``fit.smooth_standard_px``); the standard
    is uniform and Lambertian, so it varies only slowly with irradiance and
    vignetting, and smoothing removes its noise and quantisation from every
    reconstructed value (:func:`prepare_bands`). Then, per band of the
    probe's rows and columns only, the geometry of each pixel
    (:func:`~wardjax.geometry.band_geometry_jnp`), its mirror point on the
    standard sampled bilinearly, and eq. "f_r,measured" with its masks
    (:func:`~wardjax.reconstruct_brdf`), fused (:func:`reconstruct_bands`). ``dtype`` sets the storage
    and the precision (float32 keeps a 12 MP capture in memory and is ~10⁻⁴
    px accurate in the mirror mapping; float64 for the effects workflow).
    ``clip_bounds`` also keeps :attr:`Reconstruction.f_clip`, the lower
    bound of every probe pixel clipped by the sensor (censored data for
    :func:`wardjax.effects.discover`; one more image in memory). ``setup`` is the first
    pass when the caller made it already (in ``dtype``), to check it first.
    """
    h, w = cap.rig.camera.height, cap.rig.camera.width
    dtype = np.dtype(dtype)
    if setup is None:
        setup = prepare_bands(cap, band_rows=band_rows, dtype=dtype)
    f_r = np.full((h, w, 3), np.nan, dtype)
    wi = np.zeros((h, w, 3), dtype)
    wo = np.zeros((h, w, 3), dtype)
    points = np.full((h, w, 3), np.nan, dtype)
    flags = np.zeros((h, w), np.uint8)
    f_clip = np.full((h, w, 3), np.nan, dtype) if clip_bounds else None
    if setup.box is not None:
        cols = setup.box[1]
        for rows, out in reconstruct_bands(cap, setup, max(1, min(band_rows, h))):
            for dst, src in zip((f_r, flags, wi, wo, points, f_clip), out):
                if dst is not None:
                    dst[rows, cols] = src
    return Reconstruction(f_r, flags, wi, wo, points, setup.probe, f_clip)
