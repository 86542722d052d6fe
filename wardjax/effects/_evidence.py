"""The evidence tests of a discovery step: the likelihood-ratio p-value, the gap's tail and the stop rule.

Small and pure (scalars in, scalars out), kept apart from the search in ``_discover``.
"""

from __future__ import annotations

import math

from scipy.special import chdtrc  # χ² survival function, without importing scipy.stats

from ._effect import Effect
from ._report import FitState

_NOISE_Z = 2.0  # stop rule: no effect is added once χ² − dof ≤ _NOISE_Z · √(2 dof)


def _lr_p(dchi2: float, e: Effect, k: int) -> float:
    """Likelihood-ratio p-value of ``dchi2`` on the ``k`` parameters a form of ``e`` spends."""
    if dchi2 <= 0:
        return 1.0
    if any(p.sign for p in e.params):  # boundary mixture ½χ²_{k−1} + ½χ²_k
        lo = chdtrc(k - 1, dchi2) if k > 1 else 0.0
        return float(0.5 * lo + 0.5 * chdtrc(k, dchi2))
    return float(chdtrc(k, dchi2))


def _within_noise(st: FitState) -> bool:
    """The stop rule: the excess ``χ² − dof`` is within ``_NOISE_Z`` SDs (``√(2 dof)``) of what noise gives."""
    return bool(st.chi2 - st.dof <= _NOISE_Z * math.sqrt(2.0 * st.dof))


def _gap_p(chi2: float, dof: int) -> float:
    """``P(χ²_dof ≥ chi2)``: whether a gap still exceeds the noise level."""
    return float(chdtrc(dof, chi2))
