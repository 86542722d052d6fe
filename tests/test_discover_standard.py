"""The smoothed standard's noise in the fitted parameters' σ (wardjax.effects._standard_sigma)."""

from __future__ import annotations

import numpy as np
import pytest


def test_lag_form_is_the_variance_of_a_sum_over_smoothed_binned_noise():
    """A linear functional ``Σ a_i ε̄_i`` of white pixel noise (variance ``c``) smoothed by a Gaussian and binned
    ``b × b``: its variance over 4,000 draws equals ``c R(0) Σ a²`` plus :func:`lag_form`, and the per-value term
    alone falls short by about ``1/(b² R(0))`` for a smooth ``a``. Scanlines are columns of bins, two of them
    skipped (``columns``)."""
    from scipy.ndimage import gaussian_filter

    from wardjax.effects._standard_noise import bin_lag_correlation
    from wardjax.effects._standard_sigma import lag_form

    rng = np.random.default_rng(0)
    b, sig_px, c = 2, 1.5, 0.7
    h = w = 40  # pixels: 20 × 20 bins
    nb = h // b
    cols = np.array([j for j in range(nb) if j not in (5, 6)])  # the scanlines kept (bin columns)
    yy, xx = np.meshgrid(np.arange(nb), cols, indexing="ij")  # (N, S)
    a = np.stack([np.exp(-((xx - 9.5) ** 2 + (yy - 9.5) ** 2) / 30.0), np.cos(yy / 4.0)], -1)  # (N, S, K)
    a = np.swapaxes(a, 0, 1)[:, :, None, :]  # (S, N, C = 1, K = 2)
    draws = 4000
    noise = rng.normal(0.0, np.sqrt(c), (draws, h, w))
    sm = gaussian_filter(noise, (0, sig_px, sig_px), mode="wrap")
    binned = sm.reshape(draws, nb, b, nb, b).mean(axis=(2, 4))  # (draws, rows, columns) of bins
    eps = np.swapaxes(binned[:, :, cols], 1, 2)  # (draws, S, N)
    proj = np.einsum("dsn,snk->dk", eps, a[:, :, 0, :])
    emp = np.cov(proj.T)
    R = bin_lag_correlation(sig_px, b)
    lag = R.shape[0] // 2
    diag = c * R[lag, lag] * np.einsum("snck,snct->kt", a, a)
    full = diag + lag_form(a, np.array([c]), R, cols, across_only=False)
    se = np.sqrt(2.0 / (draws - 1)) * np.sqrt(np.outer(np.diag(emp), np.diag(emp)))  # SD of a sample covariance
    assert np.all(np.abs(full - emp) < 4 * se)
    assert diag[0, 0] < emp[0, 0] / 4  # the per-value share alone: far too small (R(0) = 0.032 against 1/b² = 0.25)
    # across scanlines only: the lags along each scanline left out, as where the texture carries them
    across = diag + lag_form(a, np.array([c]), R, cols, across_only=True)
    assert diag[0, 0] < across[0, 0] < full[0, 0]


def test_lag_form_takes_each_values_own_noise_level():
    """Pixel noise whose variance ``c(p)`` varies over the standard (a ramp of 8× across it, as its level falls
    away from the lamp), smoothed and binned: the variance of ``Σ a_i ε̄_i`` over 4,000 draws is the per-value form
    with ``c`` at each value, ``Σ_ij a_i a_j √(c_i c_j) R(Δ_ij)``; one ``c`` for all values (their mean) misses it
    by more than the sampling error where ``a`` sits on the quiet side."""
    from scipy.ndimage import gaussian_filter

    from wardjax.effects._standard_noise import bin_lag_correlation
    from wardjax.effects._standard_sigma import lag_form

    rng = np.random.default_rng(1)
    b, sig_px = 1, 1.5
    n = 40
    ramp = 0.2 * 8.0 ** (np.arange(n) / (n - 1))  # c along the pixel rows (the scanlines' direction)
    cols = np.arange(n)
    yy, xx = np.meshgrid(np.arange(n), cols, indexing="ij")  # (N, S)
    a = np.exp(-((xx - 20.0) ** 2 + (yy - 10.0) ** 2) / 40.0)[..., None]  # on the quiet side
    a = np.swapaxes(a, 0, 1)[:, :, None, :]  # (S, N, C = 1, K = 1)
    draws = 4000
    noise = rng.normal(0.0, 1.0, (draws, n, n)) * np.sqrt(ramp)[None, :, None]
    sm = gaussian_filter(noise, (0, sig_px, sig_px), mode="wrap")
    eps = np.swapaxes(sm, 1, 2)  # (draws, S, N)
    emp = np.var(np.einsum("dsn,sn->d", eps, a[:, :, 0, 0]), ddof=1)
    R = bin_lag_correlation(sig_px, b)
    lag = R.shape[0] // 2
    c_val = np.broadcast_to(ramp[None, :, None], (n, n, 1))  # (S, N, C): each value's own c

    def full(c):
        cb = np.broadcast_to(c, a.shape[:3])
        return float(np.sum(cb * a[..., 0] ** 2) * R[lag, lag] + lag_form(a, c, R, cols, across_only=False)[0, 0])

    se = np.sqrt(2.0 / (draws - 1)) * emp
    assert abs(full(c_val) - emp) < 3 * se
    assert full(np.array([ramp.mean()])) > emp + 6 * se


def test_standard_noise_follows_the_standards_level(tmp_path):
    """A 16-bit capture of a dark metal at 160 × 120: the standard's relative noise variance read at each bin's
    mirror point against the simulated sensor's, ``(σ²(lit) + σ²(dark)) / (lit − dark)²`` from the noise-free
    images there. It spans more than 3× over the probe's mirror points (the standard dims away from the lamp),
    and the estimate follows it to within a quarter for 80 % of the bins: no one value could."""
    import wardjax as wj
    from wardjax.effects._standard_noise import standard_noise
    from wardjax.geometry import mirror_point, project
    from wardjax.reconstruct import bin_scanlines, reconstruct_capture, sample_bilinear
    from wardjax.simulate import SensorNoise

    p = wj.WardParams(rho_d=(0.03,) * 3, rho_s=0.35, alpha_x=0.08, alpha_y=0.08)
    kw = {"seed": 1, "texture": "none", "image_size": (160, 120), "bit_depth": 16}
    noisy = wj.simulate_capture(p, tmp_path / "noisy", **kw)
    clean = wj.simulate_capture(p, tmp_path / "clean", noise=SensorNoise(0.0, 0.0), **kw)
    bins = bin_scanlines(reconstruct_capture(noisy), 6000)
    c = standard_noise(noisy, bins.points)
    lit, dark, _ = clean.window(slice(None))
    sensor = SensorNoise()
    truth_img = (sensor.sigma(lit) ** 2 + sensor.sigma(dark) ** 2) / np.maximum(lit - dark, 1e-6) ** 2
    uv, _ = project(noisy.rig.camera, mirror_point(bins.points))
    truth = sample_bilinear(np.asarray(truth_img, float), uv)
    ok = np.isfinite(bins.f_r) & np.isfinite(truth)
    lo, hi = np.percentile(truth[ok], [10, 90])
    assert hi / lo > 3.0
    q10, q90 = np.percentile(c[ok] / truth[ok], [10, 90])
    assert q10 > 0.75 and q90 < 1.25


def test_bin_lag_correlation_keeps_the_noise_low_frequencies():
    """``R(0)`` is the kernel's energy after binning, and the lags sum to ``1/b²``: smoothing removes none of the
    noise's mean."""
    from wardjax.effects._standard_noise import bin_lag_correlation, smoothing_factor

    for b in (1, 2, 3):
        R = bin_lag_correlation(1.5, b)
        lag = R.shape[0] // 2
        assert R[lag, lag] == pytest.approx(smoothing_factor(1.5, b), rel=1e-9)
        assert R.sum() == pytest.approx(1.0 / b**2, rel=1e-4)
        np.testing.assert_allclose(R, R[::-1, ::-1], atol=1e-15)


def _smoothed_binned(rng, shape_bins, b, sig_px, c, cols):
    """Relative errors ``(S, N)`` of the bins ``cols`` × rows: white pixel noise (variance ``c``) smoothed by a
    Gaussian of ``sig_px`` pixels, as the reconstruction smooths the standard, then averaged ``b × b``."""
    from scipy.ndimage import gaussian_filter

    n_cols, n_rows = shape_bins
    px = rng.normal(0.0, np.sqrt(c), (n_rows * b, n_cols * b))
    sm = gaussian_filter(px, sig_px, mode="nearest")
    return sm.reshape(n_rows, b, n_cols, b).mean(axis=(1, 3)).T[cols]  # (S, N)


@pytest.mark.slow
def test_dark_metal_sigma_covers_the_standards_noise(tmp_path):
    """A dark metal (ρd 0.03, ρs 0.35, α 0.08) captured at 160 × 120: the baseline fitted to it is the truth of 40
    draws that give its prediction the probe's white noise and the standard's smoothed noise (per channel, at the
    ``c`` the capture reads at each value; white pixel noise smoothed and binned as the reconstruction does). z of
    α and ρs: SD within 0.75–1.35 with the standard's lags in σ, above 1.8 with the per-value share alone (as
    reported before)."""
    import dataclasses

    import wardjax as wj
    from wardjax.effects import ScanlineModel
    from wardjax.effects._capture import capture_data
    from wardjax.effects._discover import _baseline
    from wardjax.effects._standard_noise import bin_lag_correlation
    from wardjax.effects._standard_sigma import with_standard

    p = wj.WardParams(rho_d=(0.03,) * 3, rho_s=0.35, alpha_x=0.08, alpha_y=0.08)
    cap = wj.simulate_capture(p, tmp_path / "metal", seed=1, texture="none", image_size=(160, 120))
    data = capture_data(cap, max_samples=6000)
    assert data.standard is not None
    c, R, cols = data.standard  # c (S, N, C): at each value's mirror point
    b = next(bb for bb in (1, 2, 3, 4) if bin_lag_correlation(1.5, bb).shape == R.shape)
    search, ref, _ = _baseline(ScanlineModel(cap.config.fit.normalization), data, (), 20, 64, False)
    f, mask = np.asarray(ref.pred), np.asarray(data.mask)
    lag = R.shape[0] // 2
    probe_sd = np.sqrt(np.maximum(np.asarray(data.sigma) ** 2 - c * R[lag, lag] * f**2, 0.0))
    rng = np.random.default_rng(7)
    z = {"plain": [], "lags": []}
    for _ in range(40):
        unit = [_smoothed_binned(rng, (int(cols.max()) + 1, f.shape[1]), b, 1.5, 1.0, cols) for _ in range(c.shape[-1])]
        eps = np.stack(unit, -1) * np.sqrt(c)
        y = f * (1.0 + eps) + rng.normal(0.0, 1.0, f.shape) * probe_sd
        sib = search.sibling(dataclasses.replace(data, y=np.where(mask, y, 0.0)))
        st = sib.state_of(sib.fit([(ref.state.u, list(search.layout.slices["model"]), ())])[0], ())
        wide = with_standard(sib, st)
        for name in ("alpha", "rho_s"):
            d = st.values["model"][name] - ref.state.values["model"][name]
            z["plain"].append(d / st.sigma["model"][name])
            z["lags"].append(d / wide.sigma["model"][name])
    assert 0.75 < np.std(z["lags"]) < 1.35
    assert np.std(z["plain"]) > 1.8


def _whitened_search(rng, names=("anisotropy", "offset")):
    """A :class:`~wardjax.effects._search._Search` over Ward scanlines (ρd 0.1, ρs 0.2, α 0.1, a little noise)
    whitened by a random lower-triangular ``W`` ``(S, C N, C N)``, with the effects ``names`` testable."""
    import dataclasses

    from wardjax.effects import ScanlineModel, scanline_data
    from wardjax.effects._library import library
    from wardjax.effects._search import _Search

    s_n, n, c_n = 4, 12, 3
    ang = np.linspace(0.1, 0.7, n)
    tilt = np.linspace(-0.2, 0.2, s_n)[:, None]
    wi = np.stack([np.broadcast_to(tilt, (s_n, n)), np.broadcast_to(np.sin(ang), (s_n, n)), np.ones((s_n, n))], -1)
    wo = wi * np.array([1.0, -1.0, 1.0])
    wi, wo = (v / np.linalg.norm(v, axis=-1, keepdims=True) for v in (wi, wo))
    y = 0.1 / np.pi + 0.2 * np.exp(-((np.arange(n) - n / 2) ** 2) / 8.0)[None, :, None] * np.ones((s_n, 1, c_n))
    y = y + 0.01 * rng.normal(size=y.shape)
    m = c_n * n
    W = np.tril(rng.normal(size=(s_n, m, m))) * 0.1 + np.eye(m)
    data = dataclasses.replace(scanline_data(y, wi, wo, np.full(y.shape, 0.01)), whiten=W)
    model = ScanlineModel()
    testable = tuple(e for e in library("scanline") if e.name in names)
    return _Search(model, data, testable, 20, 64)


def test_standard_jacobian_by_differences_is_the_autodiff_jacobian(rng):
    """The sandwich's ``Wᵀ ∂r/∂u`` (forward differences through the residual view's program, ``Wᵀ`` in NumPy)
    against forward-mode autodiff of the whitened residuals with ``Wᵀ`` taken column by column, at a state with an
    effect switched on; ``whitened_jacobian`` is the same without ``Wᵀ``."""
    import jax
    import jax.numpy as jnp

    from wardjax.effects._solve import _data_residuals
    from wardjax.effects._standard_sigma import jacobian_at, whitened_jacobian

    search = _whitened_search(rng)
    lay = search.layout
    u = lay.u_initial() + 0.05 * rng.normal(size=lay.size + 1)
    free = tuple(lay.slices["model"] + lay.slices["anisotropy"])
    act = (0,)
    got = jacobian_at(search, u, free, act)
    raw = whitened_jacobian(search, u, free, act)
    W, shape = np.asarray(search.data.whiten), np.shape(search.data.y)
    s_n, n, c_n = shape
    flags = jnp.asarray([i in act for i in range(len(search.testable))])
    idx = jnp.asarray(free)
    with jax.enable_x64(True):
        ctx = search.model.context(search.data_dev) if hasattr(search.model, "context") else None
        args = (jnp.asarray(u), idx, jnp.ones(len(free), bool), flags, search.data_dev, ctx)

        def resid(z):
            r = _data_residuals(z, args, model=search.model, effects=search.testable, layout_key=lay.key)
            return r[: s_n * n * c_n]

        ref = np.asarray(jax.jacfwd(resid)(jnp.asarray(u)[idx])).reshape(*shape, len(free))
    # the differences' rounding is ~ε|r|/h, the same in every column: compared against the largest entry
    assert np.all(np.max(np.abs(ref), axis=(0, 1, 2)) > 0)
    np.testing.assert_allclose(raw, ref, rtol=0, atol=1e-6 * np.max(np.abs(ref)))
    for k in range(len(free)):
        col = ref[..., k].transpose(0, 2, 1).reshape(s_n, c_n * n)
        want = np.einsum("sji,sj->si", W, col).reshape(s_n, c_n, n).transpose(0, 2, 1)
        np.testing.assert_allclose(got[..., k], want, rtol=0, atol=1e-6 * np.max(np.abs(ref)) * np.abs(W).sum(1).max())
    assert got.shape == raw.shape == (*shape, len(free))
