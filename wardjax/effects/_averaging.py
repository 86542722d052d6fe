"""The model's parameters averaged over the last step's candidate models by their evidence.

Why
    Once discovery has named an effect, the σ of the chosen model's ρs and α
    say how well the data fix them *given* that model. Where a runner-up
    explained the data almost as well (a camera response against a coloured
    specular, a ramp against the Fresnel rise), the parameters move with the
    choice, and z against the truth read too large. Bayesian model averaging
    (Hoeting et al. 1999, Statistical Science 14, 382, eqs. 1–2) over the
    models of the last step — the model before it and each candidate with
    positive evidence — weights each by ``exp(ΔBIC/2)`` (BIC's approximation
    of the Bayes factor against the model before the step) and gives

        μ̄ = Σ w_m μ_m,   σ̄² = Σ w_m (σ_m² + (μ_m − μ̄)²),

    the within-model variance plus the spread between models. Where nothing
    was named, or the winner stands alone by a wide margin, ``σ̄`` is the
    chosen model's ``σ``. Where a gap beyond the noise remains, the
    discrepancy term's σ (:mod:`~wardjax.effects._discrepancy`) is added in
    quadrature.

    The named model and the ones the report calls *not told apart* from it
    (``ambiguous``) enter with the largest weight of the step, whatever their
    own ΔBIC: the report has said the data do not choose between them, and
    the σ say the same. An effect named because it lowers χ² at least as much
    with no more parameters can trail a runner-up in ΔBIC (each deflated by
    its own design effect); weighed by the numbers, the runner-up's fit would
    make the average (a camera response named over an illumination ramp on
    the Radiance bench: α from the ramp's fit, z −78). Every ΔBIC here is on
    one scale: the named model's as ranked, before it was read again under the
    covariance it was named on (its fit is that reading's).
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["model_averaged"]


def model_averaged(steps: list, baseline, ambiguous=(), discrepancy: dict | None = None) -> dict[str, dict[str, float]]:
    """``{name: {"value", "sigma", "sigma_model", "sigma_discrepancy"}}`` for the model's own parameters
    (``values["model"]``).

    ``steps``: the report's :class:`~wardjax.effects._report.Step` list;
    ``baseline``: the fitted baseline :class:`~wardjax.effects._report.FitState`;
    ``ambiguous``: the report's ``(named, other, ΔBIC difference)`` pairs;
    ``discrepancy``: the discrepancy term's reading (:mod:`~wardjax.effects._discrepancy`) or ``None``.
    ``sigma_model`` is the chosen model's σ, ``sigma_discrepancy`` the discrepancy term's (0 without one), and
    ``sigma`` the averaged one with the discrepancy's added in quadrature.
    """
    final = steps[-1].evidence.state if steps else baseline
    extra = (discrepancy or {}).get("sigma", {})
    out = {
        k: {
            "value": float(v),
            "sigma": float(final.sigma["model"][k]),
            "sigma_model": float(final.sigma["model"][k]),
            "sigma_discrepancy": float(extra.get(k, 0.0)),
        }
        for k, v in final.values["model"].items()
    }
    if steps:
        _average(out, steps, baseline, ambiguous)
    for d in out.values():
        d["sigma"] = math.hypot(d["sigma"], d["sigma_discrepancy"])
    return out


def _average(out: dict, steps: list, baseline, ambiguous) -> None:
    """``out``'s values and σ averaged over the last step's models (module docstring), in place."""
    before = steps[-2].evidence.state if len(steps) > 1 else baseline
    named = {steps[-1].effect} | {b for a, b, _ in ambiguous if a == steps[-1].effect}
    cands = [
        c
        for c in steps[-1].candidates
        if c.state is not None
        and c.physical
        and math.isfinite(c.delta_bic)
        and (c.delta_bic > 0 or c.effect == steps[-1].effect)  # the named model enters whatever its ranked ΔBIC
    ]
    top = max([0.0] + [c.delta_bic for c in cands])
    models = [(0.0, before)] + [(top if c.effect in named else c.delta_bic, c.state) for c in cands]
    w = np.array([math.exp(0.5 * (d - top)) for d, _ in models])
    w = w / w.sum()
    for k in out:
        mu = np.array([st.values["model"][k] for _, st in models])
        sd = np.array([st.sigma["model"][k] for _, st in models])
        ok = np.isfinite(mu) & np.isfinite(sd)
        if not ok.any():
            continue
        wk = w[ok] / w[ok].sum()
        m = float(np.sum(wk * mu[ok]))
        out[k]["value"] = m
        out[k]["sigma"] = float(math.sqrt(np.sum(wk * (sd[ok] ** 2 + (mu[ok] - m) ** 2))))
