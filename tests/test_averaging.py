"""Parameters averaged over the last step's models (``wardjax.effects._averaging``), against the formulas of
Hoeting et al. (1999), eqs. 1–2, written out here: ``μ̄ = Σ w μ``, ``σ̄² = Σ w (σ² + (μ − μ̄)²)``."""

import math
from types import SimpleNamespace as NS

import numpy as np
import pytest

from wardjax.effects._averaging import model_averaged


def _state(rho_s, s_rho, alpha, s_alpha):
    return NS(values={"model": {"rho_s": rho_s, "alpha": alpha}}, sigma={"model": {"rho_s": s_rho, "alpha": s_alpha}})


def _cand(effect, delta_bic, state, physical=True):
    return NS(effect=effect, delta_bic=delta_bic, state=state, physical=physical)


def _bma(models):
    """``(weight, μ, σ)`` triples by the formulas."""
    w = np.array([m[0] for m in models], float)
    w /= w.sum()
    mu, sd = np.array([m[1] for m in models]), np.array([m[2] for m in models])
    m = float(w @ mu)
    return m, math.sqrt(float(w @ (sd**2 + (mu - m) ** 2)))


def test_weights_are_the_evidence_and_the_spread_enters():
    """Model before the step (ΔBIC 0), the winner (ΔBIC 4) and a runner-up (ΔBIC 2): ``exp(ΔBIC/2)`` weights;
    an unphysical or negative-evidence candidate does not enter."""
    base = _state(0.050, 1e-4, 0.10, 2e-4)
    win = _state(0.060, 2e-4, 0.09, 1e-4)
    run = _state(0.055, 3e-4, 0.11, 3e-4)
    cands = [
        _cand("gamma", 4.0, win),
        _cand("fresnel", 2.0, run),
        _cand("ambient", -3.0, _state(1.0, 1.0, 1.0, 1.0)),
        _cand("second_lobe", 9.0, _state(1.0, 1.0, 1.0, 1.0), physical=False),
    ]
    step = NS(effect="gamma", evidence=NS(state=win), candidates=cands)
    got = model_averaged([step], base)
    for k in ("rho_s", "alpha"):
        models = [
            (math.exp(d / 2), *(st.values["model"][k], st.sigma["model"][k]))
            for d, st in ((0.0, base), (4.0, win), (2.0, run))
        ]
        m, s = _bma(models)
        assert got[k]["value"] == pytest.approx(m, rel=1e-12)
        assert got[k]["sigma"] == pytest.approx(s, rel=1e-12)
        assert got[k]["sigma_model"] == win.sigma["model"][k]


def test_a_model_not_told_apart_weighs_as_the_named_one():
    """A camera response named over a per-channel specular scale the report calls not told apart, the scale's ΔBIC
    670 below: by the numbers the scale would not enter; it enters with the top weight, so the averaged value lies
    between them and σ holds their spread. Without the ambiguity the average is the named model's."""
    base = _state(0.0639, 2e-5, 0.0871, 2e-5)
    gamma = _state(0.0582, 1.2e-4, 0.0902, 7e-5)
    scale = _state(0.0639, 5e-5, 0.0872, 2.6e-5)
    cands = [_cand("gamma", 2169.0, gamma), _cand("coloured_specular", 1500.0, scale)]
    step = NS(effect="gamma", evidence=NS(state=gamma), candidates=cands)
    both = model_averaged([step], base, [("gamma", "coloured_specular", 669.0)])
    m, s = _bma([(1.0, 0.0582, 1.2e-4), (1.0, 0.0639, 5e-5)])
    assert both["rho_s"]["value"] == pytest.approx(m, rel=1e-12) and both["rho_s"]["sigma"] == pytest.approx(s)
    assert 0.0582 < both["rho_s"]["value"] < 0.0639 and both["rho_s"]["sigma"] > 20 * 1.2e-4
    alone = model_averaged([step], base)
    assert alone["rho_s"]["value"] == pytest.approx(0.0582, rel=1e-12)
    assert alone["rho_s"]["sigma"] == pytest.approx(1.2e-4, rel=1e-12)
    # an ambiguity of an earlier step's effect does not enter this step's average
    other = model_averaged([step], base, [("anisotropy", "coloured_specular", 1.0)])
    assert other["rho_s"]["value"] == pytest.approx(0.0582, rel=1e-12)


def test_the_named_model_weighs_as_the_best_of_its_step():
    """Named by dominance (it lowers χ² more with fewer parameters) with a lower ΔBIC than a runner-up that is not
    its confusable alternative: the two weigh alike; the value is not taken from the runner-up alone."""
    base = _state(0.0602, 4e-5, 0.0858, 3e-5)
    gamma = _state(0.0566, 1.2e-4, 0.0900, 1.2e-4)
    ramp = _state(0.0620, 1e-4, 0.0863, 5e-5)
    cands = [_cand("gamma", 214.8, gamma), _cand("illumination_gradient", 368.9, ramp)]
    step = NS(effect="gamma", evidence=NS(state=gamma), candidates=cands)
    got = model_averaged([step], base)
    for k in ("rho_s", "alpha"):
        m, s = _bma(
            [
                (1.0, gamma.values["model"][k], gamma.sigma["model"][k]),
                (1.0, ramp.values["model"][k], ramp.sigma["model"][k]),
            ]
        )
        assert got[k]["value"] == pytest.approx(m, rel=1e-9) and got[k]["sigma"] == pytest.approx(s, rel=1e-9)


def test_nothing_named_is_the_baseline():
    base = _state(0.05, 1e-4, 0.1, 2e-4)
    got = model_averaged([], base)
    assert got["rho_s"] == {"value": 0.05, "sigma": 1e-4, "sigma_model": 1e-4, "sigma_discrepancy": 0.0}


def test_the_named_model_enters_whatever_its_ranked_evidence():
    """Deflated by its own design effect the named effect's ranked ΔBIC can fall below zero; it is still the model
    the report names and enters at the step's top weight."""
    base = _state(0.05, 1e-4, 0.1, 2e-4)
    named = _state(0.06, 1e-4, 0.09, 1e-4)
    other = _state(0.055, 1e-4, 0.095, 1e-4)
    cands = [_cand("gamma", -2.0, named), _cand("coloured_specular", 5.0, other)]
    got = model_averaged([NS(effect="gamma", evidence=NS(state=named), candidates=cands)], base)
    m, s = _bma([(1.0, 0.06, 1e-4), (1.0, 0.055, 1e-4), (math.exp(-2.5), 0.05, 1e-4)])
    assert got["rho_s"]["value"] == pytest.approx(m, rel=1e-12) and got["rho_s"]["sigma"] == pytest.approx(s)
