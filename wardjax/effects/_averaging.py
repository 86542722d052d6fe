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
    chosen model's ``σ``.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["model_averaged"]


def model_averaged(steps: list, baseline) -> dict[str, dict[str, float]]:
    """``{name: {"value", "sigma", "sigma_model"}}`` for the model's own parameters (``values["model"]``).

    ``steps``: the report's :class:`~wardjax.effects._report.Step` list;
    ``baseline``: the fitted baseline :class:`~wardjax.effects._report.FitState`.
    ``sigma_model`` is the chosen model's σ, ``sigma`` the averaged one.
    """
    final = steps[-1].evidence.state if steps else baseline
    out = {
        k: {"value": float(v), "sigma": float(final.sigma["model"][k]), "sigma_model": float(final.sigma["model"][k])}
        for k, v in final.values["model"].items()
    }
    if not steps:
        return out
    before = steps[-2].evidence.state if len(steps) > 1 else baseline
    models = [(0.0, before)] + [
        (c.delta_bic, c.state)
        for c in steps[-1].candidates
        if c.state is not None and c.physical and c.delta_bic > 0 and math.isfinite(c.delta_bic)
    ]
    top = max(d for d, _ in models)
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
    return out
