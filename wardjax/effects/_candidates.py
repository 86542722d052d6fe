"""The candidates of one discovery step: each remaining effect fitted on top of the current model, scored and ranked.

Each effect is fitted from each of its starts (and, where it has optional
parameters, also in its reduced form); the best physical start gives its
:class:`Candidate` (Δχ², ΔBIC, likelihood-ratio p-value). Fits that stopped
at the step cap and decide the step are continued before ranking, and on a
textured capture Δχ² is deflated by the texture between scanlines
(:class:`CrossTexture`). The ranking puts first the best candidate that no
supported candidate dominates (``_evidence._dominant_first``).
"""

from __future__ import annotations

import dataclasses
import functools
import math
from collections.abc import Callable

import numpy as np

from ._evidence import _dominant_first, _gap_p, _lr_p
from ._report import Candidate, FitState
from ._search import _Search, _View
from ._step_record import flat as _flat
from ._structure import _binned_test

_REFINE_BIC = 0.5  # ... a runner-up matters if its ΔBIC (a lower bound) is at least this fraction of the winner's
# a specular reflectance is a fraction of the light: a candidate whose fit drives ρs past 1 (and past the current
# model's) is no evidence for the effect. On a dark metal (ρs 0.35) a camera response took a systematic of the dark
# tail by trading γ against the lobe, to ρs 1.3 and α −20 %, and was named on every capture.
_RHO_S_MAX = 1.0


def _candidate_jobs(search: _Search, cur: FitState, remaining: list[int]):
    """Jobs extending ``cur`` by each remaining effect, one per start of that effect.

    Returns the jobs, ``(effect index, form)`` of each job, and the free
    parameter indices of ``cur`` (model plus active effects), which every job
    frees together with its own effect's. Form 0 frees all the effect's
    parameters; form 1, for an effect with optional parameters, holds those
    at their absent value.
    """
    layout, testable = search.layout, search.testable
    jobs, owner = [], []
    free_cur = list(cur.free)  # the model's and the active effects' (optional ones held stay held)
    for i in remaining:
        e = testable[i]
        own = layout.slices[e.name]
        pinned = [j for j, p in zip(own, e.params) if p.optional]
        reduced = [[j for j in own if j not in pinned]] if pinned else []
        # textured (search.cross set), an optional parameter is held absent: see Param.optional
        forms = ([own] if search.cross is None or not pinned else []) + reduced
        for form, free_e in enumerate(forms):
            for st in e.starts():
                u0 = cur.u.copy()
                for j, v, p in zip(own, st, e.params):
                    u0[j] = p.to_u(v if j in free_e else p.absent)
                jobs.append((u0, free_cur + free_e, cur.active + (i,)))
                owner.append((i, form))
    return jobs, owner, free_cur


def _rho_s(st: FitState) -> float:
    """The model's ρs in ``st`` (``-inf`` where the model has none)."""
    return float(st.values.get("model", {}).get("rho_s", -math.inf))


def _score_candidate(search: _Search, cur: FitState, structure_p_of: Callable[[str], float], i: int, rs):
    """The :class:`Candidate` for effect ``i`` from its fits ``rs``, and the index of the fit it rests on.

    The best physical start is chosen (a fit on the unphysical side of an
    amplitude, or one that drives the model's ρs past ``_RHO_S_MAX``, counts
    as no evidence, Δχ² = 0); the index is ``None`` when no
    start gave a finite fit.
    """
    e = search.testable[i]
    sts = [search.state_of(r, cur.active + (i,)) for r in rs]
    # parameters each fit spends on the effect: all of them, or the reduced form without its optional ones
    ks = [len(st.free) - len(cur.free) + e.n_data_params for st in sts]
    bound = max(_RHO_S_MAX, _rho_s(cur))
    phys = [k for k, st in enumerate(sts) if e.physical(st.values[e.name]) and _rho_s(st) <= bound]
    pool = phys or range(len(sts))
    # the best form by BIC (for an effect without optional parameters: the lowest χ²); of starts within
    # rounding of the best (equivalent minima, e.g. anisotropy's (η, φ) and (−η, φ + π/2)) the first, so that
    # the choice does not hang on the last digits of how the fits were batched
    score = {k: sts[k].chi2 + ks[k] * search.ln_n for k in pool}
    best = min(score.values(), default=math.nan)
    k = next((k for k in pool if score[k] <= best + 1e-9 * max(1.0, abs(best))), None)
    sp = structure_p_of(e.covariate)
    if k is None:
        return Candidate(e.name, e.k, math.nan, -math.inf, 1.0, 0.0, sp, False, None, math.nan), None
    chosen, n_k = sts[k], ks[k]
    dchi2 = max(cur.chi2 - chosen.chi2 if phys else 0.0, 0.0)
    excess = max(cur.chi2 - cur.dof, dchi2, 1e-300)
    return Candidate(
        effect=e.name,
        k=n_k,
        delta_chi2=dchi2,
        delta_bic=dchi2 - n_k * search.ln_n,
        p_value=_lr_p(dchi2, e, n_k),
        explained=dchi2 / excess,
        structure_p=sp,
        physical=bool(phys),
        state=chosen,
        gap_p_after=_gap_p(chosen.chi2, chosen.dof) if phys else _gap_p(cur.chi2, cur.dof),
    ), k


def _continue_contenders(search: _Search, cur: FitState, remaining: list, fits: dict, scored: dict, score):
    """Continue the fits that stopped at the step cap where they decide the step, and rescore them in place.

    These are the winner's and those of runners-up whose ΔBIC (a lower bound
    while unconverged) already reaches ``_REFINE_BIC`` of the winner's: the
    ranking among them, and the reported parameters, need converged fits.
    Repeats until no such unconverged fit is left unrefined, since a
    continued fit can change which candidate leads.
    """
    refined: set = set()
    while True:
        top = max(scored[i][0].delta_bic for i in remaining)
        todo = [
            i
            for i in remaining
            if i not in refined
            and scored[i][1] is not None
            and not scored[i][0].state.ok
            and (scored[i][0].delta_bic == top or scored[i][0].delta_bic >= _REFINE_BIC * top > 0)
        ]
        if not todo:
            break
        for i in todo:
            k = scored[i][1]
            fits[i][k] = search.refine(fits[i][k], cur.active + (i[0],))
            scored[i] = score(i[0], fits[i])
            refined.add(i)


def _rechecked(search: _Search, cur: FitState, win: Candidate) -> Candidate:
    """``win`` with the guard's second opinion, the texture's covariance from the variogram, where it is carried."""
    got = None if search.recheck is None or win.state is None else search.recheck(cur, win.state)
    return win if got is None else dataclasses.replace(win, variogram=got)


def _deflated(search: _Search, cur: _View, cand: Candidate, state: FitState) -> Candidate:
    """``cand`` with Δχ² deflated by the texture between scanlines in ΔBIC and the p-value (:class:`CrossTexture`)."""
    new, cross = search.residual_view(state), search.cross
    assert cross is not None  # called only where the texture is carried (_rank_candidates)
    dchi2, deff = cross.deflate(cand.delta_chi2, cur.r, cur.state.chi2, new.r, state.chi2, new.pred)
    e = next(t for t in search.testable if t.name == cand.effect)
    return dataclasses.replace(
        cand, delta_bic=dchi2 - cand.k * search.ln_n, p_value=_lr_p(dchi2, e, cand.k), design_effect=deff
    )


def _rank_candidates(search: _Search, cur: _View, remaining: list[int]):
    """Fit every remaining effect on top of ``cur`` and rank the candidates by ΔBIC, best first.

    Returns the sorted candidates and the fitted state of each effect that
    gave a finite fit, or ``None`` when the current model leaves no room in
    the padded parameter width for another effect.
    """
    mask = search.mask
    r_flat = _flat(cur.r.reshape(mask.shape) if mask is not None else cur.r, mask)
    jobs, owner, free_cur = _candidate_jobs(search, cur.state, remaining)
    if len(free_cur) + 2 > search.k_pad:
        return None
    structure_p = {}  # binned test per covariate: the residuals and covariates are fixed within a step

    def structure_p_of(name: str) -> float:
        if name not in cur.covs:
            return math.nan
        if name not in structure_p:
            structure_p[name] = _binned_test(r_flat, _flat(cur.covs[name], mask))[2]
        return structure_p[name]

    res = search.fit(jobs)
    score = functools.partial(_score_candidate, search, cur.state, structure_p_of)
    keys = list(dict.fromkeys(owner))  # (effect, form)
    fits = {key: [r for r, o in zip(res, owner) if o == key and np.isfinite(r[1])] for key in keys}
    scored = {key: score(key[0], fits[key]) for key in keys}
    _continue_contenders(search, cur.state, keys, fits, scored, score)
    by_form = {key: st for key in keys if scored[key][1] is not None and (st := scored[key][0].state) is not None}
    evidence = {key: scored[key][0] for key in keys}
    if search.cross is not None:  # the texture between scanlines and channels inflates coherent evidence
        for key in by_form:
            if evidence[key].delta_bic > 0:
                evidence[key] = _deflated(search, cur, evidence[key], by_form[key])
    # each effect by its better form (the reduced one where its optional parameters do not pay their way)
    best = {}
    for key in keys:
        if key[0] not in best or evidence[key].delta_bic > evidence[best[key[0]]].delta_bic:
            best[key[0]] = key
    by_effect = {i: by_form[key] for i, key in best.items() if key in by_form}
    evidence = {i: evidence[key] for i, key in best.items()}
    cands = list(evidence.values())
    cands.sort(key=lambda c: -c.delta_bic)
    return _dominant_first(cands), by_effect
