"""The discrepancy term (``wardjax.effects._discrepancy``): drawn as it assumes — a level per quantile bin of the
half-vector angle, ``N(0, τ²)`` in units of the noise σ (independent, or correlated between neighbouring bins),
added to Ward scanlines — its τ and correlation length are read back, and the parameters' σ with it cover the
truth where the fit's own σ do not."""

import numpy as np

import wardjax as wj
from wardjax.effects import ScanlineModel, _discrepancy, discover, scanline_data
from wardjax.effects._discrepancy import bin_correlation

TRUTH = {"rho_s": 0.06, "alpha": 0.09}


def _case(seed: int, tau: float, length: float = 0.0):
    params = wj.WardParams(rho_d=(0.2, 0.3, 0.5), rho_s=TRUTH["rho_s"], alpha_x=TRUTH["alpha"], alpha_y=TRUTH["alpha"])
    sim = wj.simulate_scanlines(params, x_offsets=np.linspace(-20, 20, 12), n_samples=64, noise_rel=0.0, seed=seed)
    rng = np.random.default_rng(seed)
    f = np.asarray(sim.f_true)
    sigma = 0.01 * f + 1e-4
    h = np.asarray(sim.wi) + np.asarray(sim.wo)
    theta_h = np.degrees(np.arctan2(np.hypot(h[..., 0], h[..., 1]), h[..., 2]))  # (S, N), the verdict's covariate
    edges = np.quantile(theta_h, np.linspace(0, 1, 21))
    b = np.clip(np.searchsorted(edges, theta_h, side="right") - 1, 0, 19)
    levels = tau * np.linalg.cholesky(bin_correlation(20, length) + 1e-9 * np.eye(20)) @ rng.standard_normal(20)
    delta = levels[b][..., None]  # the same level on every channel of a bin
    y = f + sigma * (delta + rng.standard_normal(f.shape))
    return scanline_data(y, sim.wi, sim.wo, sigma, points=sim.points, rho_standard=0.99), levels


def test_the_discrepancy_is_read_back_and_covers_the_truth():
    """Eight draws at τ = 3 (in noise σ): on each τ̂ is the SD of the 20 levels drawn within 15 %, on the covariate
    they were drawn along; z against the truth with the discrepancy's σ within ±4 on every draw, where the fit's
    own σ leave some beyond ±6 (the bins' levels move ρs and α by many of their σ)."""
    z_with, z_without = [], []
    for seed in range(8):
        data, levels = _case(seed, 3.0)
        rep = discover(ScanlineModel(), data, effects=(), max_steps=0)
        d = rep.discrepancy
        assert d is not None and rep.unexplained, (rep.gap, rep.unexplained)
        read = d["readings"]["theta_h"]
        assert abs(read["tau"] / np.std(levels) - 1) < 0.15, (read, np.std(levels))
        assert d["readings"][d["covariate"]]["widen"] == max(v["widen"] for v in d["readings"].values())
        av = rep.averaged
        for k, truth in TRUTH.items():
            v = av[k]
            assert abs(v["sigma"] ** 2 / (v["sigma_model"] ** 2 + v["sigma_discrepancy"] ** 2) - 1) < 1e-12
            z_with.append((v["value"] - truth) / v["sigma"])
            z_without.append((v["value"] - truth) / v["sigma_model"])
    d = rep.to_dict()
    assert "theta_h" in d["discrepancy"]["readings"] and d["averaged"]["rho_s"]["sigma_discrepancy"] > 0
    assert f"The parameters' σ include the discrepancy (a level per bin of {d['discrepancy']['covariate']}" in (
        rep.to_markdown()
    )
    assert np.max(np.abs(z_with)) < 4, z_with
    assert np.max(np.abs(z_without)) > 6, z_without


def test_levels_correlated_between_bins_are_read_so_and_covered(monkeypatch):
    """Levels drawn correlated between neighbouring bins (a squared-exponential prior over the bins' ranks,
    length 1/8): the most likely length is read back on at least 6 of 8 draws, and with it z against the truth
    stays within ±4, where independent levels (the term read with length 0 only) leave some beyond ±6 — a smooth
    discrepancy lies largely along the parameters, which independent levels give only the visible part's size."""

    def zs():
        out, lengths = [], []
        for seed in range(8):
            rep = discover(ScanlineModel(), _case(seed, 3.0, 1 / 8)[0], effects=(), max_steps=0)
            assert rep.discrepancy is not None
            lengths.append(rep.discrepancy["readings"]["theta_h"]["length"])
            out += [(rep.averaged[k]["value"] - t) / rep.averaged[k]["sigma"] for k, t in TRUTH.items()]
        return np.abs(out), lengths

    z, lengths = zs()
    assert sum(ell == 1 / 8 for ell in lengths) >= 6, lengths
    assert z.max() < 4, z
    monkeypatch.setattr(_discrepancy, "LENGTHS", (0.0,))
    z_iid, lengths = zs()
    assert set(lengths) == {0.0} and z_iid.max() > 6, z_iid


def test_no_discrepancy_where_the_gap_is_within_the_noise():
    rep = discover(ScanlineModel(), _case(0, 0.0)[0], effects=(), max_steps=0)
    assert rep.discrepancy is None and not rep.unexplained, rep.gap
    assert all(v["sigma_discrepancy"] == 0.0 for v in rep.averaged.values())
    assert rep.to_dict()["discrepancy"] is None and "include the discrepancy" not in rep.to_markdown()
