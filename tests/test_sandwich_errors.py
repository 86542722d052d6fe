"""Unweighted fits report the sandwich (heteroscedasticity-consistent) covariance.

The scanlines are drawn by the benchmark's own NumPy code (:func:`benchmarks.bench_fit.draw_scanlines`,
lamp and camera in the plane x = 0, Ward 1992, 1 % multiplicative noise), not by
:mod:`wardjax.simulate`. The reference sandwich is built here in NumPy from the analytic
Jacobian of the full 5-parameter model at the reported optimum.
"""

import numpy as np
import pytest

import wardjax as wj
from benchmarks.bench_fit import draw_scanlines, robust_sd


def _z(res, d):
    ok = res.ok
    za = ((res.params.alpha_x - d.alpha) / res.stderr.alpha_x)[ok]
    zs = ((res.params.rho_s - d.rho_s) / res.stderr.rho_s)[ok]
    return robust_sd(za), robust_sd(zs)


@pytest.mark.parametrize("alpha_range, seed", [((0.01, 0.05), 3), pytest.param((0.03, 0.3), 4, marks=pytest.mark.slow)])
def test_unweighted_errors_are_honest_under_signal_dependent_noise(alpha_range, seed):
    """No weights, noise ∝ signal: default σ gives robust z-SD 0.85–1.2; Gauss–Newton's does not on narrow lobes."""
    d = draw_scanlines(600, alpha_range, seed=seed)
    res = wj.fit_scanlines(d.f_r, d.wi, d.wo)
    assert res.ok.mean() > 0.95
    assert set(np.unique(res.errors[res.ok])) <= {"sandwich", "profile"}
    assert np.mean(res.errors[res.ok] == "sandwich") > 0.9
    sd_a, sd_s = _z(res, d)
    assert 0.85 <= sd_a <= 1.2 and 0.85 <= sd_s <= 1.2, (sd_a, sd_s)
    gn = wj.fit_scanlines(d.f_r, d.wi, d.wo, errors="gauss_newton")
    np.testing.assert_array_equal(gn.params.alpha_x, res.params.alpha_x)  # same optimum, other σ
    assert np.all(gn.errors == "gauss_newton")
    if alpha_range[1] <= 0.05:
        assert min(_z(gn, d)) > 1.5  # one variance for all samples: overconfident on narrow lobes


# 256 samples under the slow mark: the honesty test above checks that path's σ by default (a second compile)
@pytest.mark.parametrize("n", [pytest.param(256, marks=pytest.mark.slow), 9])
def test_sandwich_matches_a_numpy_reference(n):
    """HC0 over 256 samples; HC3 (residuals divided by 1 − leverage) over 9."""
    d = draw_scanlines(8, (0.03, 0.1), seed=5, n=n, span=(3.0, 40.0) if n > 64 else (1.5, 4.0))
    res = wj.fit_scanlines(d.f_r, d.wi, d.wo, errors="auto")
    gn = wj.fit_scanlines(d.f_r, d.wi, d.wo, errors="gauss_newton")
    rows = np.flatnonzero(res.errors == "sandwich")[:4]
    assert rows.size == 4
    for i in rows:
        rd, rs, a = res.params.rho_d[i], res.params.rho_s[i], res.params.alpha_x[i]
        wi, wo = d.wi[i], d.wo[i]
        h = wi + wo
        t = (h[:, 0] ** 2 + h[:, 1] ** 2) / h[:, 2] ** 2
        b = np.exp(-t / a**2) / (4 * np.pi * a**2 * np.sqrt(wi[:, 2] * wo[:, 2]))
        r = d.f_r[i] - (rd[None, :] / np.pi + rs * b[:, None])  # (N, 3)
        jac = np.zeros((len(t), 3, 5))
        for c in range(3):
            jac[:, c, c] = 1 / np.pi
        jac[:, :, 3] = b[:, None]
        jac[:, :, 4] = (rs * b * (2 * t / a**3 - 2 / a))[:, None]
        jac = jac.reshape(-1, 5)
        bread = np.linalg.inv(jac.T @ jac)
        lev = np.einsum("ip,pq,iq->i", jac, bread, jac)  # the hat matrix's diagonal
        assert abs(lev.sum() - 5) < 1e-6  # its trace is the number of parameters
        lev = lev if n <= 64 else np.zeros_like(lev)
        meat = (jac * (r.reshape(-1) / (1 - lev))[:, None] ** 2).T @ jac  # HC3 (HC0 without leverage)
        ref = bread @ meat @ bread
        np.testing.assert_allclose(res.covariance[i], ref, rtol=1e-6, atol=1e-14)
        # and Gauss–Newton's is the same bread times the mean squared residual
        dof = r.size - 5
        np.testing.assert_allclose(gn.covariance[i], bread * np.sum(r**2) / dof, rtol=1e-6, atol=1e-14)


@pytest.mark.slow
def test_few_samples_per_fit_errors_are_honest():
    """9 samples per fit (a pixel in 9 photographs), no weights: the HC3 sandwich keeps z-SD within 0.85–1.15."""
    d = draw_scanlines(3000, (0.03, 0.3), n=9, span=(1.5, 4.0), seed=2)
    res = wj.fit_scanlines(d.f_r, d.wi, d.wo)
    assert res.ok.mean() > 0.95
    sd_a, sd_s = _z(res, d)
    assert 0.85 <= sd_a <= 1.15 and 0.85 <= sd_s <= 1.15, (sd_a, sd_s)


@pytest.mark.slow  # two sample counts, two compiled programs
def test_small_problems_do_not_depend_on_padding():
    """Fits of 9 samples (compiled for 9) equal those of the same samples padded with unusable ones to 12: to
    far below the convergence test's 10⁻³ σ (the sums are vectorised, so their order of addition, and
    their rounding, depends on the padded length)."""
    d = draw_scanlines(40, (0.03, 0.3), n=9, span=(1.5, 4.0), seed=6)
    res = wj.fit_scanlines(d.f_r, d.wi, d.wo)
    pad = lambda a, v: np.concatenate([a, np.full(a.shape[:1] + (3, 3), v)], axis=1)
    padded = wj.fit_scanlines(pad(d.f_r, np.nan), pad(d.wi, np.nan), pad(d.wo, np.nan))
    assert res.ok.mean() > 0.9
    np.testing.assert_array_equal(res.status, padded.status)
    assert np.all(np.abs(padded.params.alpha_x - res.params.alpha_x) <= 1e-5 * res.stderr.alpha_x)
    np.testing.assert_allclose(padded.covariance, res.covariance, rtol=1e-4, atol=1e-14)
