"""α by inverting the physical threshold model, with the model's own uncertainty in the posterior.

Simulated observers are drawn from known α through :func:`threshold_ppb` itself, with the
CSF perturbed by its leave-one-out scatter on castleCSF data (not the tabulated, linearised
error the sampler uses), so coverage checks the approximation as well as the sampler.
"""

import numpy as np
import pytest

from wardjax.smartphone import (
    AlphaModel,
    alpha_posterior_physical,
    csf_cv_scatter,
    load_table1,
    physical_lines,
    threshold_ppb,
)
from wardjax.smartphone._alpha_physical import _sd_per_alpha


@pytest.fixture(scope="module")
def model():
    return AlphaModel.from_calibration()


def _simulate(model, alpha, rho_d, n_obs, rng):
    """Observers' whole-pixel thresholds for a surface of known α, through the physical model."""
    s = np.log(10.0) * csf_cv_scatter("Barten 1999", "gratings")
    sd = alpha * _sd_per_alpha(model, rho_d)
    t = float(threshold_ppb(sd, rho_d, sensitivity_scale=float(np.exp(s * rng.standard_normal()))))
    sigma = np.exp(model.log_sigma_obs_prior[0] + model.log_sigma_obs_prior[1] * rng.standard_normal())
    k = np.round(t * np.exp(sigma * rng.standard_normal(n_obs)))
    return np.clip(k, model.display.ppb_min, model.display.ppb_max).astype(int)


def test_csf_out_of_sample_scatter_exceeds_in_sample_fit():
    # leave-one-out on castleCSF data is larger than the in-sample RMS, and ≤ 0.2 log10 for Barten
    for calibration, in_sample in (("gratings", 0.147), ("modelfest", 0.113)):
        cv = csf_cv_scatter("Barten 1999", calibration)
        assert in_sample < cv < 0.2


@pytest.mark.slow
def test_known_alpha_inside_95_interval(model):
    rng = np.random.default_rng(2024)
    hits = []
    for seed in range(12):
        alpha = float(np.exp(rng.uniform(np.log(0.003), np.log(0.1))))
        rho = float(rng.uniform(0.05, 0.85))
        k = _simulate(model, alpha, rho, 3, rng)
        post = alpha_posterior_physical(model, ppb=k, rho_d=rho, seed=seed)
        lo, hi = post.interval(0.95)
        hits.append(lo <= alpha <= hi)
    assert np.mean(hits) >= 10 / 12, hits


def test_model_uncertainty_widens_the_interval(model):
    # many observers: the observer noise averages down and the model error shows
    rng = np.random.default_rng(7)
    k = _simulate(model, 0.02, 0.4, 40, rng)
    width = {}
    for err in (False, True, 0.155):
        lo, hi = alpha_posterior_physical(model, ppb=k, rho_d=0.4, seed=3, model_error=err).interval(0.95)
        width[err] = np.log(hi / lo)
    assert width[False] < width[True] < width[0.155]
    assert width[True] > 1.05 * width[False]


def test_lines_and_physics_overlap_on_a_table1b_cell(model):
    t = load_table1()
    i, j = 1, 2  # NCS 2500, gloss 50
    rho, ppb = float(t["rho_d"][i]), float(t["ppb"][i, j])
    lines = model.posterior(ppb_mean=ppb, n_observers=3, rho_d=rho, seed=0).interval(0.95)
    phys = alpha_posterior_physical(model, ppb_mean=ppb, n_observers=3, rho_d=rho, seed=0).interval(0.95)
    assert phys[0] < lines[1] and lines[0] < phys[1], (lines, phys)
    # and the physics interval holds the α of Table 1a's measured lobe SD on the same scale
    alpha_meas = t["lobe_sd_deg"][i, j] * physical_lines().sd_to_alpha[i]
    assert phys[0] < alpha_meas < phys[1]


def test_bad_model_error_refused(model):
    with pytest.raises(ValueError, match="model_error"):
        alpha_posterior_physical(model, ppb=[10], rho_d=0.5, seed=0, model_error=-1.0)
    with pytest.raises(ValueError, match="not both"):
        alpha_posterior_physical(model, ppb=[10], ppb_mean=10.0, n_observers=2, rho_d=0.5, seed=0)
