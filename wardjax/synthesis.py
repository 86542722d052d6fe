"""Parametric texture: steerable-pyramid analysis and Heeger–Bergen synthesis.

Image-based paper, section 4.2: the measured ρd texture is described by the
cumulative distribution functions (CDFs) of the subbands of a steerable pyramid
with four orientation bands, and textures of any size are synthesised from noise
by *histogram matching*: build the pyramid of the current image, give every
subband the distribution of the source's, collapse the pyramid, give the pixels
the source's distribution, and repeat (Heeger & Bergen 1995; the paper uses
three iterations, we default to five).

The description (:class:`TextureModel`) holds, per colour channel after a PCA
decorrelation of RGB, the quantile table (inverse CDF) of the pixels and of
every subband: highpass residual, ``height × 4`` oriented bands, lowpass
residual. It is saved as one small JSON or NPZ file.

Known limitation (the method's, not this implementation's): only marginal
statistics of subbands are kept, so textures whose look comes from *regular*
structure (bricks, weaves, grids, periodic stripes) or from long coherent
features lose it; the synthesis has the right local contrasts and orientations
at each scale but the arrangement is random. See ``tests/test_synthesis.py``
(``test_limitation_regular_texture_is_lost``).

Numerics: the pyramid runs in the input's float dtype (float64 for the
``steerable_pyramid`` functions when given float64); analysis and synthesis run
in float32 (a ρd texture needs no more). Exact histogram matching needs a full
sort of every subband: on CPU it is done by NumPy on a thread pool (XLA's CPU
sort is 4-5 times slower), on other backends by ``jax.lax.sort``; both sort
distinct keys in the same order, so they give the same permutation and
identical results. Synthesis handles one channel per XLA program and interleaves the
channels, so the host sorts one while XLA transforms another.
"""

from __future__ import annotations

import concurrent.futures
import functools
import json
import math
import os
import tempfile
from pathlib import Path
from typing import Callable, Literal

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from ._pyramid import (
    ORIENTATIONS,
    max_pyramid_height,
    periodic_smooth,
    periodic_spectrum,
    pyramid_build,
    pyramid_collapse,
    pyramid_subbands,
    pyramid_masks,
    pyramid_reconstruct,
    pyramid_shapes,
)

__all__ = [
    "TEXTURE_FORMAT_VERSION",
    "SteerablePyramid",
    "SynthesisResult",
    "TextureModel",
    "analyze_texture",
    "build_steerable_pyramid",
    "largest_valid_rectangle",
    "match_histogram",
    "quantile_probabilities",
    "periodic_smooth_decomposition",
    "reconstruct_steerable_pyramid",
    "synthesize_texture",
]

TEXTURE_FORMAT = "wardjax.texture"
TEXTURE_FORMAT_VERSION = 1
"""Version of the saved texture description; bumped when the file layout changes."""

DEFAULT_HEIGHT = 4
"""Pyramid levels used when the region allows (fewer for small regions)."""

_MIN_SIDE = 8  # smallest region/output side: a pyramid of height 1 needs 8 pixels


# ======================================================================= pyramid


class SteerablePyramid(eqx.Module):
    """Subbands of a steerable pyramid (four orientations), finest level first.

    Attributes
    ----------
    highpass
        ``(..., H, W)`` high-pass residual (frequencies above half Nyquist).
    bands
        Tuple of ``height`` arrays; level ``l`` is ``(..., 4, H_l, W_l)`` with
        ``H_{l+1} = ceil(H_l / 2)``, orientation ``b`` tuned to ``θ = π b / 4``
        (``cos³(θ − π b / 4)`` angular response; θ measured from the image's x
        axis towards +y, i.e. downwards).
    lowpass
        ``(..., H_height, W_height)`` low-pass residual; keeps the image mean.

    Coefficients are band-passed images sampled on each level's grid, so their
    amplitude does not depend on image size (pyrtools' ``SteerablePyramidFreq``
    bands equal these times ``H W / (H_l W_l)``).
    """

    highpass: np.ndarray
    bands: tuple[np.ndarray, ...]
    lowpass: np.ndarray

    @property
    def height(self) -> int:
        return len(self.bands)

    @property
    def shape(self) -> tuple[int, int]:
        return tuple(self.highpass.shape[-2:])

    def subbands(self) -> dict[str, np.ndarray]:
        """All subbands by name: ``highpass``, ``level{l}_orient{b}``, ``lowpass``."""
        out = {"highpass": self.highpass}
        for level, band in enumerate(self.bands):
            for b in range(ORIENTATIONS):
                out[f"level{level}_orient{b}"] = band[..., b, :, :]
        out["lowpass"] = self.lowpass
        return out


def band_names(height: int) -> tuple[str, ...]:
    """Names of the subbands of a pyramid of ``height`` levels, in storage order."""
    return ("highpass", *(f"level{lv}_orient{b}" for lv in range(height) for b in range(ORIENTATIONS)), "lowpass")


@functools.lru_cache(maxsize=16)
def _device_masks(shape: tuple[int, int], height: int, dtype: str) -> dict:
    return jax.tree_util.tree_map(lambda a: jnp.asarray(a, dtype), pyramid_masks(shape, height))


def _float_dtype(a: np.ndarray) -> np.dtype:
    return np.dtype(np.float64) if a.dtype == np.float64 else np.dtype(np.float32)


def _check_height(height: int, shape: tuple[int, int], what: str) -> int:
    top = max_pyramid_height(shape)
    if isinstance(height, bool) or not isinstance(height, (int, np.integer)) or not 0 <= height <= top:
        raise ValueError(
            f"height={height!r} is not possible for {what} of {shape[0]}x{shape[1]} pixels: "
            f"expected an integer in [0, {top}] (floor(log2(min side)) - 2)"
        )
    return int(height)


def build_steerable_pyramid(image, height: int = DEFAULT_HEIGHT) -> SteerablePyramid:
    """Steerable pyramid (4 orientations, frequency domain) of one image or a stack.

    Simoncelli & Freeman (1995) in the Fourier domain, as used by Heeger & Bergen
    (1995) and the image-based paper (section 4.2). With ``X`` the DFT of the
    image, normalised by ``H W``, and ``u = log2 r`` the log radial frequency
    (``r = 1`` at Nyquist):

    * highpass ``= IDFT(X hi0)``, ``hi0(u) = cos(π u / 2)`` on ``[−1, 0]``;
    * ``Z_0 = X lo0``, ``lo0 = sqrt(1 − hi0²)``;
    * band ``(l, b)`` ``= IDFT_l(i Z_l A_b(θ) hi(u + l + 1))`` with
      ``A_b(θ) = sqrt(0.8) cos³(θ − π b / 4)``;
    * ``Z_{l+1}`` = the coefficients of ``Z_l`` on a grid ``ceil(·/2)`` as large,
      times ``lo(u + l + 1)``; the lowpass residual is ``IDFT(Z_height)``.

    Since ``hi² + lo² = 1`` and ``Σ_b A_b² = 1`` the transform is a tight frame,
    and :func:`reconstruct_steerable_pyramid` inverts it exactly (to rounding)
    for every size, odd sizes included. Boundaries are periodic: apply
    :func:`periodic_smooth_decomposition` first to analyse a photograph.

    Parameters
    ----------
    image
        ``(..., H, W)`` real image(s). float64 input is transformed in float64,
        anything else in float32.
    height
        Number of band-pass levels, ``0 ≤ height ≤ floor(log2(min(H, W))) − 2``.

    Returns
    -------
    SteerablePyramid
        NumPy arrays in the working dtype.
    """
    a = np.asarray(image)
    if a.ndim < 2 or not np.issubdtype(a.dtype, np.number) or np.iscomplexobj(a):
        raise ValueError(f"image must be a real array of shape (..., H, W), got dtype {a.dtype} shape {a.shape}")
    dtype = _float_dtype(a)
    shape = tuple(a.shape[-2:])
    height = _check_height(height, shape, "an image")
    lead = a.shape[:-2]
    with jax.enable_x64(True):
        x = jnp.asarray(a.reshape(-1, *shape), dtype)
        hp, bands, lp = pyramid_build(x, _device_masks(shape, height, dtype.name), pyramid_shapes(shape, height))
        return SteerablePyramid(
            highpass=np.asarray(hp).reshape(*lead, *hp.shape[-2:]),
            bands=tuple(np.asarray(b).reshape(*lead, *b.shape[-3:]) for b in bands),
            lowpass=np.asarray(lp).reshape(*lead, *lp.shape[-2:]),
        )


def reconstruct_steerable_pyramid(pyramid: SteerablePyramid) -> np.ndarray:
    """Collapse a :class:`SteerablePyramid` back into an image (the exact inverse of the build).

    ``Z_l = pad(Z_{l+1} lo_l) + Σ_b DFT_l(band_lb) (−i A_b hi_l)``,
    ``X = Z_0 lo0 + DFT(highpass) hi0``, image ``= IDFT(X)``. Subbands may have been
    modified (that is what synthesis does); their shapes must be those a build
    of the same image size gives.

    Returns
    -------
    ndarray ``(..., H, W)`` in the pyramid's dtype (float32 or float64).
    """
    hp = np.asarray(pyramid.highpass)
    shape = tuple(hp.shape[-2:])
    height = len(pyramid.bands)
    _check_height(height, shape, "a pyramid")
    shapes = pyramid_shapes(shape, height)
    lead = hp.shape[:-2]
    for level, band in enumerate(pyramid.bands):
        want = (*lead, ORIENTATIONS, *shapes[level])
        if np.shape(band) != want:
            raise ValueError(f"pyramid.bands[{level}] has shape {np.shape(band)}, expected {want}")
    if np.shape(pyramid.lowpass) != (*lead, *shapes[-1]):
        raise ValueError(f"pyramid.lowpass has shape {np.shape(pyramid.lowpass)}, expected {(*lead, *shapes[-1])}")
    dtype = _float_dtype(hp)
    with jax.enable_x64(True):
        out = pyramid_reconstruct(
            jnp.asarray(hp.reshape(-1, *shape), dtype),
            tuple(jnp.asarray(np.reshape(b, (-1, ORIENTATIONS, *s)), dtype) for b, s in zip(pyramid.bands, shapes)),
            jnp.asarray(np.reshape(pyramid.lowpass, (-1, *shapes[-1])), dtype),
            _device_masks(shape, height, dtype.name),
            shapes,
        )
        return np.asarray(out).reshape(*lead, *shape)


def periodic_smooth_decomposition(image) -> tuple[np.ndarray, np.ndarray]:
    """Split ``image = periodic + smooth`` (Moisan 2011) so the FFT sees no border discontinuity.

    ``smooth`` solves the periodic discrete Poisson equation ``Δ s = v`` where
    ``v`` is zero except on the border, where it holds the jumps across the
    wrap-around edges (``v[0, :] = u[−1, :] − u[0, :] = −v[−1, :]``, likewise on
    columns); ``periodic = image − smooth``. ``smooth`` has zero mean and is
    harmonic inside the image, so the periodic component keeps the texture and
    drops the cross-shaped artefact a plain FFT has.

    Parameters
    ----------
    image
        ``(..., H, W)`` real image(s), float64 kept, others in float32.

    Returns
    -------
    periodic, smooth : ndarray ``(..., H, W)``
    """
    a = np.asarray(image)
    if a.ndim < 2 or not np.issubdtype(a.dtype, np.number) or np.iscomplexobj(a):
        raise ValueError(f"image must be a real array of shape (..., H, W), got dtype {a.dtype} shape {a.shape}")
    if not np.isfinite(a).all():
        raise ValueError("image holds NaN or inf; crop to valid pixels first (see largest_valid_rectangle)")
    dtype = _float_dtype(a)
    with jax.enable_x64(True):
        p, s = periodic_smooth(jnp.asarray(a.reshape(-1, *a.shape[-2:]), dtype))
        return np.asarray(p).reshape(a.shape), np.asarray(s).reshape(a.shape)


# ============================================================ histogram matching
#
# Exact matching gives the k-th smallest of n values the target quantile at
# probability (k + 1/2) / n. Ranks come from one sort of distinct 64-bit keys
# that carry the value and the position; the permutation is therefore unique
# and deterministic, and the sorted keys also give back the sorted values.
#
# Where the sort runs. XLA's CPU sort calls a compiled comparator per
# comparison and is 4-5x slower than NumPy's vectorised (AVX2) sort, so on CPU
# the rank step (pack, sort, scatter the targets into rank order) runs in
# NumPy, one row per task on a thread pool (NumPy releases the GIL); elsewhere
# it runs in XLA. The host keys are float64: a float32 widens exactly with its
# low 29 mantissa bits zero, and those bits take the position (n ≤ 2²⁹), which
# NumPy sorts 15 % faster than int64 keys. Ties then come out in increasing
# position for values with the sign bit clear and in decreasing position for
# the others (a larger magnitude is a more negative float). XLA's CPU backend
# flushes subnormals (the widened keys of ±0 are subnormal), so it sorts
# integer keys built to give that same order: the float32 mapped to an
# order-preserving uint32 in the high word, the position (complemented where
# the sign bit is set) in the low word. Both give the same permutation, hence
# bit-identical results. Arrays cross between JAX and NumPy without copies:
# ``np.asarray`` views a CPU jax.Array, and ``jax.device_put`` wraps a 64-byte
# aligned NumPy array (:func:`_aligned_empty`).

SortMethod = Literal["auto", "numpy", "xla"]

_POSITION_BITS = 29  # float64 mantissa bits below a widened float32's
_MAX_ROW = 1 << _POSITION_BITS
_POSITION_MASK = np.int64(_MAX_ROW - 1)


def _order_key(x: Array) -> Array:
    """float32 → uint32 with the same order (IEEE-754 sign-magnitude to two's-complement-like)."""
    b = jax.lax.bitcast_convert_type(x.astype(jnp.float32), jnp.uint32)
    return jnp.where(b >> 31 == 1, ~b, b | jnp.uint32(0x80000000))


def _order_key_inverse(k: Array) -> Array:
    b = jnp.where(k >> 31 == 1, k ^ jnp.uint32(0x80000000), ~k)
    return jax.lax.bitcast_convert_type(b, jnp.float32)


def _pack(x: Float[Array, "... n"]) -> Array:
    """Sort keys for the last axis: ``order_key(x) << 32 | p``, ``p`` the position, complemented if ``x``'s sign bit is set."""
    pos = jax.lax.broadcasted_iota(jnp.uint32, x.shape, x.ndim - 1)
    key = _order_key(x)
    low = jnp.where(key >> 31 == 1, pos, ~pos)  # order_key clears the top bit exactly where the sign bit is set
    return (key.astype(jnp.uint64) << jnp.uint64(32)) | low.astype(jnp.uint64)


def _unpack(keys: Array) -> tuple[Array, Array]:
    """Sorted keys → (positions of the sorted values, the sorted values)."""
    key = (keys >> jnp.uint64(32)).astype(jnp.uint32)
    low = (keys & jnp.uint64(0xFFFFFFFF)).astype(jnp.uint32)
    idx = jnp.where(key >> 31 == 1, low, ~low).astype(jnp.int32)
    return idx, _order_key_inverse(key)


def _scatter(idx: Array, values: Array) -> Array:
    """``out[..., idx[..., k]] = values[..., k]`` along the last axis (``idx`` a permutation per row)."""
    n = idx.shape[-1]
    flat_i, flat_v = idx.reshape(-1, n), values.reshape(-1, n)
    out = jax.vmap(lambda i, v: jnp.zeros(n, v.dtype).at[i].set(v, unique_indices=True))(flat_i, flat_v)
    return out.reshape(idx.shape)


def _aligned_empty(shape: tuple[int, ...], dtype) -> np.ndarray:
    """Uninitialised NumPy array with 64-byte aligned data, which ``jax.device_put`` wraps on CPU without copying."""
    dtype = np.dtype(dtype)
    nbytes = math.prod(shape) * dtype.itemsize
    buf = np.empty(nbytes + 64, np.uint8)
    start = -buf.ctypes.data % 64
    return buf[start : start + nbytes].view(dtype).reshape(shape)


def _rank_row(v, target, pick, out, picked, pos) -> None:
    """One row on the host: sorted values at ``pick`` into ``picked``; with ``target``, ``out[rank⁻¹] = target``.

    Keys are ``float64(v)`` with the position in the 29 low mantissa bits
    (zero after the exact widening), sorted as float64. Without a target only
    order statistics are needed, and sorting the float32 values gives the
    same ones, faster.
    """
    if target is None:
        picked[:] = np.sort(v)[pick]
        return
    keys = v.astype(np.float64)
    bits = keys.view(np.int64)
    bits |= pos
    keys.sort()
    picked[:] = (bits[pick] & ~_POSITION_MASK).view(np.float64)  # exact: a widened float32
    bits &= _POSITION_MASK  # the positions, in place: intp indices
    out[bits] = target  # fancy assignment with intp indices: half the time of np.put here


@functools.lru_cache(maxsize=32)
def _positions(n: int) -> np.ndarray:
    """``arange(n)`` as int64, read-only and cached: the position bits of the sort keys."""
    pos = np.arange(n, dtype=np.int64)
    pos.setflags(write=False)
    return pos


def _rank_host(values, targets, picks, workers: int | None = None):
    """:func:`_rank_match` in NumPy: rows spread over a thread pool, largest first."""
    values = [np.ascontiguousarray(v, np.float32) for v in values]
    targets = [None] * len(values) if targets is None else [np.ascontiguousarray(t, np.float32) for t in targets]
    picks = [np.asarray(p, np.intp) for p in picks]  # no copy when given intp arrays (as synthesis does)
    matched = [None if t is None else _aligned_empty(v.shape, np.float32) for v, t in zip(values, targets)]
    picked = [np.empty((*v.shape[:-1], len(p)), np.float32) for v, p in zip(values, picks)]
    jobs = []  # one per row: (values, target, pick, out, picked, positions), all 1-d views
    for v, t, m, pk, p in zip(values, targets, matched, picked, picks):
        pos = None if t is None else _positions(v.shape[-1])
        for j in np.ndindex(v.shape[:-1]):
            jobs.append((v[j], None if t is None else t[j], p, None if m is None else m[j], pk[j], pos))
    jobs.sort(key=lambda job: -job[0].size)
    workers = min(len(jobs), workers or os.cpu_count() or 1)
    if workers <= 1:
        for job in jobs:
            _rank_row(*job)
    else:
        with concurrent.futures.ThreadPoolExecutor(workers) as pool:
            for f in [pool.submit(_rank_row, *job) for job in jobs]:
                f.result()
    return (None if targets[0] is None else tuple(jax.device_put(m) for m in matched),
            tuple(jax.device_put(p) for p in picked))


@jax.jit
def _rank_xla(values, targets, picks):
    """:func:`_rank_match` in XLA (``lax.sort`` of integer keys in the host keys' order: the same permutation).

    ``picks`` are int32 arrays, traced: only their lengths are part of the
    compiled program, not the 8,192 positions of a KS pick.
    """
    if targets is None:
        return None, tuple(jnp.sort(v, axis=-1)[..., p] for v, p in zip(values, picks))
    matched, picked = [], []
    for v, t, p in zip(values, targets, picks):
        idx, vals = _unpack(jnp.sort(_pack(v), axis=-1))
        matched.append(_scatter(idx, t))
        picked.append(vals[..., p])
    return tuple(matched), tuple(picked)


def _rank_match(values, targets, picks, method: SortMethod = "auto"):
    """Exact rank matching of every row (last axis) of every array in ``values``.

    For each row ``x`` (length ``n``) with sorted order ``x_(0) ≤ … ≤ x_(n−1)``
    (ties broken by position, increasing where the sign bit is clear and
    decreasing where it is set; see the notes above): ``matched[i] = target[rank(i)]``, where ``target``
    is the row's nondecreasing target values, and ``picked = x_(pick)``, the
    order statistics at the given positions. ``targets=None`` computes only
    ``picked``.

    Parameters
    ----------
    values
        Tuple of float32 arrays ``(..., n_g)``.
    targets
        Tuple of float32 arrays of the same shapes, or ``None``.
    picks
        One sequence (or intp array) per array of int positions in ``[0, n_g)``.
    method
        ``"numpy"`` (host sort), ``"xla"`` or ``"auto"`` (NumPy on CPU).

    Returns
    -------
    matched, picked : tuples of jax.Array (``matched`` is ``None`` without targets)
    """
    if method == "xla" or (method == "auto" and jax.default_backend() != "cpu"):
        picks = tuple(jnp.asarray(np.asarray(p, np.int32)) for p in picks)
        return _rank_xla(tuple(values), None if targets is None else tuple(targets), picks)
    return _rank_host(values, targets, picks)


def _targets(table: np.ndarray, probs: np.ndarray, n: int) -> jax.Array:
    """Target sorted values: the quantile function (piecewise linear through ``(probs, table)``) at ``(k + 1/2) / n``.

    ``table`` is ``(..., q)``; returns float32 ``(..., n)``. Computed in
    float64 (near p = 1 the quantile function is steep and a float32
    probability would cost ~1e-5 relative in the tail). The points
    ``t_k = (k + 1/2) / n`` are sorted, so each segment ``[p_j, p_{j+1})`` of
    the table holds a run of them, found once by ``searchsorted``; then
    ``Q(t_k) = table_j + slope_j (t_k − p_j)`` is two ``np.repeat`` and two
    in-place passes per row, four times faster than ``np.interp``'s search per
    point (and ten times faster than XLA's ``jnp.interp`` on CPU).
    """
    table = np.asarray(table, np.float64)
    probs = np.asarray(probs, np.float64)
    t = (np.arange(n, dtype=np.float64) + 0.5) / n
    runs = np.diff(np.searchsorted(t, probs))  # points in each segment; they sum to n since p_0 = 0, p_{q-1} = 1
    t -= np.repeat(probs[:-1], runs)
    flat = table.reshape(-1, table.shape[-1])
    slopes = np.diff(flat, axis=-1) / np.diff(probs)
    out = _aligned_empty((flat.shape[0], n), np.float32)
    for row, slope, o in zip(flat, slopes, out):
        v = np.repeat(slope, runs)
        v *= t
        v += np.repeat(row[:-1], runs)
        o[:] = v
    return jax.device_put(out.reshape(*table.shape[:-1], n))


def _table_cdf(v: Float[Array, "n"], table: Float[Array, "q"], probs: Float[Array, "q"]) -> Float[Array, "n"]:
    """CDF at *sorted* ``v`` of the distribution whose quantile function interpolates ``(probs, table)`` linearly.

    Ties in ``table`` are allowed. The knot index ``i(j) = #{k: table_k ≤ v_j}`` is
    found by locating the ``q`` knots in the sorted sample and accumulating, O(n + q log n)
    instead of ``n`` binary searches (which XLA's CPU backend runs slowly).
    """
    q, n = table.shape[-1], v.shape[-1]
    pos = jnp.searchsorted(v, table, side="left")  # first j with v_j >= table_k
    i = jnp.cumsum(jnp.zeros(n + 1, jnp.int32).at[pos].add(1))[:n]
    i = jnp.clip(i, 1, q - 1)
    lo, hi = table[i - 1], table[i]
    frac = jnp.where(hi > lo, (v - lo) / jnp.where(hi > lo, hi - lo, 1.0), 1.0)
    f = probs[i - 1] + jnp.clip(frac, 0.0, 1.0) * (probs[i] - probs[i - 1])
    return jnp.where(v < table[0], 0.0, jnp.where(v >= table[-1], 1.0, f))


_KS_POINTS = 8192


def _ks_stride(n: int) -> int:
    """Order statistics the KS distance looks at: every ``max(1, n // 8192)``-th."""
    return max(1, n // _KS_POINTS)


def _ks_picks(n: int) -> np.ndarray:
    return np.arange(0, n, _ks_stride(n), dtype=np.intp)


def _ks_sorted(sub: Float[Array, "... m"], table: Float[Array, "... q"], probs, n_all: int) -> Float[Array, "..."]:
    """One-sample KS statistic against a quantile table, ``max_k |F(v_k) − ECDF|``, from every ``s``-th order statistic.

    ``sub`` holds the order statistics ``v_(0), v_(s), v_(2s), …`` of ``n_all``
    samples, ``s = max(1, n_all // 8192)`` (:func:`_ks_picks`). Since both F
    and the ECDF are nondecreasing this is within ``s / n ≤ 1/8192`` below the
    exact statistic (exact for ``n < 16384``), at a fraction of the cost.
    """
    stride = _ks_stride(n_all)
    n = sub.shape[-1]
    flat_v = sub.reshape(-1, n)
    flat_t = table.reshape(-1, table.shape[-1]).astype(sub.dtype)
    f = jax.vmap(_table_cdf, in_axes=(0, 0, None))(flat_v, flat_t, probs.astype(sub.dtype))
    k = (jnp.arange(n, dtype=f.dtype) * stride)[None, :]
    d = jnp.maximum(jnp.max(f - k / n_all, axis=-1), jnp.max((k + 1) / n_all - f, axis=-1))
    return d.reshape(sub.shape[:-1])


def quantile_probabilities(n_quantiles: int) -> np.ndarray:
    """Probabilities of a quantile table: ``p_k = sin²(π k / (2 (Q − 1)))``, from 0 to 1.

    Denser in the tails than a uniform grid (spacing ``≈ π² / (8 (Q − 1)²)`` at the
    ends, ``π / (2 (Q − 1))`` in the middle), so that interpolating the quantile
    function linearly does not fatten the tails: with uniform spacing the last
    interval alone spans from the 1/(Q−1) quantile to the maximum and inflates the
    variance by several per cent for Q ≈ 100.
    """
    k = np.arange(n_quantiles, dtype=np.float64)
    p = np.sin(0.5 * np.pi * k / (n_quantiles - 1)) ** 2
    p[0], p[-1] = 0.0, 1.0
    return p


def match_histogram(values, quantiles, probabilities=None, *, axis: int = -1) -> np.ndarray:
    """Exact, sort-based histogram matching of ``values`` to a quantile table.

    The ``k``-th smallest of the ``n`` values along ``axis`` is replaced by
    ``Q((k + 1/2) / n)``, where ``Q`` interpolates the points
    ``(probabilities, quantiles)`` linearly. So the sorted
    output *equals* the target quantiles, and the output keeps the rank order of
    the input (ties broken by position, deterministically). This is Heeger & Bergen's (1995)
    histogram matching without the binning of their CDF tables.

    Parameters
    ----------
    values
        Array; matched independently along ``axis``. Computed in float32.
    quantiles
        ``(Q,)`` nondecreasing quantile table (``Q ≥ 2``), or an array
        broadcastable against ``values`` with the table on its last axis.
    probabilities
        ``(Q,)`` increasing probabilities of the table, from 0 to 1; default
        ``linspace(0, 1, Q)``.

    Returns
    -------
    ndarray float32, the shape of ``values``.
    """
    v = np.moveaxis(np.asarray(values, dtype=np.float32), axis, -1)
    q = np.asarray(quantiles, dtype=np.float64)
    if v.ndim == 0 or v.shape[-1] == 0:
        raise ValueError(f"values must have at least one element along axis {axis}, got shape {np.shape(values)}")
    if q.ndim == 0 or q.shape[-1] < 2:
        raise ValueError(f"quantiles must hold at least 2 values on its last axis, got shape {q.shape}")
    if not (np.isfinite(q).all() and np.all(np.diff(q, axis=-1) >= 0)):
        raise ValueError("quantiles must be finite and nondecreasing along the last axis")
    if not np.isfinite(v).all():
        raise ValueError("values hold NaN or inf")
    if v.shape[-1] > _MAX_ROW:
        raise ValueError(f"at most 2**{_POSITION_BITS} values per histogram, got {v.shape[-1]} along axis {axis}")
    p = np.linspace(0.0, 1.0, q.shape[-1]) if probabilities is None else np.asarray(probabilities, np.float64)
    if p.shape != q.shape[-1:] or p[0] != 0 or p[-1] != 1 or np.any(np.diff(p) <= 0):
        raise ValueError(f"probabilities must increase from 0 to 1 with one per quantile ({q.shape[-1]}), got {p!r}")
    q = np.broadcast_to(q, (*v.shape[:-1], q.shape[-1]))
    with jax.enable_x64(True):
        target = _targets(q, p, v.shape[-1])
        (out,), _ = _rank_match((v,), (target,), ((),))
        return np.moveaxis(np.asarray(out), -1, axis)



# ================================================================== texture model


class TextureModel(eqx.Module):
    """The parametric texture of section 4.2: quantile tables of pixels and subbands, per decorrelated channel.

    Colour is handled as Heeger & Bergen suggest: RGB pixels ``x`` are
    decorrelated with a PCA, ``d = Vᵀ (x − μ)``, each channel of ``d`` is
    described and synthesised alone, and ``x = V d + μ`` maps back.

    Attributes
    ----------
    pca_mean
        ``(C,)`` channel mean ``μ`` of the analysed region.
    pca_basis
        ``(C, C)`` orthonormal ``V``; column ``k`` is principal axis ``k``
        (largest variance first, largest component positive).
    probabilities
        ``(Q,)`` the probabilities of every quantile table, increasing from 0
        to 1 (:func:`quantile_probabilities`: denser in the tails).
    pixel_quantiles
        ``(C, Q)`` quantiles of each decorrelated channel's pixels
        (``[:, 0]`` min, ``[:, -1]`` max).
    band_quantiles
        ``(C, B, Q)`` the same for each subband, ``B = 2 + 4 height``, in the
        order of :attr:`band_names`; subbands are taken from the periodic
        component of each channel, so image borders leave no trace.
    height
        Pyramid levels.
    rho_s
        ``(C,)`` specular reflectance: synthesis clamps ρd to ``[0, 1 − ρs]``.
    source_shape
        ``(H, W)`` of the image the texture was analysed from.
    region
        ``(y0, y1, x0, x1)`` the analysed rectangle (half-open, in pixels).
    region_source
        ``"argument"`` (given by the caller), ``"whole image"`` (no invalid
        pixels) or ``"largest valid rectangle"`` (the input held NaN).
    """

    pca_mean: np.ndarray
    pca_basis: np.ndarray
    probabilities: np.ndarray
    pixel_quantiles: np.ndarray
    band_quantiles: np.ndarray
    height: int = eqx.field(static=True)
    rho_s: np.ndarray
    source_shape: tuple[int, int] = eqx.field(static=True)
    region: tuple[int, int, int, int] = eqx.field(static=True)
    region_source: str = eqx.field(static=True)
    version: int = eqx.field(static=True, default=TEXTURE_FORMAT_VERSION)

    @property
    def channels(self) -> int:
        return int(self.pca_mean.shape[0])

    @property
    def n_quantiles(self) -> int:
        return int(self.pixel_quantiles.shape[-1])

    @property
    def band_names(self) -> tuple[str, ...]:
        return band_names(self.height)

    def describe_region(self) -> str:
        """One line saying which pixels were analysed and why."""
        y0, y1, x0, x1 = self.region
        return (
            f"rows {y0}:{y1}, columns {x0}:{x1} ({y1 - y0}x{x1 - x0} of {self.source_shape[0]}x"
            f"{self.source_shape[1]} pixels; {self.region_source})"
        )

    # ------------------------------------------------------------------ files

    def to_dict(self) -> dict:
        """Plain-Python form (lists and numbers) of the model; what :meth:`save` writes as JSON."""

        def rounded(a):  # float32 precision is all the quantiles carry
            return np.vectorize(lambda v: float(f"{v:.8g}"), otypes=[float])(np.asarray(a, np.float64)).tolist()

        return {
            "format": TEXTURE_FORMAT,
            "version": self.version,
            "height": self.height,
            "orientations": ORIENTATIONS,
            "channels": self.channels,
            "n_quantiles": self.n_quantiles,
            "source_shape": list(self.source_shape),
            "region": list(self.region),
            "region_source": self.region_source,
            "rho_s": rounded(self.rho_s),
            "pca_mean": np.asarray(self.pca_mean, np.float64).tolist(),
            "pca_basis": np.asarray(self.pca_basis, np.float64).tolist(),
            "probabilities": np.asarray(self.probabilities, np.float64).tolist(),
            "pixel_quantiles": rounded(self.pixel_quantiles),
            "band_names": list(self.band_names),
            "band_quantiles": rounded(self.band_quantiles),
        }

    @classmethod
    def from_dict(cls, d: dict, *, source: str = "texture description") -> "TextureModel":
        """Validate and build a model from :meth:`to_dict`'s form; errors name ``source`` and the field."""

        def field(name):
            if name not in d:
                raise ValueError(f"{source}: missing field {name!r}")
            return d[name]

        if field("format") != TEXTURE_FORMAT:
            raise ValueError(f"{source}: field 'format' is {d['format']!r}, expected {TEXTURE_FORMAT!r}")
        version = field("version")
        if version != TEXTURE_FORMAT_VERSION:
            raise ValueError(
                f"{source}: field 'version' is {version!r}; this wardjax reads version {TEXTURE_FORMAT_VERSION}"
            )

        def integer(name, lo):
            v = field(name)
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < lo:
                raise ValueError(f"{source}: field {name!r} is {v!r}, expected an integer >= {lo}")
            return int(v)

        height, channels, q = integer("height", 0), integer("channels", 1), integer("n_quantiles", 2)
        if integer("orientations", 1) != ORIENTATIONS:
            raise ValueError(f"{source}: field 'orientations' is {d['orientations']!r}, expected {ORIENTATIONS}")
        n_bands = 2 + ORIENTATIONS * height

        def array(name, shape):
            value = field(name)
            try:
                a = np.asarray(value, dtype=np.float64)
            except (TypeError, ValueError):
                raise ValueError(f"{source}: field {name!r} is not an array of numbers") from None
            if a.shape != shape:
                raise ValueError(f"{source}: field {name!r} has shape {a.shape}, expected {shape}")
            if not np.isfinite(a).all():
                raise ValueError(f"{source}: field {name!r} holds NaN or inf")
            return a

        probs = array("probabilities", (q,))
        if probs[0] != 0 or probs[-1] != 1 or np.any(np.diff(probs) <= 0):
            raise ValueError(f"{source}: field 'probabilities' must increase from 0 to 1")
        pix = array("pixel_quantiles", (channels, q))
        bands = array("band_quantiles", (channels, n_bands, q))
        if np.any(np.diff(pix, axis=-1) < 0) or np.any(np.diff(bands, axis=-1) < 0):
            raise ValueError(f"{source}: quantile tables must be nondecreasing")
        names = [str(n) for n in np.asarray(field("band_names")).tolist()]
        if tuple(names) != band_names(height):
            raise ValueError(f"{source}: field 'band_names' does not match height {height}")
        src_shape = tuple(int(v) for v in array("source_shape", (2,)))
        region = tuple(int(v) for v in array("region", (4,)))
        return cls(
            pca_mean=array("pca_mean", (channels,)),
            pca_basis=array("pca_basis", (channels, channels)),
            probabilities=probs,
            pixel_quantiles=pix,
            band_quantiles=bands,
            height=height,
            rho_s=array("rho_s", (channels,)),
            source_shape=src_shape,
            region=region,
            region_source=str(np.asarray(field("region_source")).item()),
            version=int(version),
        )

    def save(self, path) -> Path:
        """Write the model to ``path``: ``.json`` (readable) or ``.npz``; atomically (temp file + rename)."""
        path = Path(path)
        d = self.to_dict()
        suffix = path.suffix.lower()
        if suffix == ".json":
            data = (json.dumps(d, separators=(",", ":")) + "\n").encode()
            _atomic_write(path, lambda tmp: Path(tmp).write_bytes(data))
        elif suffix == ".npz":
            arrays = {k: np.asarray(v) for k, v in d.items()}
            _atomic_write(path, lambda tmp: np.savez_compressed(tmp, **arrays))
        else:
            raise ValueError(f"{path}: unknown texture file type {path.suffix!r}, expected .json or .npz")
        return path

    @classmethod
    def load(cls, path) -> "TextureModel":
        """Read a model written by :meth:`save` (``.json`` or ``.npz``), checking format, version and shapes."""
        path = Path(path)
        if not path.is_file():
            raise ValueError(f"{path}: no such texture file")
        suffix = path.suffix.lower()
        if suffix == ".json":
            try:
                d = json.loads(path.read_text())
            except (UnicodeDecodeError, json.JSONDecodeError) as e:
                raise ValueError(f"{path}: not valid JSON ({e})") from None
            if not isinstance(d, dict):
                raise ValueError(f"{path}: expected a JSON object at top level")
        elif suffix == ".npz":
            try:
                with np.load(path, allow_pickle=False) as z:
                    d = {k: (z[k].item() if z[k].ndim == 0 else z[k]) for k in z.files}
            except (OSError, ValueError) as e:
                raise ValueError(f"{path}: not a readable .npz file ({e})") from None
        else:
            raise ValueError(f"{path}: unknown texture file type {path.suffix!r}, expected .json or .npz")
        return cls.from_dict(d, source=str(path))


def _atomic_write(path: Path, write) -> None:
    """Call ``write(tmp_path)`` on a temporary file beside ``path``, then rename it into place."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=path.suffix)
    os.close(fd)
    try:
        write(tmp)
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


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


@jax.jit
def _pixel_moments(x: Float[Array, "h w c"]) -> tuple[Float[Array, "c"], Float[Array, "c c"]]:
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
    """Grid of every subband in :func:`~wardjax._pyramid.pyramid_subbands` order."""
    return (shapes[0], *(s for s in shapes[:-1] for _ in range(ORIENTATIONS)), shapes[-1])


def _groups(subbands, c: int) -> tuple:
    """Subbands as sorting rows ``(C, 1, n)``, one array per subband (highpass, levels × orientations, lowpass)."""
    return tuple(b.reshape(c, 1, -1) for b in subbands)


@functools.partial(jax.jit, static_argnames="shapes")
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
    if min(rh, rw) < _MIN_SIDE:
        raise ValueError(
            f"the analysed region (rows {y0}:{y1}, columns {x0}:{x1}, {source}) is {rh}x{rw} pixels; "
            f"need at least {_MIN_SIDE}x{_MIN_SIDE}"
        )
    height = min(DEFAULT_HEIGHT, max_pyramid_height((rh, rw))) if height is None else height
    height = _check_height(height, (rh, rw), "the analysed region")
    rho_s_vec = _rho_s_vector(rho_s, c)

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


# ====================================================================== synthesis


class SynthesisResult(eqx.Module):
    """A synthesised texture and how close its statistics came to the model's.

    Attributes
    ----------
    image
        ``(H, W, C)`` float32 linear ρd in ``[0, 1 − ρs]``; tiles seamlessly.
    distance
        ``(iterations,)`` after each iteration, the largest one-sample
        Kolmogorov–Smirnov statistic between a subband of the image (any
        channel, any subband) and the model's distribution for it.
    band_distance
        ``(iterations, C, B)`` the same per channel and subband.
    initial_distance
        The same for the starting noise (after pixel histogram matching).
    seed
        The seed the noise was drawn with.
    """

    image: np.ndarray
    distance: np.ndarray
    band_distance: np.ndarray
    initial_distance: float
    seed: int = eqx.field(static=True)


@functools.partial(jax.jit, static_argnames="shapes")
def _build_groups(d, masks, shapes):
    """Pyramid of the pixels ``d`` (``(C, 1, H W)``) as sorting groups (:func:`_groups`)."""
    c = d.shape[0]
    return _groups(pyramid_subbands(jnp.fft.rfft2(d.reshape(c, *shapes[0]), norm="forward"), masks, shapes), c)


@functools.partial(jax.jit, static_argnames="shapes")
def _collapse(groups, masks, shapes):
    """Inverse of :func:`_build_groups`: collapse matched subband groups into pixels ``(C, 1, H W)``."""
    c = groups[0].shape[0]
    subbands = tuple(g.reshape(c, *s) for g, s in zip(groups, _subband_shapes(shapes)))
    return pyramid_collapse(subbands, masks, shapes).reshape(c, 1, -1)


@functools.partial(jax.jit, static_argnames="sizes")
def _band_ks(picked, tables, probs, sizes):
    """KS distance ``(C, B)`` of every subband from its every-s-th order statistics (:func:`_ks_sorted`)."""
    return jnp.concatenate([_ks_sorted(p, t, probs, n) for p, t, n in zip(picked, tables, sizes)], axis=-1)


def _band_targets(band_q: np.ndarray, probs: np.ndarray, shapes):
    """Sorted target values ``(C, 1, n_b)`` for every subband at this output size, and its quantile table ``(C, 1, Q)``."""
    groups, tables = [], []
    for b, (h, w) in enumerate(_subband_shapes(shapes)):
        t = band_q[:, b : b + 1]
        tables.append(jnp.asarray(t, jnp.float32))
        groups.append(_targets(t, probs, h * w))
    return tuple(groups), tuple(tables)


def _heeger_bergen(rng, band_q, pixel_q, probs64, masks, shapes, iterations: int, sort: SortMethod, progress=None):
    """The iterations of :func:`synthesize_texture`, channel by channel, from the noise of ``rng`` (a NumPy Generator).

    Per channel: ``d ← match(noise, pixels)``; then ``iterations`` times: pyramid
    of ``d``, every subband ``← match(subband, its targets)``,
    ``d ← match(collapse, pixels)``; and a last pyramid to measure the final
    distance. ``band_q`` ``(C, B, Q)``, ``pixel_q`` ``(C, Q)`` and ``probs64``
    are the model's tables (float64).

    The channels are independent, so they are interleaved: while the host ranks
    one channel's subbands, XLA builds or collapses another's pyramid
    (asynchronous dispatch); the subband targets are interpolated while XLA
    builds the first pyramids. ``progress(k, iterations)`` is called as the
    ``k``-th iteration's matching is done. Returns the ``C`` channels
    ``(1, 1, H W)`` and the KS distances ``(iterations + 1, C, B)``, the first
    for the starting noise.
    """
    c, n_pix = pixel_q.shape[0], shapes[0][0] * shapes[0][1]
    probs = jnp.asarray(probs64, jnp.float32)
    pix_targets, ds, groups = [], [], []
    for ch in range(c):
        noise = rng.standard_normal((1, 1, n_pix), dtype=np.float32)  # channel by channel: the same stream as (C, n)
        pix_targets.append(_targets(pixel_q[ch : ch + 1, None], probs64, n_pix))
        (d,), _ = _rank_match((noise,), (pix_targets[ch],), ((),), sort)
        ds.append(d)
        groups.append(_build_groups(d, masks, shapes))  # dispatched: runs while the next channel is ranked
    targets, tables = zip(*(_band_targets(band_q[ch : ch + 1], probs64, shapes) for ch in range(c)))
    sizes = tuple(t.shape[-1] for t in targets[0])
    ks_picks = tuple(_ks_picks(n) for n in sizes)
    ks = [[] for _ in range(c)]
    for it in range(iterations + 1):
        last = it == iterations  # the final pyramid only measures the distance: sort, no matching
        collapsed = []
        for ch in range(c):
            matched, picked = _rank_match(groups[ch], None if last else targets[ch], ks_picks, sort)
            ks[ch].append(_band_ks(picked, tables[ch], probs, sizes))
            if not last:
                collapsed.append(_collapse(matched, masks, shapes))
        for ch in range(len(collapsed)):
            (ds[ch],), _ = _rank_match((collapsed[ch],), (pix_targets[ch],), ((),), sort)
            groups[ch] = _build_groups(ds[ch], masks, shapes)
        if progress is not None and not last:
            progress(it + 1, iterations)
    ks = np.stack([np.concatenate([np.asarray(k[it], np.float64) for k in ks]) for it in range(iterations + 1)])
    return ds, ks


@jax.jit
def _channel_moments(ds):
    """Mean ``(C,)`` and covariance ``(C, C)`` (float64, divided by ``n``) of the channels ``ds`` (each ``(1, 1, n)``)."""
    x = jnp.concatenate([d.reshape(1, -1) for d in ds]).astype(jnp.float64)
    mu = x.mean(axis=1)
    x = x - mu[:, None]
    return mu, (x @ x.T) / x.shape[1]


def _decorrelation(cov: np.ndarray) -> np.ndarray:
    """Linear map ``W`` that removes the chance correlation between independently synthesised channels.

    ``W = T^{1/2} S^{−1/2}`` with ``S`` the channels' sample covariance and
    ``T = diag(S)``, applied to the centred channels: afterwards the covariance
    is exactly diagonal, each channel keeps its variance, and ``S^{−1/2}``
    (symmetric) is the whitening closest to the identity, so the channels
    change as little as possible. Without this, the RGB variance of a texture
    with strong low frequencies misses the source's by a few per cent (few
    independent samples of the coarse scales make the sample correlation of
    independent fields non-zero). Channels with (near) zero variance are left
    alone (identity rows and columns).
    """
    c = cov.shape[0]
    var = np.diag(cov).copy()
    w = np.eye(c)
    live = np.flatnonzero(var > 1e-12 * max(var.max(), np.finfo(np.float64).tiny))
    if live.size < 2:
        return w
    evals, evecs = np.linalg.eigh(cov[np.ix_(live, live)])
    w[np.ix_(live, live)] = np.sqrt(var[live])[:, None] * ((evecs / np.sqrt(evals)) @ evecs.T)
    return w


@jax.jit
def _to_rgb(ds, mix, offset, upper):
    """``clip(mix d + offset, 0, upper)`` per pixel, channels last: ``(n, K)`` float32."""
    d = jnp.concatenate([x.reshape(1, -1) for x in ds])
    rgb = jnp.einsum("kc,cn->nk", mix.astype(d.dtype), d) + offset.astype(d.dtype)[None]
    return jnp.clip(rgb, 0.0, upper.astype(d.dtype)[None])


def synthesize_texture(
    model: TextureModel,
    shape: tuple[int, int],
    *,
    seed: int = 0,
    iterations: int = 5,
    rho_s=None,
    sort: Literal["auto", "numpy", "xla"] = "auto",
    progress: Callable[[int, int], None] | None = None,
) -> SynthesisResult:
    """Synthesise a texture of any size from a :class:`TextureModel` (Heeger & Bergen 1995, paper section 4.2).

    Per decorrelated channel, starting from seeded Gaussian white noise whose
    pixels are matched to the model's pixel histogram, each iteration

    1. builds the steerable pyramid of the current image,
    2. matches every subband's histogram exactly to the model's quantiles
       (:func:`match_histogram`),
    3. collapses the pyramid and matches the pixel histogram.

    Channels are then mixed back to RGB (``x = V d + μ``) and clamped to
    ``[0, 1 − ρs]``, after a linear correction, closest to the identity, that
    removes the chance correlation between the independently synthesised
    channels (so RGB means and variances are the source's). Every step is circular (FFT pyramid on a periodic grid,
    pointwise histogram maps), so the result tiles seamlessly. The same seed,
    shape and model give the same image.

    Parameters
    ----------
    model
        From :func:`analyze_texture` or :meth:`TextureModel.load`.
    shape
        ``(height, width)`` in pixels, NumPy order (the CLI's ``--size`` is
        ``WIDTHxHEIGHT``); each side at least ``2 ** (model.height + 2)``.
    seed
        Seed of the noise (NumPy's ``default_rng``: the same image on every backend).
    iterations
        Histogram-matching iterations (≥ 1; the paper used 3).
    rho_s
        Override the model's specular reflectance for the clamp.
    sort
        ``"auto"`` (NumPy on CPU, XLA elsewhere), ``"numpy"`` or ``"xla"``; all
        give identical results.
    progress
        Called as ``progress(k, iterations)`` when iteration ``k`` is done (the
        CLI draws its progress bar with it).

    Returns
    -------
    SynthesisResult
    """
    if not isinstance(model, TextureModel):
        raise TypeError(f"model must be a TextureModel, got {type(model).__name__}")
    try:
        hh, ww = (int(s) for s in shape)
    except (TypeError, ValueError):
        raise ValueError(f"shape={shape!r}, expected (height, width)") from None
    if (hh, ww) != tuple(shape) or min(hh, ww) < 1:
        raise ValueError(f"shape={shape!r}, expected two positive integers (height, width)")
    if hh * ww > _MAX_ROW:
        raise ValueError(f"shape={shape!r} has {hh * ww} pixels; at most 2**{_POSITION_BITS} can be synthesised")
    need = 2 ** (model.height + 2)
    if min(hh, ww) < need:
        raise ValueError(
            f"shape={shape!r} is too small for a texture analysed with {model.height} pyramid levels: "
            f"each side must be at least {need} pixels"
        )
    if isinstance(iterations, bool) or not isinstance(iterations, (int, np.integer)) or iterations < 1:
        raise ValueError(f"iterations={iterations!r}, expected an integer >= 1")
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)):
        raise ValueError(f"seed={seed!r}, expected an integer")
    if sort not in ("auto", "numpy", "xla"):
        raise ValueError(f"sort={sort!r}, expected 'auto', 'numpy' or 'xla'")
    c = model.channels
    rs = model.rho_s if rho_s is None else _rho_s_vector(rho_s, c)
    shapes = pyramid_shapes((hh, ww), model.height)

    with jax.enable_x64(True):
        masks = _device_masks((hh, ww), model.height, "float32")
        ds, ks = _heeger_bergen(
            np.random.default_rng(int(seed)),
            np.asarray(model.band_quantiles, np.float64),
            np.asarray(model.pixel_quantiles, np.float64),
            np.asarray(model.probabilities, np.float64),
            masks,
            shapes,
            iterations,
            sort,
            progress,
        )
        mu, cov = (np.asarray(a) for a in _channel_moments(ds))
        # x = V (μ + W (d − μ)) + m: decorrelate, back to RGB, clamp, in one pass over the pixels.
        mix = model.pca_basis @ _decorrelation(cov)
        offset = model.pca_basis @ mu - mix @ mu + model.pca_mean
        rgb = np.array(_to_rgb(tuple(ds), mix, offset, 1.0 - np.asarray(rs, np.float64))).reshape(hh, ww, c)
    return SynthesisResult(
        image=rgb,
        distance=ks[1:].max(axis=(1, 2)),
        band_distance=ks[1:],
        initial_distance=float(ks[0].max()),
        seed=int(seed),
    )


# ==================================================================== image files


def srgb_encode(linear) -> np.ndarray:
    """IEC 61966-2-1 sRGB transfer function of linear values in ``[0, 1]`` (clipped) → 8-bit."""
    x = np.clip(np.asarray(linear, np.float64), 0.0, 1.0)
    v = np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)
    return np.round(v * 255.0).astype(np.uint8)


def write_texture_image(path, image) -> Path:
    """Write a synthesised ρd: ``.tif``/``.tiff`` linear float32, ``.png`` an 8-bit sRGB view; atomically."""
    path = Path(path)
    img = np.asarray(image, np.float32)
    if img.ndim == 3 and img.shape[-1] == 1:
        img = img[..., 0]
    suffix = path.suffix.lower()
    if suffix in (".tif", ".tiff"):
        import tifffile

        photometric = "rgb" if img.ndim == 3 and img.shape[-1] == 3 else "minisblack"
        _atomic_write(path, lambda tmp: tifffile.imwrite(tmp, img, photometric=photometric))
    elif suffix == ".png":
        import imageio.v3 as iio

        _atomic_write(path, lambda tmp: iio.imwrite(tmp, srgb_encode(img), extension=".png"))
    else:
        raise ValueError(f"{path}: unknown image type {path.suffix!r}, expected .tif, .tiff or .png")
    return path


def read_rho_d(path) -> np.ndarray:
    """Read a linear ρd map (``.tif``/``.tiff`` or ``.npy``) as float64 ``(H, W)`` or ``(H, W, C)``."""
    path = Path(path)
    if not path.is_file():
        raise ValueError(f"{path}: no such file")
    suffix = path.suffix.lower()
    try:
        if suffix in (".tif", ".tiff"):
            import tifffile

            a = tifffile.imread(path)
        elif suffix == ".npy":
            a = np.load(path, allow_pickle=False)
        else:
            raise ValueError(f"{path}: unknown ρd file type {path.suffix!r}, expected .tif, .tiff or .npy (linear ρd)")
    except (OSError, ValueError) as e:
        if str(path) in str(e):
            raise
        raise ValueError(f"{path}: cannot read ({e})") from None
    if a.ndim not in (2, 3) or not np.issubdtype(a.dtype, np.number):
        raise ValueError(f"{path}: expected an (H, W) or (H, W, C) numeric image, got {a.dtype} {a.shape}")
    return a.astype(np.float64)
