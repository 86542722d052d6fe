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
