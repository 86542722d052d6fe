"""The texture between scanlines, in the scanlines' diffuse levels: their relative ρd as a Gaussian process.

Why
    The scanline model profiles ρd per scanline and channel, so anything that
    scales a whole scanline (an image column) is absorbed: an illumination
    ramp across the image, ``1 + g s``, survives only on the specular lobe,
    whose amplitude then trends across scanlines. On a textured probe that
    is weak evidence — the GP along each scanline prices a lobe-sized bump
    as texture (wood 10 %, ``g = 0.25``: Δχ² 5.8; the same ramp without
    texture: 991). The ramp is also in the diffuse level: regressed on the
    scanline's mean field coordinate ``s̄``, the log of the baseline's ρd of
    160 × 120 captures has slope 0.28 for ``g = 0.25`` and 0.14 for ``g =
    0.12`` on every texture, and 0.00–0.04 (noise, wood, marble 4 %) and
    0.10 ± 0.07 (marble 10 %) without a ramp. A camera response or an offset
    on the lit frame leaves it flat (slopes within ±0.02).

    So the levels enter the likelihood as a random effect: ``ℓ_j = mean_c
    ρd_{j,c}/ρ̄d_c`` (:func:`relative_levels`) is a Gaussian process over the scanline index ``j`` about
    a common mean ``μ`` (profiled), with covariance ``C = σ² (ρ^{|j−k|} +
    λ δ_{jk})`` — texture correlated over neighbouring columns, plus what
    each column's own mean carries — and the residuals gain ``L⁻¹ (ℓ −
    μ̂ 1)`` (``L Lᵀ = C``; :func:`level_whitening`). An effect that changes
    the levels coherently across the image (``illumination_gradient``'s
    ``b``) is then fitted to both its signatures at once, and a specular
    trend the levels do not share is not named a ramp.

Estimating ``C`` (restricted maximum likelihood)
    From the baseline's ``ℓ`` with the mean *and* the trend in ``s̄`` as fixed
    effects, so that a ramp in the capture is not taken for texture: ``σ²``
    profiled, ``(ρ, λ)`` the best of a grid (Patterson & Thompson 1971).
    The trend is removed only for the estimate; the whitening profiles the
    mean alone, so a ramp still costs χ² until an effect explains it.

    From ~55 levels the estimate is uncertain exactly where a trend lives
    (long-range correlation), and a trend's Δχ² under it is heavier-tailed
    than χ²₁ (at ρ 0.93, Δχ² > 9.6 in 5.5 % of trend-free series, not
    0.2 %). ``deff`` (in the summary) is the 95 % point of that statistic
    over series drawn from the estimated ``C``, each with ``C`` re-estimated
    (a parametric bootstrap), over χ²₁'s; discovery divides the levels'
    share of a candidate's Δχ² by it
    (:meth:`~wardjax.effects._texture_term.CrossTexture.deflate`). It helps
    but does not fully calibrate: the 5 % test still rejects 5–9 % at ρ
    0.85 and 10 % at 0.93 (``tests/test_levels.py``).
"""

from __future__ import annotations

import numpy as np

__all__ = ["level_whitening", "relative_levels"]

_RHO_GRID = (0.0, 0.3, 0.5, 0.7, 0.8, 0.85, 0.9, 0.93, 0.96, 0.98)
_NUGGET_GRID = (0.01, 0.1, 0.3, 1.0)
_MIN_SCANLINES = 8
_BOOTSTRAP = 200
_CHI2_1_95 = 3.841


def relative_levels(rho: np.ndarray, seen: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``ℓ = ρd a`` per scanline ``(S,)``, the weights ``a = 1/(C ρ̄d)`` ``(C,)`` and where ``ℓ`` is defined.

    ``ρ̄d`` per channel is the mean over the scanlines ``seen`` of the
    baseline's profiled ``rho`` ``(S, 1, C)``; it stays fixed for every fit
    after, so a term added to the diffuse level moves every ``ℓ`` alike
    (the mean takes it) and only a change that differs between scanlines
    costs χ². (Logs of the fitted ρd did not: a broad additive term as large
    as the diffuse level, with ρd near 0, flattened them.)
    """
    r = np.asarray(rho, float).reshape(np.shape(rho)[0], -1)
    ok = seen & np.all(np.isfinite(r), axis=1)
    mean = np.mean(r[ok], axis=0) if ok.any() else np.ones(r.shape[1])
    if not np.all(mean > 0):
        return np.zeros(len(r)), np.zeros(r.shape[1]), np.zeros(len(r), bool)
    a = 1.0 / (r.shape[1] * mean)
    return np.where(ok, np.where(ok[:, None], r, 0.0) @ a, 0.0), a, ok


def _corr(idx: np.ndarray, rho: float, nugget: float) -> np.ndarray:
    lag = np.abs(idx[:, None] - idx[None, :])
    return rho**lag + nugget * np.eye(len(idx))


class _RemlGrid:
    """Restricted likelihood (Patterson & Thompson 1971) of series on scanlines ``idx`` with fixed effects ``X``,
    over the grid of ``(ρ, λ)``, ``σ²`` profiled: what does not depend on the series is computed once."""

    def __init__(self, idx: np.ndarray, X: np.ndarray):
        self.grid = [(r, v) for r in _RHO_GRID for v in _NUGGET_GRID]
        V = np.stack([_corr(idx, r, v) for r, v in self.grid])
        L = np.linalg.cholesky(V)
        self.Linv = np.linalg.inv(L)  # (G, n, n)
        Xw = self.Linv @ X  # (G, n, p)
        q, _ = np.linalg.qr(Xw)
        self.q = q  # the whitened fixed effects' span
        n, p = X.shape
        self.dof = n - p
        _, logdet_x = np.linalg.slogdet(np.swapaxes(Xw, 1, 2) @ Xw)
        self.const = 2.0 * np.sum(np.log(np.diagonal(L, axis1=1, axis2=2)), axis=1) + logdet_x
        # whitened deviations from the GLS mean (σ² = 1): L⁻¹ (I − 1 wᵀ), wᵀ ℓ = 1ᵀ C⁻¹ ℓ / 1ᵀ C⁻¹ 1
        u = self.Linv @ np.ones(n)  # (G, n)
        w = np.einsum("gnm,gn->gm", self.Linv, u) / np.sum(u * u, axis=1, keepdims=True)
        self.P = self.Linv - u[:, :, None] * w[:, None, :]

    def fit(self, y: np.ndarray) -> tuple[int, float]:
        """The grid index of the REML estimate for ``y`` ``(n,)`` and its ``σ²``."""
        yw = self.Linv @ y  # (G, n)
        proj = np.einsum("gnp,gn->gp", self.q, yw)
        s2 = np.maximum((np.sum(yw * yw, axis=1) - np.sum(proj * proj, axis=1)) / self.dof, 1e-300)
        ll = -0.5 * (self.dof * np.log(s2) + self.const)
        g = int(np.argmax(ll))
        return g, float(s2[g])


def level_whitening(ell: np.ndarray, ok: np.ndarray, trend: np.ndarray) -> tuple[np.ndarray, dict] | None:
    """The matrix ``P`` ``(n, S)`` with ``‖P ℓ‖² = (ℓ − μ̂ 1)ᵀ C⁻¹ (ℓ − μ̂ 1)``, and a summary of ``C``.

    Parameters
    ----------
    ell, ok
        :func:`relative_levels` of the baseline, ``(S,)``.
    trend
        ``(S,)`` the scanline's mean field coordinate ``s̄`` (a fixed effect
        of the REML estimate only).

    Returns ``None`` with fewer than 8 defined scanlines. ``P`` is zero in the
    columns of undefined scanlines; its ``n`` rows (the defined ones) have
    rank ``n − 1`` (``μ`` profiled), the degrees of freedom the term adds.
    """
    idx = np.flatnonzero(ok)
    n = len(idx)
    if n < _MIN_SCANLINES:
        return None
    y = ell[idx]
    x = trend[idx] - np.mean(trend[idx])
    grid = _RemlGrid(idx, np.stack([np.ones(n), x], axis=1))
    g, s2 = grid.fit(y)
    r, v = grid.grid[g]
    P = np.zeros((n, len(ell)))
    P[:, idx] = grid.P[g] / np.sqrt(s2)
    # a trend's Δχ² under the estimated C is χ²₁ only if C were known: over series drawn from it, each with its C
    # re-estimated, its 95 % point against χ²₁'s is the inflation the estimate's own error brings (1 for white
    # levels, ~2.6 at ρ 0.93, where a trend-free series passed Δχ² > 9.6 in 5.5 % of draws, not 0.2 %)
    rng = np.random.default_rng(0)
    Lc = np.linalg.cholesky(s2 * _corr(idx, r, v))
    stats = []
    for _ in range(_BOOTSTRAP):
        yb = Lc @ rng.standard_normal(n)
        gb, s2b = grid.fit(yb)
        a, b = grid.P[gb] @ yb, grid.P[gb] @ x
        stats.append(float(a @ b) ** 2 / max(float(b @ b), 1e-300) / s2b)
    deff = max(1.0, float(np.quantile(stats, 0.95)) / _CHI2_1_95)
    return P, {"sd": float(np.sqrt(s2 * (1.0 + v))), "rho": float(r), "nugget": float(v), "n": n, "deff": deff}


def subset_whitening(s_n: int, idx: np.ndarray, rho: float, nugget: float, s2: float) -> np.ndarray:
    """:func:`level_whitening`'s ``P`` ``(n, s_n)`` for the scanlines ``idx`` alone, under a covariance estimated
    on all of them (``σ² (ρ^{|j−k|} + λ δ_{jk})``, the mean profiled): the levels of one half of the scanlines
    (the hold-out check, :mod:`~wardjax.effects._holdout`)."""
    idx = np.asarray(idx)
    n = len(idx)
    Linv = np.linalg.inv(np.linalg.cholesky(_corr(idx, rho, nugget)))
    u = Linv @ np.ones(n)
    w = Linv.T @ u / float(u @ u)
    P = np.zeros((n, s_n))
    P[:, idx] = (Linv - np.outer(u, w)) / np.sqrt(s2)
    return P
