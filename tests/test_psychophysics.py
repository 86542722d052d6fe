"""wardjax.smartphone: PPB↔CPD, gratings, the Table-1 α model, the emcee posterior."""

import imageio.v3 as iio
import numpy as np
import pytest
from click.testing import CliRunner

import wardjax as wj
from wardjax import smartphone as ps
from wardjax.run import main
from wardjax.smartphone._alpha_posterior import _batched, _initial_walkers, _problem_arrays

# ----------------------------------------------------------------------------- geometry


def test_ppb_to_cpd_paper_setup():
    cpd = wj.ppb_to_cpd([1, 120], "iphone5s", "paper")
    assert cpd[0] == pytest.approx(54.3, rel=0.005)  # the paper prints 54.2 in §5
    # 0.4529: within 0.5 % of 0.45 at the printed precision (0.45 ± 0.005 → ±1.1 %)
    assert round(float(cpd[1]), 2) == 0.45 and cpd[1] == pytest.approx(0.45, rel=0.0065)
    np.testing.assert_allclose(wj.cpd_to_ppb(cpd), [1, 120], rtol=1e-12)
    # small-angle check: 1 PPB ≈ 1 / degrees(2 p / D)
    p, d = 25.4 / 326, 19.1 * 25.4
    assert cpd[0] == pytest.approx(1 / np.rad2deg(2 * p / d), rel=1e-6)


def test_other_geometries():
    near = ps.Viewing("near", eye_to_screen_mm=250.0)
    oblique = ps.Viewing("oblique", eye_to_screen_mm=19.1 * 25.4, screen_obliquity_deg=60.0)
    base = wj.ppb_to_cpd(10)
    assert wj.ppb_to_cpd(10, viewing=near) < base  # closer: coarser in angle
    assert wj.ppb_to_cpd(10, viewing=oblique) == pytest.approx(2 * base, rel=1e-3)  # cos 60° foreshortening
    retina = ps.Display("hi", ppi=652.0, width_px=10, height_px=10)
    assert wj.ppb_to_cpd(2, display=retina) == pytest.approx(base * 10, rel=1e-3)  # same period in mm as 1 PPB
    with pytest.raises(ValueError, match="ppb must be > 0"):
        wj.ppb_to_cpd(0)
    with pytest.raises(ValueError, match="display must be one of"):
        wj.ppb_to_cpd(1, display="nokia")


def test_grating_image_and_cli(tmp_path):
    g = ps.grating_image(3, 12, 4)
    assert g.dtype == np.uint8 and g.shape == (4, 12)
    np.testing.assert_array_equal(g[0], [255] * 3 + [0] * 3 + [255] * 3 + [0] * 3)
    res = CliRunner().invoke(main, ["gratings", "--display", "iphone5s", "--out", str(tmp_path / "g")])
    assert res.exit_code == 0, res.output
    files = sorted((tmp_path / "g").glob("grating_*.png"))
    assert len(files) == 120
    im = iio.imread(files[6])  # 7 PPB
    assert im.shape == (1136, 640)
    np.testing.assert_array_equal(im[0, :28], [255] * 7 + [0] * 7 + [255] * 7 + [0] * 7)
    lines = (tmp_path / "g" / "gratings.csv").read_text().splitlines()
    assert lines[1].startswith("grating_001.png,1,54.3")
    bad = CliRunner().invoke(main, ["gratings", "--display", "nokia", "--out", str(tmp_path / "x")])
    assert bad.exit_code == 2 and "display must be one of" in bad.output


# ----------------------------------------------------------------------------- α model


def test_table_1c_reproduced_from_1b():
    t = ps.load_table1()
    am = wj.AlphaModel.from_calibration()
    got = np.array([am.alpha(t["ppb"][i], t["rho_d"][i]) for i in range(4)])
    assert np.max(np.abs(got - t["alpha"])) <= 0.001
    # RGB ρd of a grey goes through the same lightness
    np.testing.assert_allclose(am.alpha(t["ppb"][1], np.full(3, t["rho_d"][1])), got[1], atol=1e-12)


def test_lightness_interpolation_between_anchors():
    am = wj.AlphaModel.from_calibration()
    t = ps.load_table1()
    mid = am.alpha(20, 0.35)
    lo, hi = am.alpha(20, t["rho_d"][2]), am.alpha(20, t["rho_d"][1])
    assert min(lo, hi) <= mid <= max(lo, hi)
    assert am.alpha(20, 0.99) == pytest.approx(am.alpha(20, t["rho_d"][0]))  # held beyond the ends
    np.testing.assert_allclose(am.ppb_for_alpha(am.alpha(37.0, 0.6), 0.6), 37.0)


def test_physical_lines_r2_and_sd_to_alpha_scale():
    phys = ps.physical_lines()
    print(
        "\nPPB→SD lines, gloss 95–30: R² =",
        np.round(phys.r2, 4),
        " SD→α scale (per degree) =",
        np.round(phys.sd_to_alpha, 5),
        " σ_obs (log PPB, per observer) =",
        round(phys.sigma_obs, 3),
    )
    assert np.all(phys.r2 > 0.96)  # the paper's claim
    assert np.all(phys.slope > 0)
    # α per degree of lobe SD: below π/180 (an SD in reflected-angle degrees, not half-angle)
    assert np.all((0.5 * np.pi / 180 < phys.sd_to_alpha) & (phys.sd_to_alpha < np.pi / 180))
    # independent check of one line with numpy.polyfit
    t = ps.load_table1()
    slope, icpt = np.polyfit(t["ppb"][0, :4], t["lobe_sd_deg"][0, :4], 1)
    assert phys.slope[0] == pytest.approx(slope) and phys.intercept[0] == pytest.approx(icpt)


# ----------------------------------------------------------------------------- posterior


def test_jax_log_prob_matches_numpy_reference(rng):
    am = wj.AlphaModel.from_calibration()
    import jax

    for ppb, mean in (([18, 17, 19], None), ([1, 2], None), ([120], None), (None, 17.3)):
        data, hyper = _problem_arrays(am, [None if ppb is None else np.array(ppb, float)], [mean], [3], [0.5])
        theta = _initial_walkers(data, hyper, 16, rng, scale=5.0)
        with jax.enable_x64(True):
            got = np.asarray(_batched(theta, *data, hyper))[0]
        host = tuple(np.asarray(x)[0] for x in data)
        want = ps.log_prob_numpy(theta[0], *host, hyper)
        finite = np.isfinite(want)
        assert finite.sum() > 4
        np.testing.assert_array_equal(np.isfinite(got), finite)
        np.testing.assert_allclose(got[finite], want[finite], rtol=1e-9, atol=1e-9)


def test_posterior_reports_and_agrees_with_point_model():
    am = wj.AlphaModel.from_calibration()
    post = am.posterior(ppb=[18, 17, 19], rho_d=0.8, seed=0)
    print("\n" + post.summary())
    lo95, hi95 = post.interval(0.95)
    lo68, hi68 = post.interval(0.68)
    assert lo95 < lo68 < post.median < hi68 < hi95
    assert lo68 < am.alpha(18, 0.8) < hi68
    assert post.converged and post.n_steps >= 50 * post.tau_max
    assert 0.15 < post.acceptance < 0.7
    assert set(post.params) == {"alpha", "sigma_obs", "ppb_median", "cal_intercept", "cal_slope"}
    assert post.samples.shape == (post.n_steps * post.n_walkers,)
    # the same seed gives the same chain; RGB ρd of a grey is the same surface
    again = am.posterior(ppb=[18, 17, 19], rho_d=(0.8, 0.8, 0.8), seed=0)
    np.testing.assert_allclose(again.samples, post.samples, rtol=1e-12)


def test_posterior_from_a_published_mean_is_wider_than_from_individuals():
    am = wj.AlphaModel.from_calibration()
    ind = am.posterior(ppb=[17, 17, 18], rho_d=0.3, seed=1)
    mean = am.posterior(ppb_mean=17.33, n_observers=3, rho_d=0.3, seed=1)
    one = am.posterior(ppb_mean=17.33, n_observers=1, rho_d=0.3, seed=1)
    assert abs(mean.median - ind.median) < 0.25 * ind.std + 0.002
    width = {k: np.subtract(*p.interval(0.95)[::-1]) for k, p in (("ind", ind), ("mean", mean), ("one", one))}
    assert width["one"] > width["mean"]  # more observers, narrower


def test_posterior_refuses_unconverged_chain():
    am = wj.AlphaModel.from_calibration()
    with pytest.raises(ps.NotConvergedError, match="not converged"):
        am.posterior(ppb=[18], rho_d=0.5, seed=0, burn=50, chunk=100, max_steps=100)


@pytest.mark.parametrize(
    "kwargs, err, message",
    [
        (dict(ppb=[18, -2], rho_d=0.5), ValueError, "grating set 1..120"),
        (dict(ppb=[0], rho_d=0.5), ValueError, "grating set 1..120"),
        (dict(ppb=[17.5], rho_d=0.5), ValueError, "whole pixels"),
        (dict(ppb=[True], rho_d=0.5), TypeError, "integer"),
        (dict(ppb=[], rho_d=0.5), ValueError, "non-empty"),
        (dict(ppb=[18], rho_d=1.5), ValueError, "rho_d must lie in \\[0, 1\\]"),
        (dict(ppb=[18], rho_d=(0.5, 0.5)), ValueError, "scalar or RGB"),
        (dict(ppb=[18], ppb_mean=18.0, n_observers=1, rho_d=0.5), ValueError, "not both"),
        (dict(ppb_mean=18.0, rho_d=0.5), ValueError, "n_observers must be a positive integer"),
        (dict(ppb_mean=18.0, n_observers=2.5, rho_d=0.5), ValueError, "n_observers must be a positive integer"),
        (dict(ppb_mean=-3.0, n_observers=2, rho_d=0.5), ValueError, "ppb_mean must be a positive"),
    ],
)
def test_bad_posterior_inputs(kwargs, err, message):
    am = wj.AlphaModel.from_calibration()
    with pytest.raises(err, match=message):
        am.posterior(seed=0, **kwargs)


# ----------------------------------------------------------------------------- fit_smartphone


def test_fit_smartphone_end_to_end():
    img = np.full((40, 40, 3), (200, 120, 60), np.uint8)
    params, stderr, post = wj.fit_smartphone(img, (5, 35, 5, 35), ppb=[10, 10, 10], seed=0)
    assert isinstance(params, wj.WardParams)
    np.testing.assert_allclose(params.rho_d, wj.diffuse_from_srgb(img, (5, 35, 5, 35)))
    assert float(params.rho_s) == pytest.approx(0.050, abs=5e-4)
    assert float(params.alpha_x) == float(params.alpha_y) == pytest.approx(post.median)
    assert stderr["alpha_x"] == pytest.approx(post.std) and stderr["rho_d"].shape == (3,)
    assert 0 < stderr["rho_s"] < 0.02
    # thresholds from another set-up are mapped at equal cycles/degree: at half the
    # distance, 5 PPB subtends what 10 PPB does in the paper's set-up
    near = ps.Viewing("near", eye_to_screen_mm=19.1 * 25.4 / 2)
    p2, _, _ = wj.fit_smartphone(img, (5, 35, 5, 35), ppb=[5, 5, 5], viewing=near, seed=0)
    assert float(p2.alpha_x) == pytest.approx(float(params.alpha_x), rel=0.15)


# ----------------------------------------------------------------------------- coverage (slow)


@pytest.mark.slow
def test_posterior_coverage_over_2000_simulated_surfaces():
    """Simulation-based calibration: truths drawn from the model's priors (α log-uniform,
    σ_obs, calibration line), 1–3 observers each, integer thresholds; 2000 posteriors in
    four lock-step batches. 95 % intervals must cover 93–97 %, 68 % ones 65–71 %."""
    am = wj.AlphaModel.from_calibration()
    rng = np.random.default_rng(20260401)
    hits95, hits68, n_obs_total = [], [], 0
    for rep in range(4):
        rho = rng.uniform(0.01, 0.9, 500)
        k, truth = ps.simulate_observers(am, rho, 3, rng)
        n_obs = rng.integers(1, 4, 500)
        k[np.arange(3)[None, :] >= n_obs[:, None]] = 0
        n_obs_total += int(n_obs.sum())
        res = am.posterior_batch(k, rho, seed=rep, thin=10)
        assert res.converged.mean() >= 0.99
        for level, hits in ((0.95, hits95), (0.68, hits68)):
            iv = res.interval(level)
            hits += list((truth["alpha"] >= iv[:, 0]) & (truth["alpha"] <= iv[:, 1]))
    c95, c68 = np.mean(hits95), np.mean(hits68)
    print(f"\ncoverage over {len(hits95)} surfaces / {n_obs_total} observers: 95% → {c95:.3f}, 68% → {c68:.3f}")
    assert 0.93 <= c95 <= 0.97
    assert 0.65 <= c68 <= 0.71
