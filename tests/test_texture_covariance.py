"""The texture covariance the scanline model carries: measured along a scanline and between channels, and the
design effect of the part it leaves out (between neighbouring scanlines)."""

import math

import numpy as np
import pytest

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


def test_design_effect_spans_the_scanline_for_a_texture_smooth_along_it():
    """A texture smooth along the scanline (Gaussian, width 4 samples) and AR(1) across scanlines, whitened along
    each scanline by its measured covariance; a lobe-shaped change orthogonal to each scanline's constant (ρd is
    profiled). A Monte Carlo of ``dᵀr`` over independent draws is the true design effect: read over half a
    scanline of sample lags (the default) it agrees to 20 %; cut off at 8 samples it reads lower, further off."""
    from scipy.ndimage import gaussian_filter1d

    rng = np.random.default_rng(4)
    s, n, rho_s, noise, width = 200, 48, 0.7, 0.01, 4

    def field():
        x = np.empty((s, n + 8 * width))
        x[0] = rng.standard_normal(n + 8 * width)
        for k in range(1, s):
            x[k] = rho_s * x[k - 1] + math.sqrt(1 - rho_s**2) * rng.standard_normal(n + 8 * width)
        t = 0.1 * gaussian_filter1d(x, width, axis=1)[:, 4 * width : 4 * width + n]
        return (t + noise * rng.standard_normal((s, n)))[..., None]

    e = field()
    ok = np.ones(e.shape, bool)
    X, _ = joint_autocovariance(e, ok, np.array([noise**2]))
    fit = TextureFit(np.array([[noise**2, 0.0, 0.0]]), np.zeros(1), np.zeros(1), np.ones(1), np.zeros(1), X)
    sigma = np.full(e.shape, noise)
    W = texture_whitening(fit, sigma, ok)
    g = np.exp(-0.5 * ((np.arange(n) - n / 2) / 5.0) ** 2)  # a lobe-sized bump in every scanline
    d = np.einsum("sij,j->si", W, g / noise)
    a = np.einsum("sij,j->si", W, np.ones(n) / noise)  # the whitened constant, which ρd takes
    d = (d - a * (np.sum(a * d, 1, keepdims=True) / np.sum(a * a, 1, keepdims=True)))[..., None]
    deff = design_effect(d, W, sigma, ok, cross_covariance(e, ok))
    short = design_effect(d, W, sigma, ok, cross_covariance(e, ok, lags=(8, 8)))
    stats = [np.sum(d[..., 0] * np.einsum("sij,sj->si", W, field()[..., 0] / noise)) for _ in range(300)]
    mc = np.var(stats) / np.sum(d * d)
    assert mc > 3.0  # the scanlines' shared texture matters here
    assert abs(deff / mc - 1) < 0.2
    assert abs(short - mc) > abs(deff - mc)


def test_design_effect_is_one_for_a_texture_independent_between_scanlines():
    rng = np.random.default_rng(2)
    e = 0.02 * rng.standard_normal((300, 32, 2))
    ok = np.ones(e.shape, bool)
    X = cross_covariance(e, ok)
    W = np.broadcast_to(np.eye(32), (300, 2, 32, 32))
    d = np.zeros(e.shape)
    d[:, 10:20] = 1.0
    assert design_effect(d, W, np.ones(e.shape), ok, X) < 1.1


def _channel_texture(rng, s, n, width, mix):
    """A texture in three channels: rows of ``mix`` weight independent smooth fields of one spatial scale (one
    row of weights is a scalar modulation of a colour; several rows make its hue vary with the pattern)."""
    fields = np.stack([_smooth_field(rng, s, n, width) for _ in range(mix.shape[0])], -1)  # (S, N, K)
    return fields @ mix  # (S, N, C)


def test_white_noise_share_is_read_between_channels():
    """The white noise under a smooth texture: its share of the lag-0 variance is what the channels' cross-
    covariance (which has no nugget) does not explain. Recovered within 10 % for a scalar modulation and for a
    texture whose hue varies with the pattern (texture variance 4–9× the noise's, as on the textured bench); the
    drop from lag 0 to lag 1 (the old upper bound) overstates it."""
    from wardjax.effects._texture import lag_covariances
    from wardjax.effects._texture_term import white_noise_share

    rng = np.random.default_rng(3)
    s, n = 200, 64
    noise = np.array([0.004, 0.003, 0.0025])
    for mix in (np.array([[0.012, 0.01, 0.008]]), np.array([[0.012, 0.008, 0.004], [0.0, 0.006, 0.008]])):
        e = _channel_texture(rng, s, n, 4, mix) + noise * rng.standard_normal((s, n, 3))
        ok = np.ones(e.shape, bool)
        lags = lag_covariances(e, ok)
        nu = white_noise_share(lags)
        np.testing.assert_allclose(nu, noise**2, rtol=0.1)
        half = (lags.shape[2] - 1) // 2
        drop = np.array([lags[c, c, half] - lags[c, c, half + 1] for c in range(3)])
        assert np.all(drop > 1.1 * noise**2)
    # one channel: the straight line through lags 1 and 2, for a texture smooth at the sample scale
    e = 0.012 * _smooth_field(rng, s, n, 6)[..., None] + 0.004 * rng.standard_normal((s, n, 1))
    nu = white_noise_share(lag_covariances(e, np.ones(e.shape, bool)))
    np.testing.assert_allclose(nu, 0.004**2, rtol=0.25)


def test_level_noise_follows_the_irradiance_under_a_texture():
    """Read and shot noise divided by an irradiance that falls along the scanline, under a texture whose
    roughness changes along it too: the noise read from lag-1 differences, the texture's share taken from the
    other channels value by value, follows ``s0 w² + s1 f w`` within 15 % at both ends."""
    from scipy.ndimage import gaussian_filter1d

    from wardjax.effects._noise import noise_columns
    from wardjax.effects._texture import joint_autocovariance, lag_covariances, level_noise
    from wardjax.effects._texture_term import white_noise_share

    rng = np.random.default_rng(4)
    s, n = 300, 64
    w = np.broadcast_to(np.linspace(0.5, 1.5, n)[None, :, None], (s, n, 1))
    level = np.broadcast_to(np.array([0.2, 0.16, 0.12]), (s, n, 3))
    true = np.stack([noise_columns(level[..., c], w[..., 0]) @ np.array([4e-6, 2e-5, 0.0]) for c in range(3)], -1)
    # the texture's step on the sample plane halves along the scanline: rougher at the start than at the end
    rough = gaussian_filter1d(rng.standard_normal((s, 2 * n)), 2, axis=1)[:, ::2]
    smooth = gaussian_filter1d(rng.standard_normal((s, n)), 4, axis=1)
    ramp = np.linspace(1.0, 0.0, n)[None, :]
    t = ramp * rough / rough.std() + (1 - ramp) * smooth / smooth.std()
    e = 0.02 * t[..., None] * np.array([1.0, 0.8, 0.6]) + np.sqrt(true) * rng.standard_normal((s, n, 3))
    ok = np.ones(e.shape, bool)
    lags = lag_covariances(e, ok)
    X, _ = joint_autocovariance(e, ok, white_noise_share(lags), lags)
    coef = level_noise(e, level, ok, X, w)
    est = np.stack([noise_columns(level[..., c], w[..., 0]) @ coef[c] for c in range(3)], -1)
    for sl in (slice(0, 8), slice(n - 8, n)):
        np.testing.assert_allclose(est[:, sl].mean((0, 1)), true[:, sl].mean((0, 1)), rtol=0.15)


def _profiled_chi2(e, X, noise, ok):
    """Per scanline, the generalised least squares χ² about a free level (ρd) of the values in ``ok``, with the
    covariance ``noise² I + X``: ``eᵀ (K⁻¹ − K⁻¹ 1 (1ᵀ K⁻¹ 1)⁻¹ 1ᵀ K⁻¹) e``, and its degrees of freedom ``n − 1``."""
    q, dof = [], []
    for row, m in zip(e, ok):
        ki = np.linalg.inv(noise**2 * np.eye(m.sum()) + X[np.ix_(m, m)])
        one = np.ones(m.sum())
        a = ki @ one
        r = row[m]
        q.append(r @ ki @ r - (a @ r) ** 2 / (one @ a))
        dof.append(m.sum() - 1)
    return float(np.sum(q)) / float(np.sum(dof))


def test_variogram_covariance_is_unbiased_on_two_runs_where_products_about_the_mean_are_not():
    """A texture smooth along the scanline (Gaussian, width 8 samples, as the simulated wood), 25× the white
    noise's variance, measured on two runs of values either side of a highlight, each scanline about its own level.
    With the covariance from the cross-variogram (a quarter-scanline window, the guard's second opinion) the
    profiled χ² per degree of freedom reads 0.94 (the window's leakage puts a little texture at high frequencies,
    where there is only noise); from the products about each scanline's mean, whose bias changes with the lag where
    the values are two runs, 0.83: the same data look better fitted than the noise allows, and a gap left on top
    of such a texture reads larger against it than it is."""
    from wardjax.effects._texture import lag_covariances

    rng = np.random.default_rng(5)
    s, n, noise = 300, 96, 0.006
    t = 0.03 * _smooth_field(rng, s, n, 8)
    e = (t + noise * rng.standard_normal((s, n)))[..., None]
    ok = np.ones(e.shape, bool)
    ok[:, 30:62] = False  # the highlight, where the texture is not measured
    e = np.where(ok, e - np.nanmean(np.where(ok, e, np.nan), 1, keepdims=True), 0.0)
    nu = np.array([noise**2])
    X_v, _ = joint_autocovariance(e, ok, nu, lag_covariances(e, ok, variogram=True), window=0.5)
    X_m, _ = joint_autocovariance(e, ok, nu)
    g_v, g_m = _profiled_chi2(e[..., 0], X_v, noise, ok[..., 0]), _profiled_chi2(e[..., 0], X_m, noise, ok[..., 0])
    assert 0.92 < g_v < 1.05, g_v
    assert g_m < 0.88, g_m


def test_lag_sums_by_fft_equal_the_sums_over_each_overlap():
    """The cross-covariance and the design effect sum products over every scanline and sample lag; by FFT they must
    give the sums taken directly over each overlap, for every lag sign (an index off by one would shift them)."""
    from wardjax.effects._texture import _lag_sums

    rng = np.random.default_rng(3)
    a, b = rng.standard_normal((7, 11)), rng.standard_normal((7, 11))
    K, M = 3, 5
    got = _lag_sums(a, b, K, M)
    for k in range(-K, K + 1):
        for m in range(-M, M + 1):
            want = sum(
                a[s, i] * b[s + k, i + m] for s in range(7) for i in range(11) if 0 <= s + k < 7 and 0 <= i + m < 11
            )
            assert got[K + k, M + m] == pytest.approx(want, abs=1e-12)


def test_fft_convolution_equals_scipy_signal():
    """The FFT convolution the lag sums and the standard's smoothing kernel use is SciPy's ``fftconvolve`` (mode
    "full"), computed with ``scipy.fft`` alone: same shape and values for unequal, odd and even shapes."""
    from scipy.signal import fftconvolve

    from wardjax.effects._texture import convolve_full

    rng = np.random.default_rng(4)
    for sx, sy in [((7, 11), (7, 11)), ((5, 8), (9, 3)), ((1, 16), (4, 1))]:
        x, y = rng.standard_normal(sx), rng.standard_normal(sy)
        want = fftconvolve(x, y, mode="full")
        got = convolve_full(x, y)
        assert got.shape == want.shape
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-12)


# --------------------------------------------------------------------------- the capture fit's texture-field estimator


def _field_and_covariance(rng, shape, width, draws):
    """``draws`` samples of a stationary field (white noise convolved with a Gaussian kernel ``k``) and its exact
    autocovariance ``c = k ⋆ k`` on lags ``(−G1 … G1) × (−G2 … G2)`` (index ``Δ mod 2G``)."""
    from scipy.signal import fftconvolve

    half = int(np.ceil(4 * width))
    t = np.arange(-half, half + 1)
    k = np.exp(-0.5 * (t[:, None] ** 2 + t[None, :] ** 2) / width**2)
    k /= np.sqrt(np.sum(k**2))  # unit variance
    white = rng.standard_normal((draws, shape[0] + 2 * half, shape[1] + 2 * half))
    fields = fftconvolve(white, k[None], mode="valid", axes=(1, 2))
    c = fftconvolve(k, k[::-1, ::-1])  # lags −2·half … 2·half
    lag = np.zeros((2 * shape[0], 2 * shape[1]))
    i = np.arange(-2 * half, 2 * half + 1)
    lag[np.ix_(i % lag.shape[0], i % lag.shape[1])] = c
    return fields, lag


def _exact_covariance(g, lag):
    """``Σ_u Σ_v g_p(u) c(v − u) g_q(v)`` for ``g`` ``(G1, G2, P)`` by FFT on the ``2G`` torus (no wrap)."""
    gf = np.fft.fft2(g, s=lag.shape, axes=(0, 1))
    return np.einsum("abp,ab,abq->pq", gf, np.fft.fft2(lag), np.conj(gf)).real / lag.size


def test_placement_covariance_is_unbiased_and_positive_definite():
    """A stationary field of known autocovariance and two statistics of it — a mean over a block and a contrast
    that changes sign across the block (as a lobe's α-derivative does). From one sample, the placement estimate
    is positive semi-definite in every draw; over draws its mean is the exact ``g C gᵀ``: with the full
    placements alone for a correlated field (within 8 %, the Monte-Carlo spread ±3 %), and with the partial
    ones scaled by their overlap for an uncorrelated one. The Monte-Carlo covariance of the statistics agrees."""
    from wardjax.fit import placement_covariance

    rng = np.random.default_rng(3)
    shape, draws = (56, 52), 150
    g = np.zeros(shape + (2,))
    g[22:34, 20:32, 0] = 1.0 / 12**2  # a mean over a 12 × 12 block
    g[22:34, 20:26, 1], g[22:34, 26:32, 1] = 1.0, -1.0  # a contrast: left half minus right half
    occupied = np.ones(shape, bool)
    for width, min_overlap in ((2.5, 1.0), (0.0, 0.5)):
        if width:
            fields, lag = _field_and_covariance(rng, shape, width, draws)
            truth = _exact_covariance(g, lag)
        else:
            fields = rng.standard_normal((draws,) + shape)
            truth = np.einsum("abp,abq->pq", g, g)
        est = np.array([placement_covariance(f[..., None], occupied, g[..., None], min_overlap) for f in fields])
        assert np.all(np.linalg.eigvalsh(est) >= -1e-12 * np.trace(est, axis1=1, axis2=2)[:, None])
        np.testing.assert_allclose(np.diag(est.mean(axis=0)), np.diag(truth), rtol=0.08)
        theta = np.einsum("dab,abp->dp", fields, g)
        np.testing.assert_allclose(theta.var(axis=0), np.diag(truth), rtol=0.35)  # 150 draws: ±12 % (1σ)
