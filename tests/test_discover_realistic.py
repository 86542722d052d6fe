"""discover on realistic captures: the stop rule once the gap is noise, the texture's Gaussian-process term."""

import math

import numpy as np
import pytest

import wardjax as wj
from wardjax.effects import ScanlineModel, discover
from wardjax.effects._texture import estimate_texture, texture_whitening


def _ar1(rng, shape, rho):
    """Unit-variance AR(1) series along axis 1 (an exponential autocovariance ρ^|k|)."""
    s, n = shape
    x = np.empty(shape)
    x[:, 0] = rng.standard_normal(s)
    for i in range(1, n):
        x[:, i] = rho * x[:, i - 1] + math.sqrt(1 - rho**2) * rng.standard_normal(s)
    return x


def test_texture_and_noise_separated_from_second_differences():
    """White noise whose variance grows with the level plus an AR(1) texture: the lag regression recovers the
    noise coefficients, the texture variance and its correlation, which the lag-1 estimate lumps together."""
    rng = np.random.default_rng(0)
    s, n = 200, 128
    level = 0.2 + 0.1 * np.sin(np.linspace(0, 3, n))[None, :, None] * np.ones((s, 1, 1))
    sig2 = 1e-6 + 4e-5 * level  # read floor + shot noise
    tex_sd, rho = 0.01, 0.8
    e = tex_sd * _ar1(rng, (s, n), rho)[..., None] + np.sqrt(sig2) * rng.standard_normal((s, n, 1))
    fit = estimate_texture(e, level, np.ones(e.shape, bool))
    assert fit.significant()[0]
    assert abs(math.sqrt(fit.T[0]) / tex_sd - 1) < 0.1
    assert abs(fit.rho[0] - rho) < 0.06
    est = fit.sigma(level) ** 2
    assert np.all(np.abs(est / sig2 - 1) < 0.25)
    # whitened with the estimate, the residuals are white with unit variance
    W = texture_whitening(fit, np.sqrt(est), np.ones(e.shape, bool))
    z = np.einsum("scij,sjc->sic", W, e / np.sqrt(est))
    assert abs(np.mean(z**2) - 1) < 0.05
    lag1 = np.mean(z[:, 1:] * z[:, :-1])
    assert abs(lag1) < 0.03


def test_white_noise_reads_no_texture():
    rng = np.random.default_rng(1)
    e = 0.003 * rng.standard_normal((100, 96, 3))
    fit = estimate_texture(e, np.full(e.shape, 0.2), np.ones(e.shape, bool))
    assert not fit.significant().any()


@pytest.mark.slow  # a whole discovery on a capture: minutes on two cores
def test_no_effect_added_once_the_gap_is_within_noise(tmp_path):
    """Saturated highlight: once saturation has closed the gap to within 2√(2 dof) of the noise, nothing else
    is added and the report says so."""
    from wardjax.effects._capture import capture_data

    p = wj.WardParams(rho_d=(0.35, 0.4, 0.45), rho_s=0.02, alpha_x=0.06, alpha_y=0.06)
    cap = wj.simulate_capture(p, tmp_path / "clip", seed=5, image_size=(96, 72), texture="none", headroom=1.4)
    d = capture_data(cap)
    rep = discover(ScanlineModel(), d, keep_plot_data=False)
    assert rep.found == ["saturation"]
    assert rep.within_noise and "nothing further needed" in rep.verdict()
    st = rep.final
    assert st.chi2 - st.dof <= 2 * math.sqrt(2 * st.dof)
    assert rep.to_dict()["verdict"] == rep.verdict()


def test_long_range_texture_read_from_what_is_left_about_each_scanline_mean():
    """A texture correlated over the whole scanline (ρ = 0.995 per sample, like the simulated wood) whose
    per-scanline mean the ρd fit has taken out: the short lags see only ``T (1 − ρ)``, so the estimate must also
    reproduce the variance left about each scanline's mean (the lag-0 row), not grow ``T`` without bound."""
    from wardjax.effects._texture import _g0

    rng = np.random.default_rng(2)
    s, n = 60, 98
    level = np.full((s, n, 1), 0.2)
    e = 0.04 * _ar1(rng, (s, n), 0.995)[..., None] + 0.002 * rng.standard_normal((s, n, 1))
    e -= e.mean(1, keepdims=True)  # what one ρd per scanline leaves
    fit = estimate_texture(e, level, np.ones(e.shape, bool))
    assert fit.significant()[0]
    implied = fit.T[0] * np.mean(_g0(e[..., 0], float(fit.rho[0]))) + np.mean(fit.sigma(level) ** 2)
    measured = np.mean(e**2)
    assert abs(implied / measured - 1) < 0.15


@pytest.mark.slow  # two discoveries on a textured capture: minutes on two cores
@pytest.mark.parametrize("offset, named", [(0.0, []), (0.01, ["ambient"])])
def test_textured_capture_offset_named_untouched_not(tmp_path, offset, named):
    """A wood-textured capture ``simulate_capture`` wrote, its lit frame's linear values raised by ``offset``
    (edited through the image codec, nothing of ``wardjax.effects``): with the texture carried, the untouched
    capture names nothing and the offset is named ``ambient`` — the texture does not absorb it."""
    import tomllib

    from wardjax._files import decode_image, encode_image, read_image, write_image
    from wardjax.effects._capture import capture_data

    p = wj.WardParams(rho_d=(0.6, 0.5, 0.4), rho_s=0.04, alpha_x=0.12, alpha_y=0.12)
    folder = tmp_path / "wood"
    wj.simulate_capture(p, folder, seed=0, image_size=(160, 120), texture="wood")
    if offset:
        cfg = tomllib.loads((folder / "capture.toml").read_text())
        enc, bits = cfg["images"]["encoding"], int(cfg["images"]["bit_depth"])
        lit = folder / cfg["images"]["lit"]
        v = decode_image(read_image(lit), enc, bits).astype(np.float64) + offset
        write_image(lit, encode_image(np.clip(v, 0.0, 1.0), enc, bits))
    cap = wj.load_capture(folder)
    rep = discover(ScanlineModel(cap.config.fit.normalization), capture_data(cap), keep_plot_data=False, texture=True)
    assert rep.settings["texture"] is not None
    assert rep.found == named
