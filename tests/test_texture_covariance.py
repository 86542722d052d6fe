"""The texture covariance the scanline model carries: measured along a scanline and between channels, and the
design effect of the part it leaves out (between neighbouring scanlines)."""

import math

import numpy as np

from wardjax.effects._texture import (
    TextureFit,
    cross_covariance,
    design_effect,
    joint_autocovariance,
    texture_whitening,
)


def _smooth_field(rng, s, n, width):
    """Unit-variance field, Gaussian-smoothed along the scanline (smooth grain, not an exponential)."""
    from scipy.ndimage import gaussian_filter1d

    x = gaussian_filter1d(rng.standard_normal((s, n + 8 * width)), width, axis=1)[:, 4 * width : 4 * width + n]
    return x / x.std()


def test_joint_covariance_whitens_a_texture_shared_by_the_channels():
    """One smooth pattern in the diffuse colour of every channel plus white noise: whitened with the measured
    covariance, the residuals are white — unit variance, no correlation along the scanline or between channels —
    which the per-channel exponential cannot give (it leaves the channels correlated)."""
    rng = np.random.default_rng(0)
    s, n = 300, 48
    colour = np.array([0.6, 0.5, 0.4])
    noise = 0.002
    t = 0.03 * _smooth_field(rng, s, n, 3)
    e = t[..., None] * colour + noise * rng.standard_normal((s, n, 3))
    e -= e.mean(1, keepdims=True)  # what one ρd per scanline and channel leaves
    ok = np.ones(e.shape, bool)
    X, used = joint_autocovariance(e, ok, np.full(3, noise**2))
    assert np.allclose(used, noise**2)  # the given noise is below the lag-0 to lag-1 drop: kept
    # the measured cross-channel covariance at lag 0 is the colour's outer product times the texture variance
    lag0 = np.array([[X[c * n + 5, c2 * n + 5] for c2 in range(3)] for c in range(3)])
    corr = lag0 / np.sqrt(np.outer(np.diag(lag0), np.diag(lag0)))
    assert np.all(corr > 0.95)
    fit = TextureFit(np.tile([noise**2, 0.0, 0.0], (3, 1)), np.zeros(3), np.zeros(3), np.ones(3), np.zeros(3), X)
    sigma = np.full(e.shape, noise)
    W = texture_whitening(fit, sigma, ok)
    assert W.shape == (s, 3 * n, 3 * n)
    zj = np.einsum("sij,sj->si", W, (e / sigma).transpose(0, 2, 1).reshape(s, 3 * n))
    z = zj.reshape(s, 3, n)
    # a per-scanline mean was removed in each channel: 3 of the 3n directions per scanline are spent
    assert abs(np.mean(z**2) * n / (n - 1) - 1) < 0.1
    assert abs(np.mean(z[:, :, 1:] * z[:, :, :-1])) < 0.05
    rgb = np.corrcoef(z.transpose(1, 0, 2).reshape(3, -1))
    assert np.max(np.abs(rgb - np.eye(3))) < 0.1


def test_design_effect_of_a_trend_across_correlated_scanlines():
    """A texture correlated from scanline to scanline as an AR(1), ρ_s per scanline, and the direction of a
    level change shared by all scanlines: the per-scanline model undercounts its variance by
    ``Σ_s,s' ρ_s^|s−s'| / S ≈ (1 + ρ_s)/(1 − ρ_s)``; the design effect reads that, and a Monte Carlo of the
    statistic ``dᵀr`` agrees."""
    rng = np.random.default_rng(1)
    s, n, rho_s, noise = 400, 24, 0.6, 0.01

    def field():
        x = np.empty((s, n))
        x[0] = rng.standard_normal(n)
        for k in range(1, s):
            x[k] = rho_s * x[k - 1] + math.sqrt(1 - rho_s**2) * rng.standard_normal(n)
        return 0.02 * x[..., None] + noise * rng.standard_normal((s, n, 1))  # white along the scanline

    e = field()
    ok = np.ones(e.shape, bool)
    X = cross_covariance(e, ok, lags=(12, 2))
    tex, tot = 0.02**2, 0.02**2 + noise**2
    W = np.broadcast_to(np.eye(n), (s, 1, n, n))  # the working model: white along each scanline, variance tot
    sigma = np.full(e.shape, math.sqrt(tot))
    d = np.zeros(e.shape)
    d[:, n // 3 : 2 * n // 3] = 1.0  # a bump in the middle of every scanline, as a lobe-amplitude change gives
    d -= d.mean(1, keepdims=True)  # what is left of it beside ρd per scanline
    deff = design_effect(d, W, sigma, ok, X)
    # about each scanline's mean the bump's variance ratio is the AR(1) sum, weighted by the texture's share
    theory = 1 + tex / tot * (2 * rho_s / (1 - rho_s))
    assert abs(deff / theory - 1) < 0.15
    # the statistic dᵀr over independent draws: its variance over dᵀd·var(e) is the design effect
    stats = []
    for _ in range(60):
        r = field()
        r -= r.mean(1, keepdims=True)
        stats.append(np.sum(d * r))
    mc = np.var(stats) / (np.sum(d * d) * tot)
    assert abs(mc / theory - 1) < 0.35


def test_design_effect_is_one_for_a_texture_independent_between_scanlines():
    rng = np.random.default_rng(2)
    e = 0.02 * rng.standard_normal((300, 32, 2))
    ok = np.ones(e.shape, bool)
    X = cross_covariance(e, ok)
    W = np.broadcast_to(np.eye(32), (300, 2, 32, 32))
    d = np.zeros(e.shape)
    d[:, 10:20] = 1.0
    assert design_effect(d, W, np.ones(e.shape), ok, X) < 1.1
