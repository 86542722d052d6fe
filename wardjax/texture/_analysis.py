"""Texture analysis: the PCA-decorrelated quantile tables of pixels and subbands of a ρd map."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from .._rules import check_rho_sum
from ._histogram import quantile_probabilities
from ._jit import texture_jit
from ._model import TextureModel
from ._pyramid import (
    ORIENTATIONS,
    max_pyramid_height,
    periodic_spectrum,
    pyramid_shapes,
    pyramid_subbands,
)
from ._rank import _rank_match
from ._steerable import _MIN_SIDE, DEFAULT_HEIGHT, _check_height, _device_masks

# ======================================================================= analysis


def largest_valid_rectangle(valid) -> tuple[int, int, int, int]:
    """Largest axis-aligned rectangle of ``True`` pixels, as ``(y0, y1, x0, x1)`` (half-open).

    Row-by-row dynamic programme (the histogram method): for each column the
    height of the run of valid pixels ending at the current row, and the widest
    span around it over which every column's run is at least that tall; O(H W).
    Ties go to the first found (top-most, then left-most). Raises if no pixel is
    valid.
    """
    v = np.asarray(valid, dtype=bool)
    if v.ndim != 2:
        raise ValueError(f"valid must be a 2-D mask, got shape {v.shape}")
    h, w = v.shape
    cols = np.arange(w)
    heights = np.zeros(w, np.int64)
    left = np.zeros(w, np.int64)
    right = np.full(w, w, np.int64)
    best, best_rect = 0, None
    for y in range(h):
        row = v[y]
        heights = np.where(row, heights + 1, 0)
        cur_left = np.maximum.accumulate(np.where(row, 0, cols + 1))
        left = np.where(row, np.maximum(left, cur_left), 0)
        cur_right = np.minimum.accumulate(np.where(row, w, cols)[::-1])[::-1]
        right = np.where(row, np.minimum(right, cur_right), w)
        area = (right - left) * heights
        j = int(np.argmax(area))
        if area[j] > best:
            best = int(area[j])
            best_rect = (y + 1 - int(heights[j]), y + 1, int(left[j]), int(right[j]))
    if best_rect is None:
        raise ValueError("no valid (finite) pixel in the image")
    return best_rect


def _as_channels(rho_d, name: str = "rho_d") -> np.ndarray:
    a = np.asarray(rho_d)
    if not np.issubdtype(a.dtype, np.number) or np.iscomplexobj(a):
        raise ValueError(f"{name} must be a real array, got dtype {a.dtype}")
    if a.ndim == 2:
        a = a[..., None]
    if a.ndim != 3 or a.shape[-1] < 1:
        raise ValueError(f"{name} must have shape (H, W) or (H, W, C), got {np.shape(rho_d)}")
    return a.astype(np.float64)


def _rho_s_vector(rho_s, channels: int, name: str = "rho_s") -> np.ndarray:
    r = np.asarray(rho_s, dtype=np.float64)
    if r.ndim > 1 or (r.ndim == 1 and r.shape[0] not in (1, channels)):
        raise ValueError(f"{name} must be a scalar or hold one value per channel ({channels}), got shape {r.shape}")
    r = np.broadcast_to(r, (channels,)).copy()
    if not (np.isfinite(r).all() and np.all((r >= 0) & (r < 1))):
        raise ValueError(f"{name}={rho_s!r} must lie in [0, 1)")
    return r


@texture_jit
def _pixel_moments(x: Float[Array, "h w c"]) -> tuple[Float[Array, " c"], Float[Array, "c c"]]:
    """Mean and sample covariance (divided by ``n − 1``, as ``np.cov``) of the pixels of ``x`` (float64)."""
    p = x.reshape(-1, x.shape[-1])
    mean = p.mean(axis=0)
    p = p - mean[None]
    return mean, (p.T @ p) / max(1, p.shape[0] - 1)


def _pca(mean: np.ndarray, cov: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Mean and orthonormal principal axes (columns, variance descending, largest component positive)."""
    evals, evecs = np.linalg.eigh(cov)
    evecs = evecs[:, np.argsort(evals)[::-1]]
    sign = np.sign(evecs[np.argmax(np.abs(evecs), axis=0), np.arange(evecs.shape[1])])
    return mean, evecs * np.where(sign == 0, 1.0, sign)


def _subband_shapes(shapes) -> tuple[tuple[int, int], ...]:
    """Grid of every subband in :func:`~wardjax.texture._pyramid.pyramid_subbands` order."""
    return (shapes[0], *(s for s in shapes[:-1] for _ in range(ORIENTATIONS)), shapes[-1])


def _groups(subbands, c: int) -> tuple:
    """Subbands as sorting rows ``(C, 1, n)``, one array per subband (highpass, levels × orientations, lowpass)."""
    return tuple(b.reshape(c, 1, -1) for b in subbands)


@texture_jit(static_argnames="shapes")
def _analysis_groups(x, mean, axis, masks, shapes):
    """One decorrelated channel ``d = (x − μ) · axis`` (float32) → periodic component → pyramid → subband groups,
    then the pixels ``(1, 1, H W)``."""
    d = ((x - mean[None, None]) @ axis).astype(jnp.float32)[None]
    return _groups(pyramid_subbands(periodic_spectrum(d), masks, shapes), 1) + (d.reshape(1, 1, -1),)


def _quantile_picks(n: int, probs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Order statistics for quantiles at ``probs`` (linear interpolation at position ``p (n − 1)``).

    Returns the positions ``(i0…, i1…)`` to read from the sorted sample and the weights ``w``:
    ``quantile = x_(i0) (1 − w) + x_(i1) w``.
    """
    pos = probs * (n - 1.0)
    i0 = np.clip(np.floor(pos).astype(np.int64), 0, n - 1)
    i1 = np.minimum(i0 + 1, n - 1)
    return np.concatenate([i0, i1]).astype(np.intp), pos - i0


def analyze_texture(
    rho_d,
    *,
    region: tuple[int, int, int, int] | None = None,
    height: int | None = None,
    n_quantiles: int = 129,
    rho_s=0.0,
    max_side: int | None = None,
) -> TextureModel:
    """Parametric description of a ρd texture (image-based paper, section 4.2; Heeger & Bergen 1995).

    1. Pick the pixels: ``region`` if given (it must hold no NaN), else the whole
       image if every pixel is finite, else the largest rectangle of pixels that
       are finite in every channel (:func:`largest_valid_rectangle`; NaN marks
       pixels without reference data). :attr:`TextureModel.region_source` says
       which.
    2. Decorrelate the channels with a PCA, ``d = Vᵀ (x − μ)``.
    3. Per channel: quantiles of the pixels of ``d``; periodic component of ``d``
       (:func:`periodic_smooth_decomposition`); steerable pyramid; quantiles of
       every subband (the CDFs the paper keeps).

    Parameters
    ----------
    rho_d
        ``(H, W, C)`` or ``(H, W)`` diffuse reflectance (linear), NaN where invalid.
    region
        ``(y0, y1, x0, x1)``, half-open pixel rectangle to analyse.
    height
        Pyramid levels; default ``min(4, floor(log2(min side)) − 2)``.
    n_quantiles
        Entries per quantile table (≥ 2; 129 keeps the CDF to better than 1 %).
    rho_s
        Specular reflectance of the material (scalar or per channel); synthesis
        clamps ρd to ``[0, 1 − ρs]`` (energy conservation).
    max_side
        If given, a region (step 1) longer than this on a side is cut to its
        centred ``max_side``-long part (``region_source`` says so): the model
        keeps quantiles, which a few million pixels determine as well as tens
        of millions, while the pyramid's memory grows with the pixels
        (:func:`wardjax.write_capture_outputs` uses 2048 for big captures).

    Returns
    -------
    TextureModel
    """
    a = _as_channels(rho_d)
    h, w, c = a.shape
    if isinstance(n_quantiles, bool) or not isinstance(n_quantiles, (int, np.integer)) or n_quantiles < 2:
        raise ValueError(f"n_quantiles={n_quantiles!r}, expected an integer >= 2")
    bad = ~np.isfinite(a)
    if region is not None:
        try:
            y0, y1, x0, x1 = (int(v) for v in region)
        except (TypeError, ValueError):
            raise ValueError(f"region={region!r}, expected (y0, y1, x0, x1)") from None
        if not (0 <= y0 < y1 <= h and 0 <= x0 < x1 <= w):
            raise ValueError(f"region={tuple(region)!r} is not a non-empty rectangle inside the {h}x{w} image")
        if bad[y0:y1, x0:x1].any():
            n_bad = int(bad[y0:y1, x0:x1].any(axis=-1).sum())
            raise ValueError(f"region={tuple(region)!r} holds {n_bad} NaN/inf pixels; choose a region of valid pixels")
        source = "argument"
    elif not bad.any():
        y0, y1, x0, x1 = 0, h, 0, w
        source = "whole image"
    else:
        y0, y1, x0, x1 = largest_valid_rectangle(~bad.any(axis=-1))
        source = "largest valid rectangle"
    rh, rw = y1 - y0, x1 - x0
    if max_side is not None and max(rh, rw) > max_side:
        y0, x0 = y0 + max(rh - max_side, 0) // 2, x0 + max(rw - max_side, 0) // 2
        y1, x1 = y0 + min(rh, max_side), x0 + min(rw, max_side)
        rh, rw = y1 - y0, x1 - x0
        source = f"{source}, centred {rh}x{rw} part"
    if min(rh, rw) < _MIN_SIDE:
        raise ValueError(
            f"the analysed region (rows {y0}:{y1}, columns {x0}:{x1}, {source}) is {rh}x{rw} pixels; "
            f"need at least {_MIN_SIDE}x{_MIN_SIDE}"
        )
    height = min(DEFAULT_HEIGHT, max_pyramid_height((rh, rw))) if height is None else height
    height = _check_height(height, (rh, rw), "the analysed region")
    rho_s_vec = _rho_s_vector(rho_s, c)
    check_rho_sum("rho_s", a[y0:y1, x0:x1], rho_s_vec)  # ρd + ρs ≤ 1: energy conservation

    shapes = pyramid_shapes((rh, rw), height)
    probs = quantile_probabilities(int(n_quantiles))
    with jax.enable_x64(True):
        x = jnp.asarray(a[y0:y1, x0:x1], jnp.float64)
        mean, basis = _pca(*(np.asarray(m) for m in _pixel_moments(x)))
        masks = _device_masks((rh, rw), height, "float32")
        # One channel per XLA program (small buffers); XLA builds the next channel while the host sorts one.
        per_channel = [_analysis_groups(x, mean, basis[:, ch], masks, shapes) for ch in range(c)]
        picks = [_quantile_picks(g.shape[-1], probs) for g in per_channel[0]]
        picked = [_rank_match(groups, None, tuple(p for p, _ in picks))[1] for groups in per_channel]
    tables = []  # quantile = x_(i0) (1 − λ) + x_(i1) λ
    for g, (_, lam) in enumerate(picks):
        v = np.concatenate([np.asarray(p[g], np.float64) for p in picked])
        tables.append(v[..., : probs.size] * (1.0 - lam) + v[..., probs.size :] * lam)
    band_q = np.concatenate(tables[:-1], axis=1)  # (C, B, Q)
    return TextureModel(
        pca_mean=mean,
        pca_basis=basis,
        probabilities=probs,
        pixel_quantiles=tables[-1][:, 0],
        band_quantiles=band_q,
        height=height,
        rho_s=rho_s_vec,
        source_shape=(h, w),
        region=(y0, y1, x0, x1),
        region_source=source,
    )
