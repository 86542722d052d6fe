"""The effect library: absent values leave the model alone, hooks against independent references,
measurement inverses, symmetry cancellation, bad inputs."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import wardjax as wj
from benchmarks import hidden_effects as bench
from wardjax.effects import LIBRARY, ScanlineModel, get_effect, library, scanline_data


@pytest.fixture(scope="module")
def small():
    return bench.simulate_case(None, 5, n_scanlines=3, n_samples=64)


def _vals(effects, model, data, **over):
    v = {"model": {"rho_s": 0.05, "alpha": 0.12}}
    for e in effects:
        v[e.name] = {p.name: (p.init if np.isnan(p.absent) else p.absent) for p in e.params}
    for k, d in over.items():
        v.setdefault(k, {}).update(d)
    return v


def test_library_covers_the_issue():
    names = {e.name for e in LIBRARY}
    for n in (
        "saturation",
        "ambient",
        "gamma",
        "illumination_gradient",
        "directional_emission",
        "fresnel",
        "anisotropy",
        "second_lobe",
        "coloured_specular",
        "retroreflection",
        "contrast_gloss",
    ):
        assert n in names
    assert {e.name for e in library("threshold")} == {"contrast_gloss", "lobe_floor", "ppb_curvature"}
    for e in LIBRARY:
        assert e.title and e.covariate and e.__doc__ and len(e.__doc__) > 200, e.name
    with pytest.raises(ValueError, match="no effect named 'nope'"):
        get_effect("nope")
    with pytest.raises(ValueError, match="model must be"):
        library("brdf")


def test_absent_effects_are_the_identity(small):
    """With every effect at its absent value the prediction equals the plain Ward prediction."""
    m = ScanlineModel()
    d = small.data
    effs = tuple(e for e in library("scanline") if e.applicable(d) is None)
    assert len(effs) >= 8
    with jax.enable_x64(True):
        act_off = {e.name: jnp.asarray(False) for e in effs}
        act_on = {e.name: jnp.asarray(e.name != "saturation") for e in effs}
        f_all, rho_all, _ = m.predict(_vals(effs, m, d), act_on, effs, d)
        f_none, rho_none, _ = m.predict({"model": {"rho_s": 0.05, "alpha": 0.12}}, {}, (), d)
        f_all, f_none = np.asarray(f_all), np.asarray(f_none)
    np.testing.assert_allclose(f_all, f_none, rtol=1e-12)
    # ... and the plain prediction is wardjax.ward_brdf with the profiled ρd
    with jax.enable_x64(True):
        ref = np.asarray(
            wj.ward_brdf(
                wj.WardParams(jnp.asarray(np.asarray(rho_none)), 0.05, 0.12, 0.12), jnp.asarray(d.wi), jnp.asarray(d.wo)
            )
        )
    np.testing.assert_allclose(f_none, ref, rtol=1e-12)
    del act_off


def test_anisotropy_hook_matches_rotated_ward(small):
    """The rotated anisotropic lobe equals ward_brdf evaluated in the turned tangent frame."""
    m, d = ScanlineModel(), small.data
    e = get_effect("anisotropy")
    eta, phi = 0.3, 0.7
    with jax.enable_x64(True):
        f, rho, _ = m.predict(
            {"model": {"rho_s": 0.05, "alpha": 0.12}, "anisotropy": {"eta": eta, "phi": phi}},
            {"anisotropy": jnp.asarray(True)},
            (e,),
            d,
        )
        c, s = np.cos(phi), np.sin(phi)

        def rot(w):
            w = np.asarray(w)
            return np.stack([c * w[..., 0] + s * w[..., 1], -s * w[..., 0] + c * w[..., 1], w[..., 2]], -1)

        p = wj.WardParams(jnp.asarray(np.asarray(rho)), 0.05, 0.12 * np.exp(eta), 0.12 * np.exp(-eta))
        ref = np.asarray(wj.ward_brdf(p, jnp.asarray(rot(d.wi)), jnp.asarray(rot(d.wo))))
    np.testing.assert_allclose(np.asarray(f), ref, rtol=1e-10)


@pytest.mark.parametrize(
    "name,v",
    [
        ("ambient", {"a": 0.03}),
        ("ambient", {"a": -0.01}),
        ("gamma", {"eps": 0.2}),
        ("gamma", {"eps": -0.1}),
        ("illumination_gradient", {"b": 0.4, "b_st": 0.3}),
    ],
)
def test_measurement_inverse(small, name, v):
    """unmeasure(measure(f)) = f, and its derivative is the inverse of the forward derivative."""
    m, d = ScanlineModel(), small.data
    e = get_effect(name)
    with jax.enable_x64(True):
        ctx = m.context(d)
        f = jnp.asarray(np.asarray(d.y))
        y = e.measure(v, f, ctx)
        back, dfdy = e.unmeasure(v, y, ctx)
        dydf = jax.jvp(lambda ff: e.measure(v, ff, ctx), (f,), (jnp.ones_like(f),))[1]
    np.testing.assert_allclose(np.asarray(back), np.asarray(f), rtol=1e-10, atol=1e-14)
    np.testing.assert_allclose(np.asarray(dfdy) * np.asarray(dydf), 1.0, rtol=1e-9)


def test_gamma_is_the_ratio_of_decoded_values():
    """A γ mismatch on probe and standard gives f_std (f/f_std)^(1+ε): the exposure cancels."""
    e = get_effect("gamma")
    f, fs, eps, k = np.array([0.02, 0.3, 2.0]), 0.99 / np.pi, 0.15, 0.37
    ratio = (k * f) ** (1 + eps) / (k * fs) ** (1 + eps) * fs
    with jax.enable_x64(True):
        got = np.asarray(e.measure({"eps": eps}, jnp.asarray(f), {"f_std": fs}))
    np.testing.assert_allclose(got, ratio, rtol=1e-12)


@pytest.mark.parametrize("hidden", ["symmetric_falloff", "directional_emission"])
def test_symmetric_effects_cancel_from_the_ratio(hidden):
    """Simulated on probe and standard, they leave v/v_std unchanged, and the library says so."""
    c0 = bench.simulate_case(None, 11, n_scanlines=3, n_samples=64)
    c1 = bench.simulate_case(hidden, 11, n_scanlines=3, n_samples=64)
    np.testing.assert_allclose(np.asarray(c1.data.y), np.asarray(c0.data.y), rtol=1e-12)
    why = get_effect(hidden).applicable(c1.data)
    assert why is not None and "cancels" in why


def test_saturation_applies_only_to_a_plateau(small):
    assert "plateau" in get_effect("saturation").applicable(small.data)
    sat = bench.simulate_case("saturation", 5, n_scanlines=3, n_samples=64)
    assert get_effect("saturation").applicable(sat.data) is None


def test_bench_strength_is_in_range():
    for h in ("gamma", "anisotropy", "fresnel"):
        c = bench.simulate_case(h, 3, n_scanlines=3, n_samples=64)
        assert 3.0 <= c.strength_sigma <= 10.0


def test_scanline_data_rejects_bad_input():
    f = np.ones((2, 5, 3))
    w = np.tile([0.0, 0.0, 1.0], (2, 5, 1))
    with pytest.raises(ValueError, match=r"wi must have shape \(2, 5, 3\)"):
        scanline_data(f, w[:, :4], w, 0.01)
    with pytest.raises(ValueError, match="f_r must have shape"):
        scanline_data(np.ones(5), w, w, 0.01)
    with pytest.raises(ValueError, match="no usable observation"):
        scanline_data(f * np.nan, w, w, 0.01)
    with pytest.raises(ValueError, match="kind must be"):
        scanline_data(f, w, w, 0.01, kind="radiance")
    with pytest.raises(ValueError, match="sigma must be > 0"):
        wj.effects.threshold_data([1, 2], [1, 2], [0, 1], [0.1, 0.2])


def test_capture_noise_estimate_ignores_the_signal_gradient():
    """Second-difference pseudo-residuals recover a heteroscedastic σ under a steep, curved signal
    (first differences counted the gradient as noise: σ ≈ 1.4× too large on a clean capture)."""
    from wardjax.effects._capture import _noise_model

    rng = np.random.default_rng(0)
    t = np.linspace(-1.0, 1.0, 200)
    truth = 0.15 + 0.3 * np.exp(-0.5 * (t / 0.3) ** 2) + 0.05 * t  # diffuse, a highlight, a gradient
    f0 = np.broadcast_to(truth[None, :, None] * np.array([1.0, 0.8, 0.6]), (300, 200, 3))
    sig = np.sqrt(0.002**2 + (0.01 * f0) ** 2)
    f = f0 + sig * rng.standard_normal(f0.shape)
    f[::7, 50] = np.nan  # missing values are skipped
    est = _noise_model(f)
    ratio = np.nanmedian(est / sig, axis=(0, 1))
    np.testing.assert_allclose(ratio, 1.0, atol=0.05)
    ok = np.isfinite(f)
    assert abs(np.mean(((f - f0)[ok] / est[ok]) ** 2) - 1.0) < 0.05


@pytest.mark.slow
def test_flagged_clipped_values_are_censored_not_dropped():
    """Saturated values the sensor flags are fitted with the censored likelihood: without the lamp geometry
    the clip level varies along the scanlines and no plateau of ties shows, yet the flags name it."""
    from wardjax.effects import discover

    case = bench.simulate_case("saturation", 3, n_scanlines=6, n_samples=128)
    d = case.data
    sat = get_effect("saturation")
    with jax.enable_x64(True):  # the values clipped in the simulation (ties of y r²/cos θi)
        flags = np.asarray(sat.censored(True, d))
    assert 50 < flags.sum() < 0.2 * d.n_obs
    y = np.where(np.asarray(d.mask), np.asarray(d.y), np.nan)
    bare = scanline_data(y, d.wi, d.wo, d.sigma, kind="ratio")
    assert "plateau" in sat.applicable(bare)
    flagged = scanline_data(y, d.wi, d.wo, d.sigma, kind="ratio", censored=flags)
    assert sat.applicable(flagged) is None
    rep = discover(ScanlineModel(), flagged, keep_plot_data=False)
    assert rep.found[:1] == ["saturation"] and rep.gap[-1] < 1.1 < rep.gap[0]
    a = rep.final.values["model"]["alpha"]
    assert abs(a / case.truth["alpha"] - 1) < 0.05
    with pytest.raises(ValueError, match="censored must have shape"):
        scanline_data(y, d.wi, d.wo, d.sigma, censored=flags[:, :5])


@pytest.mark.slow
def test_capture_clipped_probe_pixels_are_censored_not_dropped(tmp_path):
    """On a capture whose highlight clips (the standard does not), diagnose's data keep the clipped probe pixels
    as censored lower bounds (they were dropped, so the saturation effect could never apply to a capture), the
    unclipped values are those of the reconstruction unchanged, and discovery names saturation and recovers α."""
    from wardjax.effects import discover
    from wardjax.effects._capture import capture_data
    from wardjax.reconstruct import MIN_SCANLINE_SAMPLES, reconstruct_capture

    p = wj.WardParams(rho_d=(0.35, 0.4, 0.45), rho_s=0.02, alpha_x=0.06, alpha_y=0.06)
    cap = wj.simulate_capture(p, tmp_path / "clip", seed=5, image_size=(96, 72), texture="none", headroom=1.4)
    d = capture_data(cap)  # 96 × 72: b = 1, each value one pixel
    assert d.censored is not None
    cens, m, y = np.asarray(d.censored), np.asarray(d.mask), np.asarray(d.y)
    assert 30 < cens.sum() < 0.05 * d.n_obs
    rec = reconstruct_capture(cap, dtype=np.float64, clip_bounds=True)
    box = np.ix_(rec.probe.any(axis=1), rec.probe.any(axis=0))
    f_img, c_img = (a[box].transpose(1, 0, 2) for a in (rec.f_r, rec.f_clip))  # (columns, rows, 3)
    keep = np.sum(np.all(np.isfinite(f_img), axis=-1), axis=1) >= MIN_SCANLINE_SAMPLES
    f_img, c_img = f_img[keep], c_img[keep]
    np.testing.assert_array_equal(m & ~cens, np.isfinite(f_img))
    np.testing.assert_array_equal(y[m & ~cens], f_img[np.isfinite(f_img)])
    np.testing.assert_array_equal(cens, np.isfinite(c_img))
    np.testing.assert_array_equal(y[cens], c_img[cens])
    # each bound is the clip level: below the true BRDF of its pixel
    with jax.enable_x64(True):
        truth = np.asarray(
            wj.ward_brdf(
                wj.WardParams(jnp.asarray(np.asarray(p.rho_d, float)), 0.02, 0.06, 0.06),
                jnp.asarray(d.wi),
                jnp.asarray(d.wo),
            )
        )
    assert np.all(y[cens] < truth[cens])
    sat = get_effect("saturation")
    assert sat.applicable(d) is None
    rep = discover(ScanlineModel(), d, max_steps=1, keep_plot_data=False)
    assert rep.found == ["saturation"] and rep.gap[1] < 1.1 < rep.gap[0]
    assert abs(rep.final.values["model"]["alpha"] / 0.06 - 1) < 0.03


def test_capture_noise_follows_the_lamp_irradiance():
    """The sensor's read and shot noise divided by the lamp's irradiance, which falls along each scanline: given
    ``w = r²/cos θi`` the second-difference estimate recovers σ at both ends; as a function of the level alone
    it is off by > 25 % at one end (the whitened residuals of a clean capture ran from 0.5 to 2.2 along it)."""
    from wardjax.effects._capture import _noise_model

    rng = np.random.default_rng(1)
    s, n = 300, 120
    t = np.linspace(-1.0, 1.0, n)
    w = np.broadcast_to(np.linspace(0.55, 1.5, n)[None, :], (s, n))
    truth = 0.15 + 0.2 * np.exp(-0.5 * (t / 0.3) ** 2)
    f0 = np.broadcast_to(truth[None, :, None] * np.array([1.0, 0.8, 0.6]), (s, n, 3))
    sig = np.sqrt(1e-6 * w[..., None] ** 2 + 2e-5 * f0 * w[..., None])
    f = f0 + sig * rng.standard_normal(f0.shape)
    est = _noise_model(f, w=w)
    flat = _noise_model(f)
    for sl in (slice(0, 10), slice(n - 10, n)):
        np.testing.assert_allclose(np.median(est[:, sl] / sig[:, sl], axis=(0, 1)), 1.0, atol=0.06)
    assert np.max(np.abs(np.median(flat[:, :10] / sig[:, :10], axis=(0, 1)) - 1.0)) > 0.25


def test_whitened_residuals_take_one_whitening_where_nothing_is_measured(small):
    """With a texture whitening ``L⁻¹`` the residuals with no measurement effect on are computed from one
    whitening (the design whitened once per solve); they must equal generalised least squares done by hand
    with numpy, and the general path (a measurement effect switched on at its absent value, the hook the
    identity) must give the same."""
    m = ScanlineModel()
    d = small.data
    s_n, n, c_n = d.y.shape
    rng = np.random.default_rng(3)
    B = rng.standard_normal((s_n, c_n * n, 12)) * 0.7
    K = np.eye(c_n * n)[None] + B @ B.transpose(0, 2, 1)
    W = np.linalg.inv(np.linalg.cholesky(K))
    import dataclasses

    dw = dataclasses.replace(d, whiten=W)
    effs = tuple(e for e in library("scanline") if e.applicable(d) is None)
    vals = _vals(effs, m, d)
    with jax.enable_x64(True):
        ctx = m.context(dw)
        f_spec = np.asarray(m._parts(vals, effs, dw, ctx, {e.name: False for e in effs}))

        @jax.jit
        def resid(act):
            return m.residuals(vals, act, effs, dw)

        off = {e.name: jnp.asarray(False) for e in effs}
        r_direct = np.asarray(resid(off))
        r_general = np.asarray(resid({**off, "gamma": jnp.asarray(True)}))
        r_static = np.asarray(m.residuals(vals, {e.name: False for e in effs}, effs, dw))
    # by hand: per scanline, L⁻¹ applied to (y − Ward terms)/σ and to 1/σ on each channel, least squares for ρd/π
    y, sg, mk = np.asarray(d.y), np.asarray(d.sigma), np.asarray(d.mask)
    ref = np.zeros((s_n, n, c_n))
    for s in range(s_n):
        u = np.where(mk[s], (y[s] - f_spec[s]) / sg[s], 0.0).T.reshape(-1)
        X = np.zeros((c_n * n, c_n))
        for c in range(c_n):
            X[c * n : (c + 1) * n, c] = np.where(mk[s, :, c], 1.0 / sg[s, :, c], 0.0)
        A, b = W[s] @ X, W[s] @ u
        coef = np.linalg.lstsq(A, b, rcond=None)[0]
        ref[s] = (b - A @ coef).reshape(c_n, n).T
    ref = np.where(mk, ref, 0.0).reshape(-1)
    assert np.max(np.abs(ref)) > 1.0  # the whitening matters: not a trivially small residual
    for r in (r_direct, r_general, r_static):
        np.testing.assert_allclose(r, ref, rtol=1e-8, atol=1e-8 * np.max(np.abs(ref)))


def test_smoothing_factor_is_the_kernels_energy():
    """A Gaussian of σ pixels keeps ``1/(4πσ²)`` of a white noise's variance (its kernel's energy); a ``b × b`` mean
    of the result keeps about ``1/b²`` of that where ``b`` ≪ σ, and ``1/b²`` of the unsmoothed noise at σ → 0."""
    from wardjax.effects._standard_noise import smoothing_factor

    for s in (2.0, 3.0):
        np.testing.assert_allclose(smoothing_factor(s, 1), 1 / (4 * np.pi * s * s), rtol=0.02)
    assert smoothing_factor(3.0, 2) == pytest.approx(smoothing_factor(3.0, 1), rel=0.1)
    np.testing.assert_allclose(smoothing_factor(1e-3, 3), 1 / 9, rtol=1e-6)


def test_capture_noise_counts_the_smoothed_standard(tmp_path, monkeypatch):
    """σ of a capture's BRDF values against the noise itself: the same scene with and without sensor noise
    (16-bit 320 × 240, binned 2 × 2), their difference is the noise the reconstruction carries. With the smoothed
    standard's share ``(Δf/σ)²`` averages 1; the second differences alone miss it (> 1.05)."""
    from wardjax.effects import _capture
    from wardjax.simulate import SensorNoise

    p = wj.WardParams(rho_d=(0.6, 0.5, 0.4), rho_s=0.04, alpha_x=0.12, alpha_y=0.12)
    kw = {"seed": 3, "texture": "none", "bit_depth": 16, "image_size": (320, 240)}
    noisy = wj.simulate_capture(p, tmp_path / "noisy", **kw)
    clean = wj.simulate_capture(p, tmp_path / "clean", noise=SensorNoise(0.0, 0.0), **kw)

    def ratio():
        a, b = _capture.capture_data(noisy, max_samples=6000), _capture.capture_data(clean, max_samples=6000)
        m = np.asarray(a.mask) & np.asarray(b.mask)
        return float(np.mean(((np.asarray(a.y) - np.asarray(b.y))[m] / np.asarray(a.sigma)[m]) ** 2))

    assert 0.94 < ratio() < 1.03
    monkeypatch.setattr(_capture, "standard_noise", lambda cap, points: np.zeros(3))
    assert ratio() > 1.05
