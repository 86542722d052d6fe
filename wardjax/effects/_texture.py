"""ρd texture in the scanline model: a Gaussian-process term with the texture's measured autocovariance.

Why this form
    A textured probe's diffuse albedo varies from pixel to pixel, ``ρd(p) =
    ρ̄d (1 + t(p))``. With one ρd per scanline the texture is left in the
    residuals, where it swamps every effect (an untouched 320 × 240 wood
    capture reads a gap near 2.7). Two other forms do not work:

    - ρd per image position with a smoothness prior: per pixel the diffuse
      term is free, so everything the smoothness allows — a gradient across
      the image, an offset — is absorbed as texture;
    - a two-scale split, texture fixed in image coordinates: needs several
      lamp positions per point, which one capture does not have.

    Here the texture is a zero-mean Gaussian process along each scanline,
    added to the white noise. Marginalising it, the likelihood is
    ``N(f, D + X)``, and the residuals ``r = L⁻¹ (y − f)/σ`` with
    ``L Lᵀ = I + D⁻¹ X D⁻¹`` are white again. A specular misfit is *not*
    absorbed: the process is stationary and fixed before any effect is
    tried, so a residual that follows the lobe, an image position or
    ``log f`` coherently over all scanlines still costs χ² — it is only
    discounted by the texture's own covariance, not fitted.

    ``X`` is measured, not a parametric form (:func:`joint_autocovariance`):
    the products of the baseline's residuals off the highlight at every lag
    along the scanline and between every pair of channels. An exponential
    per channel, ``T_c ρ^{|i−j|}`` (below), gets two things wrong: wood
    grain is smooth along a scanline, and an exponential (a rough process)
    explains a highlight-sized bump as texture at small cost (a ramp across
    the image goes unseen); and the texture is one pattern in all three
    channels, so per-channel whitening counts the same texture three times
    as independent evidence. What one scanline's
    process cannot hold — the texture shared by neighbouring scanlines
    (image columns: marble's veins run across several) — enters each
    candidate's evidence as a design effect (:func:`design_effect`), which
    is what stopped marble's veins being named an illumination gradient.

Estimating ``T`` and ``ρ`` from one capture (the significance test)
    :func:`~wardjax.effects._texture_term.with_texture` uses this estimate
    only to decide whether there is a texture to carry: its white noise tends
    to 0 on smooth textures (the exponential takes the whole drop from lag
    0 to lag 1). The noise the model carries is read between channels
    (:func:`~wardjax.effects._texture_term.white_noise_share`) and its shape
    by :func:`level_noise`.

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
    correlated over most of a scanline (the simulated wood): alone they let
    ``ρ`` run to the grid's end with ``T`` far above the variance the
    residuals have, and the GP would absorb a smooth effect shared by all
    scanlines. So one more row per value pins ``T``: the squared deviation from its scanline's
    mean (the per-scanline ρd takes that mean out; off the highlight, as the
    long lags), with::

        E[(e_i − ē)²] = σ²(f_i) (1 − 1/n) + T (1 − 2/n Σ_j ρ^{|i−j|} + 1/n² Σ_jk ρ^{|j−k|})

    (the variance the texture leaves about the mean of an ``n``-value
    scanline; ``benchmarks/texture_across_scanlines.py`` checks it).
"""

from __future__ import annotations

import numpy as np
from scipy import fft as sfft
from scipy.optimize import nnls

from ._noise import noise_columns

__all__ = [
    "TextureFit",
    "cross_covariance",
    "design_effect",
    "estimate_texture",
    "joint_autocovariance",
    "texture_whitening",
]

_F_MIN = 30.0
_LAGS = (1, 2, 3, 4, 6, 8, 12, 16)
_CROSS_SCANLINES = 8  # scanline lags of the cross-covariance (the design effect); sample lags: half a scanline
_RHO_GRID = np.concatenate([np.linspace(0.0, 0.9, 19), [0.92, 0.94, 0.96, 0.97, 0.98, 0.985, 0.99, 0.995]])


class TextureFit:
    """Noise and texture estimate per channel: ``s`` (3,) noise coefficients, ``T`` texture variance, ``rho``.

    ``acov`` ``(C N, C N)``, when set, is the texture's measured covariance
    along a scanline and between channels (:func:`joint_autocovariance`), used
    by :func:`texture_whitening` instead of the exponential ``T ρ^k``.
    """

    def __init__(
        self,
        s: np.ndarray,
        T: np.ndarray,
        rho: np.ndarray,
        scale: np.ndarray,
        sse_gain: np.ndarray,
        acov: np.ndarray | None = None,
    ):
        self.s, self.T, self.rho, self.scale, self.sse_gain, self.acov = s, T, rho, scale, sse_gain, acov

    def sigma(self, level: np.ndarray, w: np.ndarray | None = None) -> np.ndarray:
        """White-noise SD at predicted level ``(S, N, C)`` and inverse irradiance ``w`` ``(S, N, 1)`` (default 1):
        ``√(s0 w² + s1 f w + s2 f²)`` (:func:`~wardjax.effects._noise.noise_columns`)."""
        fc = np.abs(level) / self.scale
        cols = noise_columns(fc, np.ones_like(fc) if w is None else w)  # (S, N, C, 3)
        return np.sqrt(np.einsum("snck,ck->snc", cols, self.s))

    def significant(self) -> np.ndarray:
        """Per channel: the texture term's F statistic in the lag regression exceeds ``_F_MIN`` (else ``T = 0``)."""
        return self.T > 0


def _g(rho: float, k: int) -> float:
    return (6.0 - 8.0 * rho**k + 2.0 * rho ** (2 * k)) / 6.0


def _lag0_rows(e: np.ndarray, level: np.ndarray, inv_irr: np.ndarray):
    """Squared deviations from each scanline's mean ``(e_i − ē_s)²``, their levels, ``1 − 1/n_s`` and ``w``."""
    ok = np.isfinite(e)
    n = ok.sum(1, keepdims=True)
    mean = np.nansum(e, 1, keepdims=True) / np.maximum(n, 1)
    use = ok & (n >= 8)
    w = np.broadcast_to(1.0 - 1.0 / np.maximum(n, 1), e.shape)
    return ((e - mean) ** 2)[use], level[use], w[use], inv_irr[use]


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


def estimate_texture(
    e: np.ndarray, level: np.ndarray, ok: np.ndarray, off: np.ndarray | None = None, w: np.ndarray | None = None
) -> TextureFit:
    """Noise and texture per channel from residuals ``e`` ``(S, N, C)`` at predicted ``level``, where ``ok``.

    See the module docstring: NNLS of ``d_k²/6`` on ``[w², f w, f², g_ρ(k)]``
    over the lags, for each ``ρ`` of a grid; ``w`` ``(S, N, 1)`` the inverse
    irradiance (default 1; :func:`~wardjax.effects._noise.noise_columns`).
    """
    c_n = e.shape[-1]
    w = np.ones(e.shape[:2] + (1,)) if w is None else np.broadcast_to(w, e.shape[:2] + (1,))
    g1 = np.where(ok, e, np.nan)
    gk = g1 if off is None else np.where(ok & off, e, np.nan)
    s_out = np.zeros((c_n, 3))
    T = np.zeros(c_n)
    rho = np.zeros(c_n)
    gain = np.zeros(c_n)
    scale = np.ones(c_n)
    for c in range(c_n):
        rows_y, rows_l, rows_w, rows_k = [], [], [], []
        for k in _LAGS:
            if 2 * k >= e.shape[1]:
                break
            g = g1 if k == 1 else gk
            d2 = (g[:, : -2 * k, c] - 2.0 * g[:, k:-k, c] + g[:, 2 * k :, c]) ** 2 / 6.0
            lv = level[:, k:-k, c]
            m = np.isfinite(d2)
            rows_y.append(d2[m])
            rows_l.append(lv[m])
            rows_w.append(w[:, k:-k, 0][m])
            rows_k.append(np.full(int(m.sum()), k))
        e0, l0, w0, ww0 = _lag0_rows(gk[..., c], level[..., c], w[..., 0])
        y = np.concatenate(rows_y + [e0])
        lv = np.concatenate(rows_l + [l0])
        wv = np.concatenate(rows_w + [ww0])
        kk = np.concatenate(rows_k + [np.zeros(e0.size, int)])
        sc = max(float(np.mean(np.abs(lv))), 1e-30)
        scale[c] = sc
        base = noise_columns(lv / sc, wv)
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
    """Lower-triangular ``L⁻¹`` with ``L Lᵀ = I + D⁻¹ T R_ρ D⁻¹`` per scanline and channel, ``(S, C, N, N)``.

    With ``fit.acov`` (:func:`joint_autocovariance`) the channels of a
    scanline are whitened together, ``L Lᵀ = I + D⁻¹ X D⁻¹``, ``(S, C N, C N)``
    (values ordered channel by channel).

    Values not in ``use`` (masked, or flagged clipped) are decoupled: their
    rows and columns are those of the identity.
    """
    s_n, n, c_n = sigma.shape
    if fit.acov is not None:  # the measured covariance, all channels of a scanline together (units of f²)
        a = np.where(use, 1.0 / sigma, 0.0).transpose(0, 2, 1).reshape(s_n, c_n * n)
        K = np.eye(c_n * n)[None] + a[:, :, None] * fit.acov[None] * a[:, None, :]
        return np.linalg.inv(np.linalg.cholesky(K))
    idx = np.arange(n)
    out = np.empty((s_n, c_n, n, n))
    for c in range(c_n):
        R = fit.rho[c] ** np.abs(idx[:, None] - idx[None, :]) if fit.rho[c] > 0 else np.eye(n)
        a = np.where(use[..., c], np.sqrt(max(fit.T[c], 0.0)) / sigma[..., c], 0.0)  # (S, N)
        K = np.eye(n)[None] + a[:, :, None] * R[None] * a[:, None, :]
        L = np.linalg.cholesky(K)
        out[:, c] = np.linalg.inv(L)
    return out


def _centred(e: np.ndarray, off: np.ndarray) -> np.ndarray:
    """Residuals off the highlight about their scanline's mean (NaN elsewhere): what ρd per scanline leaves."""
    eo = np.where(off, e, np.nan)
    n = np.sum(np.isfinite(eo), axis=1, keepdims=True)
    return eo - np.nansum(eo, axis=1, keepdims=True) / np.maximum(n, 1)


def _lag_means(eo: np.ndarray, K: int, M: int) -> np.ndarray:
    """``⟨eo_{s,i,c} eo_{s+k,i+m,c'}⟩`` over the finite products, ``(C, C, 2K + 1, 2M + 1)`` for ``|k| ≤ K``,
    ``|m| ≤ M``; 0 where fewer than ``4 N`` products (``N`` samples a scanline) are finite."""
    s_n, n, c_n = eo.shape
    ok = np.isfinite(eo)
    z, w = np.where(ok, eo, 0.0), ok.astype(float)
    out = np.zeros((c_n, c_n, 2 * K + 1, 2 * M + 1))
    for c in range(c_n):
        for c2 in range(c_n):
            total = _lag_sums(z[..., c], z[..., c2], K, M)
            count = np.rint(_lag_sums(w[..., c], w[..., c2], K, M))  # the products where both are measured
            out[c, c2] = np.where(count > 4 * n, total / np.maximum(count, 1.0), 0.0)
    return out


def joint_autocovariance(
    e: np.ndarray, off: np.ndarray, noise_var: np.ndarray, lags: np.ndarray | None = None, window: float = 1.0
) -> tuple[np.ndarray, np.ndarray]:
    """The texture's covariance along one scanline, between all channels, ``(C N, C N)``, measured off the highlight.

    Entry ``(c N + i, c' N + j)`` is ``c_{cc'}(j − i) = ⟨ē_{i,c} ē_{j,c'}⟩``,
    the product of residuals about each scanline's mean (white noise adds
    nothing off the diagonal), the diagonal ``c = c', i = j`` less the white
    noise, every lag tapered by a Hann
    window of half the scanline, the whole made positive semi-definite
    (negative eigenvalues set to 0). Removing each scanline's mean biases
    every entry by about the same constant per channel pair; a constant added
    to a channel's covariance does not change the fit, since ρd per scanline
    and channel is a free constant (generalised least squares with an
    intercept).

    The white noise is ``noise_var`` (from :func:`estimate_texture`) but at
    most ``c_cc(0) − c_cc(1)``: the drop from lag 0 to lag 1 is noise plus
    the texture's own drop, never less than the noise. Where the
    exponential's fit puts more there (a texture smoother than an
    exponential, e.g. a blurred frame), the excess would be counted twice,
    as texture and as noise. Returns ``X`` and the noise used ``(C,)``. ``lags``: the
    :func:`lag_covariances` of ``e`` if already measured (they do not depend on the noise);
    ``window``: the Hann window's half-width as a fraction of half a scanline.

    Two properties of a real ρd texture that ``T ρ^k`` per channel misses:
    its shape along the scanline (wood grain is smooth, so a sharp,
    highlight-sized bump is *not* cheap to explain as texture, whereas the
    exponential — a rough, Markov process — explains it at small cost), and
    that it is one pattern in every channel, in the diffuse colour (the
    dichromatic model, Shafer 1985): the specular lobe is white, so the
    channel combinations across the diffuse colour see the lobe without the
    texture, and the generalised least squares weights them accordingly.
    """
    lags = lag_covariances(e, off) if lags is None else lags
    return _assemble(lags, e.shape[1], np.array(noise_var, float), window)


def lag_covariances(e: np.ndarray, off: np.ndarray, variogram: bool = False) -> np.ndarray:
    """``⟨ē_{i,c} ē_{i+m,c'}⟩`` off the highlight about each scanline's mean, ``(C, C, 2 H + 1)`` for ``|m| ≤ H``
    (``H`` half a scanline): what :func:`joint_autocovariance` assembles, independent of the noise.

    ``variogram``: lag ``m ≠ 0`` is the lag-0 value less the cross-variogram
    ``½ ⟨(e_{i+m,c} − e_{i,c})(e_{i+m,c'} − e_{i,c'})⟩``, which no mean enters.
    The products about the mean carry a bias, ``−2/n Σ_j c(i − j) + 1/n² Σ_jk
    c(j − k)`` for ``n`` values, that is one constant (absorbed by ρd per
    scanline) only where the values are contiguous; off the highlight they
    are two runs, one on each side of it, and on a texture smooth along the
    scanline the bias then bends the long lags. The variogram's covariance
    reads clean textured captures closer to a gap of 1, but as the
    covariance of every fit it costs power on library effects, so
    ``discover`` reads it only as the guard's second opinion
    (:mod:`wardjax.effects._recheck`).
    """
    s_n, n, c_n = e.shape
    half = max(n // 2, 2)
    out = _lag_means(_centred(e, off), 0, half)[:, :, 0]
    if variogram:
        raw = np.where(off, e, np.nan)
        for m in range(1, half + 1):
            d = (raw[:, m:] - raw[:, :-m]).reshape(-1, c_n)  # (S (N − m), C)
            ok = np.isfinite(d)
            dz = np.where(ok, d, 0.0)
            cnt = ok.T.astype(float) @ ok  # (C, C): the pairs where both channels are measured
            gamma = 0.5 * (dz.T @ dz) / np.maximum(cnt, 1.0)  # symmetric: lag −m is the same
            out[:, :, half + m] = out[:, :, half - m] = np.where(cnt > 4 * n, out[:, :, half] - gamma, 0.0)
    return out


def _assemble(lags: np.ndarray, n: int, noise: np.ndarray, window: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """``X`` ``(C N, C N)`` from :func:`lag_covariances`, less the white noise (capped), tapered by a Hann window
    of ``window`` × half a scanline, made PSD."""
    c_n, half = lags.shape[0], (lags.shape[2] - 1) // 2
    lag = np.arange(n)[None, :] - np.arange(n)[:, None]  # j − i
    w = window * half
    taper = np.where(np.abs(lag) < w, 0.5 * (1.0 + np.cos(np.pi * lag / w)), 0.0)
    X = np.zeros((c_n * n, c_n * n))
    noise = noise.copy()
    for c in range(c_n):
        for c2 in range(c_n):
            ac = lags[c, c2].copy()
            if c == c2:
                noise[c] = min(noise[c], max(ac[half] - ac[half + 1], 0.0))
                ac[half] = max(ac[half] - noise[c], 0.0)
            X[c * n : (c + 1) * n, c2 * n : (c2 + 1) * n] = ac[np.clip(lag, -half, half) + half] * taper
    X = 0.5 * (X + X.T)
    ev, V = np.linalg.eigh(X)
    return (V * np.maximum(ev, 0.0)) @ V.T, noise


def level_noise(
    e: np.ndarray, level: np.ndarray, ok: np.ndarray, X: np.ndarray, w: np.ndarray | None = None
) -> np.ndarray:
    """White-noise coefficients ``(C, 3)`` of ``σ² = s0 w² + s1 f w + s2 f²`` (units of ``level``), texture known.

    Lag-1 second differences ``d = e_{i−1} − 2 e_i + e_{i+1}`` over all
    values, highlight included (the level dependence of shot noise is read
    there), less the texture's share. With several channels that share is
    read *at each value* from the other channels: the noise is independent
    between channels and the texture is one pattern scaled per channel, so
    ``E[d_c d_{c'}] = (a_{c'}/a_c) E[d_c²]_texture`` and::

        E[d_c² − r_{cc'} d_c d_{c'}]/6 = σ_c²(f, w),   r_{cc'} = X_{cc}(0)/X_{cc'}(0)

    (``X`` the texture's covariance, :func:`joint_autocovariance`; averaged
    over ``c'``). The texture's share then follows it where its
    statistics change along a scanline — the step on the sample plane
    halves from one end of a 160 × 120 capture's scanline to the other, so
    a rough texture's lag-1 differences are larger at one end — which the
    stationary share, one channel's ``(6 c(0) − 8 c(1) + 2 c(2))/6``, took
    for shot noise wherever the highlight sat (whitened mean square 0.54 on
    the highlight of a noise-textured capture). One channel: that
    stationary share.

    NNLS on ``[w², f w, f²]`` (``w`` ``(S, N, 1)`` the inverse irradiance,
    default 1; :func:`~wardjax.effects._noise.noise_columns`).
    """
    s_n, n, c_n = e.shape
    w = np.ones((s_n, n, 1)) if w is None else np.broadcast_to(w, (s_n, n, 1))
    g = np.where(ok, e, np.nan)
    d = g[:, :-2] - 2.0 * g[:, 1:-1] + g[:, 2:]
    out = np.zeros((c_n, 3))
    for c in range(c_n):
        blk = X[c * n : (c + 1) * n, c * n : (c + 1) * n]
        cm = [float(np.mean(np.diagonal(blk, m))) for m in range(3)]
        pairs = [(c2, cm[0] / X[c * n, c2 * n]) for c2 in range(c_n) if c2 != c and X[c * n, c2 * n] > 0]
        if pairs:  # the texture's share at each value, from the channels' cross-products
            tex = np.mean([r * d[..., c] * d[..., c2] for c2, r in pairs], axis=0) / 6.0
        else:
            tex = np.full(d.shape[:2], (6.0 * cm[0] - 8.0 * cm[1] + 2.0 * cm[2]) / 6.0)
        y = d[..., c] ** 2 / 6.0 - tex
        lv = level[:, 1:-1, c]
        m = np.isfinite(y)
        sc = max(float(np.mean(np.abs(lv[m]))), 1e-30)
        coef, _ = nnls(noise_columns(lv[m] / sc, w[:, 1:-1, 0][m]), y[m])
        out[c] = coef / np.array([1.0, sc, sc * sc])
    return out


def cross_covariance(e: np.ndarray, off: np.ndarray, lags: tuple[int, int] | None = None) -> np.ndarray:
    """Texture covariance between scanlines and between channels ``(C, C, 2K + 1, 2M + 1)``.

    ``X[c, c', K + k, M + m] = ⟨ē_{s,i,c} ē_{s+k,i+m,c'}⟩`` off the highlight,
    about each scanline's mean, for scanline lags ``1 ≤ |k| ≤ K`` and sample
    lags ``|m| ≤ M``; ``k = 0`` (within a scanline, which the whitening
    models) is zero. Neighbouring scanlines are neighbouring image columns:
    this is what the per-scanline Gaussian process leaves out.

    ``lags`` ``(K, M)``, default 8 scanlines and half a scanline of samples —
    the range the within-scanline covariance spans
    (:func:`joint_autocovariance`). The sample range matters: a candidate's
    whitened direction is orthogonal to each scanline's constants (ρd is
    profiled), so its products with the covariance largely cancel when
    summed over a scanline's lags, but cut off after a few samples they do
    not, and a present effect (a camera response on a veined marble) reads
    a design effect several times too large.
    """
    n = e.shape[1]
    K, M = (_CROSS_SCANLINES, max(n // 2, 2)) if lags is None else lags
    out = _lag_means(_centred(e, off), K, M)
    out[:, :, K] = 0.0  # within a scanline: modelled by the whitening
    return out


def convolve_full(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """The full linear convolution of two real 2-D arrays, ``(X₀ + Y₀ − 1, X₁ + Y₁ − 1)``, by FFT.

    What ``scipy.signal.fftconvolve(x, y, mode="full")`` returns (the same numbers to rounding), with
    :mod:`scipy.fft` directly: ``scipy.signal`` imports ``scipy.stats``, together about 0.9 s of a
    ``diagnose`` run's start.
    """
    shape = [p + q - 1 for p, q in zip(x.shape, y.shape, strict=True)]
    fshape = [sfft.next_fast_len(k, real=True) for k in shape]
    spectrum = np.asarray(sfft.rfftn(x, fshape)) * np.asarray(sfft.rfftn(y, fshape))
    return np.asarray(sfft.irfftn(spectrum, fshape))[: shape[0], : shape[1]]


def _lag_sums(a: np.ndarray, b: np.ndarray, K: int, M: int) -> np.ndarray:
    """``Σ_{s,i} a[s, i] b[s + k, i + m]`` over the overlap, for ``|k| ≤ K``, ``|m| ≤ M``: ``(2K + 1, 2M + 1)``.

    One FFT cross-correlation of the ``(S, N)`` arrays instead of a sum per
    lag (the same numbers to rounding, tens of times faster): it is measured
    once per candidate whose evidence is deflated.
    """
    s_n, n = a.shape
    full = convolve_full(b, a[::-1, ::-1])  # entry (k + S − 1, m + N − 1)
    return full[s_n - 1 - K : s_n + K, n - 1 - M : n + M]


def design_effect(d: np.ndarray, W: np.ndarray, sigma: np.ndarray, use: np.ndarray, cross: np.ndarray) -> float:
    """Variance inflation of a whitened direction ``d`` ``(S, N, C)`` by the texture the whitening leaves out.

    Along ``d`` (the change a candidate effect makes to the whitened
    residuals) the evidence is ``Δχ² ≈ (dᵀr)²/dᵀd``; under the working model
    ``Var(dᵀr) = dᵀd``. With the covariance ``X`` between scanlines and
    channels (:func:`cross_covariance`) it is ``dᵀd + Σ X(k, m) u_{s,i,c}
    u_{s+k,i+m,c'}`` with ``u = Wᵀd / σ`` (back in units of f), so the
    evidence is divided by::

        D = max(1, 1 + Σ X(k, m) u u' / dᵀd)

    (a first-order Rao–Scott correction; never below 1, so it only ever
    withholds evidence). This is what keeps marble's veins, coherent over
    several image columns, from being read as a trend across scanlines.
    """
    K, M = (cross.shape[2] - 1) // 2, (cross.shape[3] - 1) // 2
    dd = float(np.sum(d * d))
    if dd <= 0:
        return 1.0
    if W.ndim == 3:  # channels whitened together
        s_n, n, c_n = d.shape
        dj = d.transpose(0, 2, 1).reshape(s_n, c_n * n)
        v = np.einsum("sij,si->sj", W, dj).reshape(s_n, c_n, n).transpose(0, 2, 1)
    else:
        v = np.einsum("scij,sic->sjc", W, d)  # Wᵀ d per scanline and channel
    u = np.where(use, v / sigma, 0.0)
    c_n = u.shape[-1]
    extra = sum(
        float(np.sum(cross[c, c2] * _lag_sums(u[..., c], u[..., c2], K, M))) for c in range(c_n) for c2 in range(c_n)
    )
    return max(1.0, 1.0 + extra / dd)
