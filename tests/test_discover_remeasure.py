"""The texture's covariance measured again once an effect is named (wardjax.effects._remeasure)."""

import math

import numpy as np
import pytest
from scipy.ndimage import gaussian_filter1d

import wardjax as wj
from wardjax.effects import scanline_data
from wardjax.effects._texture_term import with_texture


def _gap(data) -> float:
    """χ²/dof of ``data`` whitened by its covariance, a constant per scanline and channel profiled (as ρd is)."""
    s_n, n, c_n = np.shape(data.y)
    e = (np.asarray(data.y) / np.asarray(data.sigma)).transpose(0, 2, 1).reshape(s_n, c_n * n)
    A = np.kron(np.eye(c_n), np.ones((n, 1))) / np.asarray(data.sigma).transpose(0, 2, 1).reshape(s_n, c_n * n, 1)
    W = np.broadcast_to(np.eye(c_n * n), (s_n, c_n * n, c_n * n)) if data.whiten is None else np.asarray(data.whiten)
    chi2 = 0.0
    for s in range(s_n):
        we, wa = W[s] @ e[s], W[s] @ A[s]
        r = we - wa @ np.linalg.lstsq(wa, we, rcond=None)[0]
        chi2 += float(r @ r)
    return chi2 / (s_n * (c_n * n - c_n))


def test_known_texture_carries_the_noise_correlation_second_differences_undercount():
    """Noise with a short-range correlated share (a smoothed standard's, 10 % of the variance, correlation 0.9
    at lag 1) read by its second differences, as the capture's white-noise estimate reads it: the white σ reads
    the true residuals several percent high in χ². Carried as the known texture's covariance, measured on the
    same residuals, they read 1 within a few percent (a little under: a covariance measured on the residuals
    it whitens, its noisy eigenvalues clipped at 0, fits some of them)."""
    rng = np.random.default_rng(3)
    s_n, n, c_n = 40, 48, 3
    white = 0.002 * rng.standard_normal((s_n, n, c_n))
    corr = gaussian_filter1d(rng.standard_normal((s_n, n + 16, c_n)), 1.5, axis=1)[:, 8:-8]
    corr *= 0.002 * math.sqrt(0.1 / 0.9) / corr.std()
    y = 0.2 + white + corr
    d2 = np.mean((y[:, :-2] - 2 * y[:, 1:-1] + y[:, 2:]) ** 2, axis=(0, 1)) / 6.0  # the second-difference read
    sigma = np.broadcast_to(np.sqrt(d2), y.shape)
    ang = np.linspace(0.2, 0.8, n)
    wi = np.stack([np.zeros_like(ang), np.sin(ang), np.cos(ang)], -1)
    wo = np.stack([np.zeros_like(ang), -np.sin(ang), np.cos(ang)], -1)
    wi, wo = np.broadcast_to(wi, (s_n, n, 3)), np.broadcast_to(wo, (s_n, n, 3))
    data = scanline_data(y, wi, wo, sigma)
    pred = np.full(y.shape, 0.2)
    assert _gap(data) > 1.05  # the white σ alone
    got = with_texture(data, pred, significant=True)
    assert got is not None
    assert 0.95 < _gap(got[0]) < 1.01


@pytest.mark.slow  # a whole discovery on a 160 × 120 capture: minutes on two cores
def test_gap_after_the_true_effect_returns_to_the_noise_band(tmp_path):
    """Table 1's desk (αx 0.137, αy 0.15), untextured: anisotropy is the one effect present. Measured on the
    baseline's residuals, its signal was carried as 'texture' and the gap after it fell to 0.88–0.89, below
    the band 1 ± 2√(2/dof); measured on the residuals of the model with it, the gap after is no longer below
    the band (1.026 here, 2.2 SD above 1: the fit's bias on ρs and α, below) and the baseline reads above it."""
    from wardjax._data import table1_materials
    from wardjax.effects import ScanlineModel, discover
    from wardjax.effects._capture import capture_data

    p = table1_materials()["desk"]
    cap = wj.simulate_capture(p, tmp_path / "desk", seed=1, image_size=(160, 120), texture="none")
    rep = discover(ScanlineModel(cap.config.fit.normalization), capture_data(cap, max_samples=6000), texture=True)
    assert rep.found == ["anisotropy"]
    dof = rep.final.dof
    sd = math.sqrt(2.0 / dof)
    assert 1.0 - 2.0 * sd <= rep.gap[-1] <= 1.0 + 3.0 * sd
    assert rep.gap[0] > 1.0 + 2.0 * sd  # the baseline, under the same covariance
    assert rep.verdict().startswith("found anisotropy")
