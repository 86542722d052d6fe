"""ρd texture in the scanline model: a Gaussian-process term with the texture's measured autocovariance.

Why this form (measured, see docs/missing-effects.md)
    A textured probe's diffuse albedo varies from pixel to pixel, ``ρd(p) =
    ρ̄d (1 + t(p))``. With one ρd per scanline the texture is left in the
    residuals, where it swamps every effect (the gap of an untouched 320 × 240
    wood capture read 2.7 and no edit of its images was named). Two other
    ways were considered:

    - ρd per image position with a smoothness prior: per pixel the diffuse
      term is free, so everything the smoothness allows — a gradient across
      the image, an offset — is absorbed as texture;
    - a two-scale split, texture fixed in image coordinates: needs several
      lamp positions per point, which one capture does not have.

    Here the texture is a zero-mean Gaussian process along each scanline,
    ``Cov(t_i, t_j) = T_c ρ^{|i−j|}`` per channel (an exponential /
    Ornstein–Uhlenbeck autocovariance in sample index), added to the white
    noise. Marginalising it, the likelihood is ``N(f, D + T R_ρ)``, and the
    residuals ``r = L⁻¹ (y − f)/σ`` with ``L Lᵀ = I + D⁻¹ T R_ρ D⁻¹`` are
    white again. A specular misfit is *not* absorbed: the GP is stationary and
    fixed before any effect is tried, so a residual that follows the lobe, an
    image position or ``log f`` coherently over all scanlines still costs χ²
    — it is only discounted by the texture's own variance, not fitted.

Estimating ``T`` and ``ρ`` from one capture
    From the residuals ``e = y − f̂`` of the baseline fit, second differences
    at lag ``k``, ``d_k = e_{i−k} − 2 e_i + e_{i+k}``, cancel the level and any
    trend of a smooth misfit (an effect), and have::

        E[d_k²]/6 = σ²(f) + T · (6 − 8ρ^k + 2ρ^{2k})/6

    for white noise ``σ²(f) = s0 + s1 f + s2 f²`` (read, shot, relative) plus
    the texture. ``s0, s1, s2, T`` are non-negative least squares over lags
    ``k = 1…16`` for each ``ρ`` of a grid, ``ρ`` the best fit: lag 1 over all
    values (the level dependence of the noise needs the highlight), longer
    lags only off the highlight (``off``: :func:`~wardjax.effects.discover`
    passes the values predicted within 15 % of the scanline's diffuse floor),
    so that a lobe-shaped misfit of the baseline is not taken for texture — the noise model
    of :mod:`~wardjax.effects._capture` (Gasser et al. 1986) extended to
    correlated texture, which the lag-1 estimate there counted as noise.

    Short lags alone identify only ``T (1 − ρ)`` when the texture is
    correlated over most of a scanline (the simulated wood): the estimate then
    ran to ``ρ = 0.995`` with ``T`` ~36× the variance the residuals actually
    have, and the GP absorbed a smooth effect shared by all scanlines. So one
    more row per value pins ``T``: the squared deviation from its scanline's
    mean (the per-scanline ρd takes that mean out; off the highlight, as the
    long lags), with::

        E[(e_i − ē)²] = σ²(f_i) (1 − 1/n) + T (1 − 2/n Σ_j ρ^{|i−j|} + 1/n² Σ_jk ρ^{|j−k|})

    (the variance the texture leaves about the mean of an ``n``-value
    scanline), measured in ``benchmarks/texture_across_scanlines.py`` and
    docs/missing-effects.md.
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import nnls

__all__ = ["TextureFit", "estimate_texture", "texture_whitening"]

_F_MIN = 30.0
_LAGS = (1, 2, 3, 4, 6, 8, 12, 16)
_RHO_GRID = np.concatenate([np.linspace(0.0, 0.9, 19), [0.92, 0.94, 0.96, 0.97, 0.98, 0.985, 0.99, 0.995]])


class TextureFit:
    """Noise and texture estimate per channel: ``s`` (3,) noise coefficients, ``T`` texture variance, ``rho``."""

    def __init__(self, s: np.ndarray, T: np.ndarray, rho: np.ndarray, scale: np.ndarray, sse_gain: np.ndarray):
        self.s, self.T, self.rho, self.scale, self.sse_gain = s, T, rho, scale, sse_gain

    def sigma(self, level: np.ndarray) -> np.ndarray:
        """White-noise SD at predicted level ``(S, N, C)``."""
        fc = np.abs(level) / self.scale
        s = self.s
        return np.sqrt(s[:, 0] + s[:, 1] * fc + s[:, 2] * fc**2)

    def significant(self) -> np.ndarray:
        """Per channel: the texture term's F statistic in the lag regression exceeds ``_F_MIN`` (else ``T = 0``)."""
        return self.T > 0


def _g(rho: float, k: int) -> float:
    return (6.0 - 8.0 * rho**k + 2.0 * rho ** (2 * k)) / 6.0


def _lag0_rows(e: np.ndarray, level: np.ndarray):
    """Squared deviations from each scanline's mean ``(e_i − ē_s)²``, their levels and ``1 − 1/n_s``."""
    ok = np.isfinite(e)
    n = ok.sum(1, keepdims=True)
    mean = np.nansum(e, 1, keepdims=True) / np.maximum(n, 1)
    use = ok & (n >= 8)
    w = np.broadcast_to(1.0 - 1.0 / np.maximum(n, 1), e.shape)
    return ((e - mean) ** 2)[use], level[use], w[use]


def _g0(e: np.ndarray, rho: float) -> np.ndarray:
    """Texture variance left about each scanline's mean, ``1 − 2/n Σ_j ρ^{|i−j|} + 1/n² Σ_jk ρ^{|j−k|}``."""
    ok = np.isfinite(e)
    n_pts = e.shape[1]
    idx = np.arange(n_pts)
    R = rho ** np.abs(idx[:, None] - idx[None, :]) if rho > 0 else np.eye(n_pts)
    okf = ok.astype(float)
    n = np.maximum(okf.sum(1, keepdims=True), 1.0)
    row = okf @ R  # (S, N): Σ_j∈J ρ^{|i−j|}
    tot = np.sum(row * okf, 1, keepdims=True)
    g = 1.0 - 2.0 * row / n + tot / n**2
    return g[ok & (n >= 8)]


def estimate_texture(e: np.ndarray, level: np.ndarray, ok: np.ndarray, off: np.ndarray | None = None) -> TextureFit:
    """Noise and texture per channel from residuals ``e`` ``(S, N, C)`` at predicted ``level``, where ``ok``.

    See the module docstring: NNLS of ``d_k²/6`` on ``[1, f, f², g_ρ(k)]``
    over the lags, for each ``ρ`` of a grid.
    """
    c_n = e.shape[-1]
    g1 = np.where(ok, e, np.nan)
    gk = g1 if off is None else np.where(ok & off, e, np.nan)
    s_out = np.zeros((c_n, 3))
    T = np.zeros(c_n)
    rho = np.zeros(c_n)
    gain = np.zeros(c_n)
    scale = np.ones(c_n)
    for c in range(c_n):
        rows_y, rows_l, rows_k = [], [], []
        for k in _LAGS:
            if 2 * k >= e.shape[1]:
                break
            g = g1 if k == 1 else gk
            d2 = (g[:, : -2 * k, c] - 2.0 * g[:, k:-k, c] + g[:, 2 * k :, c]) ** 2 / 6.0
            lv = level[:, k:-k, c]
            m = np.isfinite(d2)
            rows_y.append(d2[m])
            rows_l.append(lv[m])
            rows_k.append(np.full(int(m.sum()), k))
        e0, l0, w0 = _lag0_rows(gk[..., c], level[..., c])
        y = np.concatenate(rows_y + [e0])
        lv = np.concatenate(rows_l + [l0])
        kk = np.concatenate(rows_k + [np.zeros(e0.size, int)])
        sc = max(float(np.mean(np.abs(lv))), 1e-30)
        scale[c] = sc
        base = np.stack([np.ones_like(lv), lv / sc, (lv / sc) ** 2], -1)
        base[kk == 0] *= w0[:, None]  # about the scanline mean, white noise keeps (1 − 1/n) of its variance
        coef0, res0 = nnls(base, y)
        best = (np.inf, None, 0.0)
        for r in _RHO_GRID:
            gr = np.array([_g(r, k) for k in _LAGS])
            col = gr[np.searchsorted(_LAGS, np.maximum(kk, 1))]
            col[kk == 0] = _g0(gk[..., c], r)
            coef, res = nnls(np.concatenate([base, col[:, None]], -1), y)
            if res < best[0]:
                best = (res, coef, r)
        res, coef, r = best
        # F statistic of the texture term (T, ρ) in the lag regression; overlapping differences are
        # correlated, so the threshold is set far out (_F_MIN)
        gain[c] = (res0**2 - res**2) / max(res**2 / max(y.size - 5, 1), 1e-300)
        if coef is None or gain[c] <= _F_MIN:  # no texture: the white-noise fit stands
            coef, r = np.append(coef0, 0.0), 0.0
        s_out[c] = coef[:3]
        s_out[c, 0] = max(s_out[c, 0], 1e-12 * max(float(np.mean(y)), 1e-30))
        T[c], rho[c] = coef[3], r
    return TextureFit(s_out, T, rho, scale, gain)


def texture_whitening(fit: TextureFit, sigma: np.ndarray, use: np.ndarray) -> np.ndarray:
    """``(S, C, N, N)`` lower-triangular ``L⁻¹`` with ``L Lᵀ = I + D⁻¹ T R_ρ D⁻¹`` per scanline and channel.

    Values not in ``use`` (masked, or flagged clipped) are decoupled: their
    rows and columns are those of the identity.
    """
    s_n, n, c_n = sigma.shape
    idx = np.arange(n)
    out = np.empty((s_n, c_n, n, n))
    for c in range(c_n):
        R = fit.rho[c] ** np.abs(idx[:, None] - idx[None, :]) if fit.rho[c] > 0 else np.eye(n)
        a = np.where(use[..., c], np.sqrt(max(fit.T[c], 0.0)) / sigma[..., c], 0.0)  # (S, N)
        K = np.eye(n)[None] + a[:, :, None] * R[None] * a[:, None, :]
        L = np.linalg.cholesky(K)
        out[:, c] = np.linalg.inv(L)
    return out
