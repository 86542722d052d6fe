"""The evidence tests of a discovery step: the likelihood-ratio p-value, the gap's tail, the stop rule and the
order between candidates.

Small and pure (scalars and candidates in, no fitting), kept apart from the search in ``_discover``.
"""

from __future__ import annotations

import math

from scipy.special import chdtrc  # χ² survival function, without importing scipy.stats

from ._effect import Effect
from ._report import Candidate, FitState

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


def _dominant_first(cands: list[Candidate]) -> list[Candidate]:
    """``cands`` (best ΔBIC first) led by the best that no supported candidate dominates.

    ``A`` dominates ``B`` when it lowers χ² at least as much with no more
    parameters (``Δχ²_A ≥ Δχ²_B``, ``k_A ≤ k_B``, one of them strict). Each
    candidate's ΔBIC is against the current model, its Δχ² divided by its
    own design effect; the evidence *between* two candidates is their own
    deviance difference, ``(Δχ²_A − Δχ²_B)/D_AB − (k_A − k_B) ln N``, which
    favours a dominant ``A`` for every ``D_AB ≥ 1``. Deflated one by one,
    the order can flip: on textured captures a camera response (γ, one
    parameter) fitted better than a per-channel specular scale (two) in each
    of four draws, and came second because its signature, shared by every
    scanline, had the larger design effect (2.0–5.3 against 1.7–4.1).
    A dominant candidate moves ahead only where its own evidence supports
    it (ΔBIC > 0), and only of the candidates it dominates: the leader is the
    best by ΔBIC among the candidates that no supported candidate dominates.
    Moving the dominant one to the front outright put it ahead of candidates
    it does not dominate: on an untouched wood desk an illumination gradient
    (Δχ² 18.9, one parameter, ΔBIC 5.5) dominated γ (18.8, ΔBIC 9.3) by a
    tenth and so led ahead of the anisotropy truly present (57.0, two
    parameters, ΔBIC 7.0), which it does not dominate.
    """

    def dominates(a: Candidate, b: Candidate) -> bool:
        return (
            a.delta_bic > 0
            and a.delta_chi2 >= b.delta_chi2
            and a.k <= b.k
            and (a.delta_chi2 > b.delta_chi2 or a.k < b.k)
        )

    if not cands:
        return []
    free = [c for c in cands if not any(dominates(d, c) for d in cands if d is not c)]
    lead = max(free, key=lambda c: c.delta_bic)  # the first of them (cands is sorted by ΔBIC)
    return [lead] + [c for c in cands if c is not lead]
