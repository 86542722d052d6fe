"""What the final model leaves unexplained: report lines that agree with the stop rule.

A binned test of the whitened residuals against a covariate pools many
scanlines into each bin; the texture whitening acts along each scanline
only, so texture shared by neighbouring scanlines inflates the binned
``χ²`` on a clean capture (untouched captures read "unexplained discrepancy
against θo" at gaps 0.88–1.07). The gap itself is what the stop rule reads
(``χ² − dof ≤ 2 √(2 dof)``, :func:`~wardjax.effects._evidence._within_noise`),
so structure is reported as unexplained only where the gap exceeds the noise:
the binned tests then say *where* the residual lives. Where the gap is within
the noise they are kept in ``report.structure`` (p-values per covariate) but
the verdict reads "nothing needed".
"""

from __future__ import annotations

import math

import numpy as np
from scipy.special import ndtr

from ._report import Candidate, FitState
from ._structure import _binned_test, covariate_value

__all__ = ["unexplained_structure"]


def unexplained_structure(
    r: np.ndarray,
    covs: dict[str, np.ndarray],
    st: FitState,
    rejected: list[Candidate],
    structure_p: float,
    within_noise: bool,
) -> tuple[list[str], dict[str, dict]]:
    """Report lines and the binned test per covariate for the final state ``st``.

    Parameters
    ----------
    r, covs
        The final whitened residuals and the covariates at the same points, flat ``(n,)``.
    st
        The final fitted state.
    rejected
        Winners not named: partial matches (supported, explaining too little),
        winners that did not predict held-out scanlines, and effects whose own
        covariate kept its structure once they were fitted.
    structure_p
        Level (Bonferroni over the covariates) of the binned tests.
    within_noise
        The stop rule holds for ``st`` (under either of the texture's
        covariances): nothing is unexplained.
    """
    structure: dict[str, dict] = {}
    flagged = []
    n_cov = max(len(covs), 1)
    for name, x in covs.items():
        chi2, dof, p, xc, mean, _ = _binned_test(r, x)
        worst = float(xc[np.argmax(np.abs(mean))]) if len(xc) else math.nan
        structure[name] = {"chi2": chi2, "dof": dof, "p": p, "worst_bin": worst}
        if p < structure_p / n_cov:
            flagged.append(
                f"unexplained discrepancy against {name} (binned χ² = {chi2:.1f} on {dof} bins, p = {p:.1e}; "
                f"largest near {covariate_value(name, worst)})"
            )
    if within_noise:
        return [], structure
    z = (st.chi2 - st.dof) / math.sqrt(2 * st.dof)
    lines = [
        f"gap {st.gap:.3f} exceeds the noise level (χ² = {st.chi2:.1f} on {st.dof} dof, "
        f"{z:.1f} SD above, p = {float(ndtr(-z)):.1e})"
    ]
    lines += flagged
    for c in rejected:
        if c.signature is not None:
            name, chi2, bins, p, left = c.signature
            lines.append(
                f"{c.effect} is supported (ΔBIC = {c.delta_bic:.1f}) but, fitted, leaves {100 * left:.0f} % of the "
                f"structure against its own covariate {name} (binned χ² = {chi2:.1f} on {bins} bins, p = {p:.1e}): "
                "the discrepancy is not of its form, not named"
            )
            continue
        if c.holdout is not None and not c.holdout.passed:
            lines.append(
                f"{c.effect} fits this capture (ΔBIC = {c.delta_bic:.1f}) but does not predict held-out "
                f"scanlines (held-out gain {c.holdout.gain:.1f}, {100 * c.holdout.share:.0f} % of its Δχ²): "
                "not named"
            )
            continue
        lines.append(
            f"{c.effect} is supported (ΔBIC = {c.delta_bic:.1f}) but explains only "
            f"{100 * c.explained:.0f} % of the excess: a partial match, not named"
            + (
                ""
                if c.variogram is None
                else f" (with the texture's covariance from the variogram: gap left "
                f"{c.variogram.gap:.3f}, p = {c.variogram.gap_p:.1e})"
            )
        )
    return lines, structure
