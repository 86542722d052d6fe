"""Histogram matching and quantile tables (Heeger & Bergen 1995, the CDF match of section 4.2)."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from ._rank import _MAX_ROW, _POSITION_BITS, _aligned_empty, _rank_match


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


def _table_cdf(v: Float[Array, " n"], table: Float[Array, " q"], probs: Float[Array, " q"]) -> Float[Array, " n"]:
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


def _ks_sorted(sub: Float[Array, "... m"], table: Float[Array, "... q"], probs, n_all: int) -> Float[Array, ...]:
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
