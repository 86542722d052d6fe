"""``discover``: find where a model and the data disagree, name the missing effect, add it.

Algorithm (DESIGN.md, "Missing effects")
    1. Fit the baseline; the *gap* is the reduced χ², ``χ²/dof`` of the
       whitened residuals ``(y − f)/σ`` — 1 when the model explains the data
       to the noise level.
    2. Test the residuals for structure against each candidate's telling
       covariate (binned means of the whitened residuals in quantile bins;
       ``Σ n_b r̄_b² ~ χ²_B`` under noise).
    3. Fit every candidate extension (current model + one effect) from
       several starts, all in one batched, jitted Levenberg–Marquardt solve,
       and score it by evidence that penalises its extra parameters.
    4. Add the best-supported candidate if it is justified; repeat. Fits
       that stopped at the step cap are continued where they decide (the
       baseline, the winner, runners-up within half its ΔBIC): γ and a
       second lobe lie in curved valleys that can need hundreds of steps.
    5. Report the structure no library effect explains.

Evidence: why BIC *and* a boundary-corrected likelihood ratio
    A candidate with ``k`` extra parameters that lowers the deviance by
    ``Δχ² = −2 Δ log L`` is scored by the Schwarz criterion,
    ``ΔBIC = Δχ² − k ln N``, ``−½ΔBIC`` approximating the log Bayes factor
    against the current model (unit-information prior); the winner is the
    candidate with the largest ΔBIC, so an effect with more parameters must
    buy its extra freedom — never the largest raw drop. With the texture carried
    each Δχ² is divided by its own design effect, and a candidate that lowers
    χ² at least as much with no more parameters is put ahead of the leader
    (``_evidence._dominant_first``). BIC's penalty grows
    with ``N``, which is what keeps false additions rare on the large
    scanline problems (``N`` ≈ 10⁴: a one-parameter effect needs
    ``Δχ² > 9.2``). On small problems (Table 1: ``N = 16``) BIC alone is
    lenient, so the winner must *also* pass the likelihood-ratio test at
    level ``alpha`` Bonferroni-corrected over the ``m`` candidates of the
    step. Amplitudes that are physical only on one side of their absent
    value (a second lobe's weight, a Fresnel κ) are fitted unconstrained; a
    fit on the unphysical side counts as no evidence, and the LR reference is
    the boundary mixture ``½χ²_{k−1} + ½χ²_k`` (Self & Liang 1987). Both
    price the effect against the noise model; where that model is off
    (correlated noise, misread texture) every Δχ² is inflated alike. So the winner must also predict data it
    was not fitted to: refitted on alternate blocks of scanlines it must lower χ² on the others (its held-out
    gain at least a quarter of its Δχ², :mod:`wardjax.effects._holdout`) — only the winner, once per step, on
    scanline data with 16 scanlines or more (on 16 threshold points the folds' noise exceeds the effects).

Guard against confident wrong names
    A library effect that is strongly supported but explains less than ``min_explained`` of the current excess
    (``χ² − dof``) *and* leaves a gap that still exceeds the noise level (``P(χ²_dof ≥ χ²_after) < structure_p``) is
    *not* added: a large discrepancy that a library effect only dents is the signature of an effect outside the
    library that it partly mimics. It is reported as a partial match next to the unexplained structure.

    Both conditions are needed. The excess ``χ² − dof`` carries the noise of χ² itself, SD ``√(2 dof)`` (≈ 110 on
    6,144 residuals): an effect whose residual signature is mostly absorbed by the baseline (a γ mismatch at
    ``ε ≈ −0.1`` moves the data by 5 σ RMS, of which ρd, ρs and α take all but ``Δχ² ≈ 30``) is decisively
    supported, yet "explains" a small fraction of an excess that is mostly noise. When the model with the effect
    leaves no significant gap, nothing is left for an out-of-library effect to explain and the effect is named.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import time
from collections.abc import Callable
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from threadpoolctl import threadpool_limits

from ._effect import Effect, Param
from ._evidence import _NOISE_Z, _dominant_first, _gap_p, _lr_p, _within_noise
from ._holdout import Holdout
from ._inputs import _check_inputs, _split_library
from ._recheck import VariogramRecheck
from ._remeasure import TextureRemeasure
from ._report import Candidate, DiscoveryReport, FitState, Step
from ._solve import _cov_full, _fit_batch, _Layout, _residual_view
from ._step_record import flat as _flat
from ._step_record import make_step, plot_sampler
from ._structure import _binned_test
from ._texture_term import CrossTexture, identity_whitened, with_texture
from ._verdict import unexplained_structure

__all__ = ["discover"]

_SOLO_MIN_OBS = 20_000  # from this many residuals on, each fit is solved alone (_fit_batch)
_REFINE_ROUNDS = 11  # more rounds of lm_steps for an unconverged fit that matters (_Search.refine): 240 steps in all
_AMBIGUOUS_BIC = 6.0  # a confusable runner-up within this ΔBIC of the winner is named too (Kass & Raftery: < 6)
# effects whose signatures one capture may not tell apart: a lamp field follows image position, anisotropy the
# half-vector azimuth, the Fresnel rise the incidence angle, and across one capture's scanlines they covary (on
# textured captures the Fresnel rise, one parameter, took the ramp across the image); a camera response compresses
# the highlight against each channel's diffuse floor, which a per-channel specular scale mimics
_CONFUSABLE = {
    "illumination_gradient": ("anisotropy", "fresnel"),
    "anisotropy": ("illumination_gradient",),
    "fresnel": ("illumination_gradient",),
    "gamma": ("coloured_specular",),
    "coloured_specular": ("gamma",),
}
_REFINE_BIC = 0.5  # ... a runner-up matters if its ΔBIC (a lower bound) is at least this fraction of the winner's


class _View(NamedTuple):
    """A fitted state with what the tests read off it: whitened residuals, prediction and covariates."""

    state: FitState
    r: np.ndarray
    pred: np.ndarray
    covs: dict
    rho: np.ndarray | None = None  # profiled ρd (S, 1, C) of a scanline model


class _Search:
    """What every fit of one ``discover`` run shares: the problem, the parameter layout and the solver settings.

    All fits of a run go through :meth:`fit` with the same padded width
    ``k_pad`` and batch width ``b_pad``, so that one compiled program serves
    the baseline, every candidate and every continuation.
    """

    def __init__(self, model, data, testable: tuple[Effect, ...], lm_steps: int, chunk: int):
        self.model, self.data, self.testable = model, data, testable
        self.lm_steps, self.chunk = lm_steps, chunk
        self.base = model.base_params(data)
        self.layout = _Layout(self.base, testable)
        self.n_obs = int(data.n_obs)
        self.cross: CrossTexture | None = None  # set when the texture is carried (design effects)
        self.recheck: VariogramRecheck | None = None  # ... and the guard's second opinion
        self.holdout: Holdout | None = None  # the winner must predict held-out scanlines
        self.remeasure: TextureRemeasure | None = None  # the texture measured again after each named effect
        # whitened by the texture's covariance, an LM step costs far more than a call's overhead: each fit alone
        # (batched, the baseline's 3 starts ran padded to the step's 16, every one until the slowest converged)
        self.solo = self.n_obs >= _SOLO_MIN_OBS or getattr(data, "whiten", None) is not None
        with jax.enable_x64(True):  # on the device once, not once per solve
            self.data_dev = jax.tree_util.tree_map(jnp.asarray, data)
        self.n_prof = int(model.n_profiled(data))
        self.ln_n = math.log(self.n_obs)
        self.k_pad = len(self.base) + max([len(e.params) for e in testable] + [0]) + 4
        self.mask = np.asarray(data.mask) if hasattr(data, "mask") else None
        self.baseline_jobs = _baseline_jobs(self.layout, self.base)
        n_cand_jobs = sum(len(e.starts()) for e in testable)
        self.b_pad = max(len(self.baseline_jobs), n_cand_jobs, 1)

    def sibling(self, data) -> _Search:
        """The same search over other ``data`` of the same shapes, solved the same way: the run's compiled program."""
        out = _Search(self.model, data, self.testable, self.lm_steps, self.chunk)
        out.solo = self.solo
        return out

    def fit(self, jobs):
        """Solve ``jobs`` (see :func:`_fit_batch`) at the run's padded width, batch width and step cap."""
        return _fit_batch(
            jobs,
            self.layout,
            self.model,
            self.testable,
            self.data_dev,
            self.k_pad,
            self.b_pad,
            self.lm_steps,
            self.chunk,
            self.solo,
        )

    def refine(self, r, active=()):
        """Continue a fit that stopped at the step cap from where it stopped, up to ``_REFINE_ROUNDS`` times.

        Curved valleys (γ against ρd, ρs and α; a second lobe against the
        first) can take Levenberg–Marquardt more than ``lm_steps`` steps; a
        fit whose parameters are reported, or whose Δχ² decides, must have
        converged. The priors stay centred on the first start. A round that leaves χ² where it was ends
        it (stalled; it stays unconverged) rather than repeat the same point.
        """
        last = math.inf
        for _ in range(_REFINE_ROUNDS):
            u, chi2, _, ok, idx, km, anchor = r
            # a round that lowered nothing has stalled (a parameter pinned where its gradient vanishes): the next,
            # from the same point, would repeat it exactly
            if ok or not np.isfinite(chi2) or chi2 >= last:
                break
            last = chi2
            job = (u, [int(j) for j in idx[km]], tuple(active), anchor)
            # the run's own batch width and mode: the compiled program is reused, not a new one for width 1
            r = self.fit([job])[0]
        return r

    def state_of(self, r, active) -> FitState:
        """The :class:`FitState` of one fit result ``r`` with the effects ``active`` switched on.

        The degrees of freedom count the free parameters, the profiled ones
        and the active effects' data-dependent ones.
        """
        u, chi2, jtj, ok, idx, km, _ = r
        n_par = int(km.sum()) + self.n_prof + sum(self.testable[i].n_data_params for i in active)
        dof = max(self.n_obs - n_par, 1)
        cov = _cov_full(self.layout, jtj, idx, km)
        return FitState(
            u=u,
            chi2=chi2,
            dof=dof,
            gap=chi2 / dof,
            ok=ok,
            cov=cov,
            active=tuple(active),
            values=self.layout.natural(u),
            sigma=self.layout.sigma(u, cov),
            free=tuple(int(j) for j in idx[km]),
        )

    def residual_view(self, st: FitState) -> _View:
        """Whitened residuals, prediction and covariates of ``st``: what the structure tests and plots read."""
        act = np.array([i in st.active for i in range(len(self.testable))], bool)
        with jax.enable_x64(True):  # the parameters too: outside, jnp.asarray would round them to float32
            r, pred, rho = _residual_view(
                jnp.asarray(st.u),
                jnp.asarray(act),
                self.data_dev,
                model=self.model,
                effects=self.testable,
                layout_key=self.layout.key,
            )
        r, pred = np.asarray(r), np.asarray(pred)
        return _View(st, r, pred, self.model.covariates(self.data, pred), None if rho is None else np.asarray(rho))


def _baseline_jobs(layout: _Layout, base: tuple[Param, ...]):
    """Baseline multi-start jobs: every combination of the model parameters' starting values.

    Each parameter contributes its ``init`` first and then its other
    ``starts``, so the first job is the plain initial guess.
    """
    u_init = layout.u_initial()
    base_free = layout.slices["model"]
    jobs = []
    b_starts: list[tuple[float, ...]] = [()]
    for p in base:
        vals = (p.init,) + tuple(v for v in p.starts if v != p.init)
        b_starts = [o + (v,) for o in b_starts for v in vals]
    for st in b_starts:
        u0 = u_init.copy()
        for j, v in zip(base_free, st):
            u0[j] = layout.entries[j][1].to_u(v)
        jobs.append((u0, base_free, ()))
    return jobs


def _fit_baseline(search: _Search) -> FitState:
    """Fit the model without effects from all its starts and keep the lowest χ², continued if it stopped early.

    Non-finite fits never win; the best one is continued because its
    parameters are reported and every candidate starts from it.
    """
    res = search.fit(search.baseline_jobs)
    best = search.refine(min(res, key=lambda t: t[1] if np.isfinite(t[1]) else np.inf))
    return search.state_of(best, ())


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


def _score_candidate(search: _Search, cur: FitState, structure_p_of: Callable[[str], float], i: int, rs):
    """The :class:`Candidate` for effect ``i`` from its fits ``rs``, and the index of the fit it rests on.

    The best physical start is chosen (a fit on the unphysical side of an
    amplitude counts as no evidence, Δχ² = 0); the index is ``None`` when no
    start gave a finite fit.
    """
    e = search.testable[i]
    sts = [search.state_of(r, cur.active + (i,)) for r in rs]
    # parameters each fit spends on the effect: all of them, or the reduced form without its optional ones
    ks = [len(st.free) - len(cur.free) + e.n_data_params for st in sts]
    phys = [k for k, st in enumerate(sts) if e.physical(st.values[e.name])]
    pool = phys or range(len(sts))
    # the best form by BIC (for an effect without optional parameters: the lowest χ²)
    k = min(pool, key=lambda k: sts[k].chi2 + ks[k] * search.ln_n) if sts else None
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


class _Steps:
    """The step loop's state: the current fit, the states so far, what was found, partial matches, ambiguities."""

    def __init__(self, cur: _View):
        self.cur = cur
        self.states = [cur.state]
        self.found: list[str] = []
        self.steps: list[Step] = []
        self.partial: list[Candidate] = []
        self.ambiguous: list[tuple[str, str, float]] = []
        self.variogram_gap: float | None = None  # the gap the stop rule read under the variogram's covariance
        self.textures: list[dict | None] = []  # the texture measured again after each named effect (None: none)
        self.cur_search: _Search | None = None  # the search ``cur`` was fitted under (its variogram's second reading)

    def final_within(self, structure_p: float) -> bool:
        """The final gap within the noise (``P ≥ structure_p``) under the variogram's covariance, where it is read:
        the reading of the last refused leader's guard where there is one (the same covariance that refused it)."""
        v, rc = self.partial[-1].variogram if self.partial else None, getattr(self.cur_search, "recheck", None)
        dof = self.cur.state.dof
        got = (v.gap_before, _gap_p(v.gap_before * dof, dof)) if v is not None else rc and rc.gap_p(self.cur.state)
        if got is None or got[1] < structure_p:
            return False
        self.variogram_gap = got[0]
        return True

    def _noise_v(self, gap: float | None, st: FitState) -> bool:
        """The stop rule on the ``gap`` the variogram's covariance read for ``st``'s model (same dof)."""
        if gap is None or not _within_noise(dataclasses.replace(st, chi2=gap * st.dof)):
            return False
        self.variogram_gap = gap
        return True

    def search(self, search, max_steps, alpha, min_explained, structure_p, stop_within_noise, sample, say) -> bool:
        """Add effects until none is justified; True if it stopped because the gap is within the noise."""
        testable = search.testable
        self.cur_search = search
        for _ in range(max_steps):
            cur = self.cur
            # the stop rule under either of the texture's covariances (the variogram's read where it named the last)
            last = getattr(self.steps[-1].evidence.variogram, "gap", None) if self.steps else None  # None: not read
            if stop_within_noise and self.found and (_within_noise(cur.state) or self._noise_v(last, cur.state)):
                return True
            remaining = [i for i in range(len(testable)) if i not in cur.state.active]
            if not remaining:
                break
            say(f"step {len(self.steps) + 1}: testing {len(remaining)} candidate effects")
            ranked = _rank_candidates(search, cur, remaining)
            if ranked is None:
                break
            cands, by_effect = ranked
            win = cands[0]
            read = _reread(search, cur, win, by_effect, remaining)  # the covariance where the leader cannot hide
            if read is not None:
                search, cur, win, summary = read
                cands = [win if c.effect == win.effect else c for c in cands]  # the model averaging reads it there
            if not (win.delta_bic > 0 and win.p_value * len(remaining) < alpha):
                break
            if read is not None:  # the step stands under the new covariance: the model before it too
                self.states[-1] = cur.state
                self.textures.append(read[3])
            hold = None if search.holdout is None else search.holdout(cur.state, win.state, win.delta_chi2)
            if hold is not None:
                win = dataclasses.replace(win, holdout=hold)
                if not hold.passed:  # it fitted this capture's noise, not a signature both halves share
                    self.partial.append(win)
                    break
            if win.explained < min_explained and win.gap_p_after < structure_p:
                win = _rechecked(search, cur.state, win)
                v = win.variogram
                if stop_within_noise and self.found and v is not None and self._noise_v(v.gap_before, cur.state):
                    return True  # what is found leaves a gap the variogram's covariance calls noise
                if v is None or not v.names(win.k, search.ln_n, win.design_effect, min_explained, structure_p):
                    self.partial.append(win)
                    break
            self.ambiguous += [
                (win.effect, c.effect, win.delta_bic - c.delta_bic)
                for c in cands[1:]
                if c.effect in _CONFUSABLE.get(win.effect, ())
                and c.delta_bic > 0
                and win.delta_bic - c.delta_bic < _AMBIGUOUS_BIC
            ]
            i_win = next(i for i in remaining if testable[i].name == win.effect)
            new = search.residual_view(win.state if read is not None else by_effect[i_win])
            self.steps.append(make_step(testable[i_win], win, cands, cur, new, sample))
            self.found.append(testable[i_win].name)
            self.cur, self.cur_search = new, search
            self.states.append(new.state)
        return False


def _reread(search: _Search, cur: _View, win: Candidate, by_effect: dict, remaining: list[int]):
    """The step's leader and the model before it under the texture measured on the leader's residuals
    (:mod:`wardjax.effects._remeasure`), its evidence read again there: ``(search, cur, win, texture)``
    (``texture`` the new covariance's summary), or ``None`` where the texture is not carried, the leader
    has no fit, or a refit fails."""
    i = next((i for i in remaining if search.testable[i].name == win.effect), None)
    if search.remeasure is None or i is None or i not in by_effect or win.delta_chi2 <= 0:
        return None
    got = search.remeasure(cur.state, by_effect[i])
    if got is None:
        return None
    new, before, after, summary = got
    new.remeasure = search.remeasure
    e, view = search.testable[i], new.residual_view(before)
    dchi2 = max(before.chi2 - after.chi2, 0.0) if e.physical(after.values[e.name]) else 0.0
    cand = dataclasses.replace(
        win,
        delta_chi2=dchi2,
        delta_bic=dchi2 - win.k * new.ln_n,
        p_value=_lr_p(dchi2, e, win.k),
        explained=dchi2 / max(before.chi2 - before.dof, dchi2, 1e-300),
        state=after,
        gap_p_after=_gap_p(after.chi2, after.dof),
    )
    if new.cross is not None and cand.delta_bic > 0:
        cand = _deflated(new, view, cand, after)
    return new, view, cand, summary


def _baseline(model, data, testable, lm_steps: int, chunk: int, texture: bool):
    """The run's :class:`_Search`, its fitted baseline's :class:`_View` and the texture summary (or ``None``).

    With the texture to be carried, the baseline that measures it is fitted
    under an identity whitening: the same numbers as white noise and the same
    compiled program as every fit after it (one program to trace and compile
    per run, not two: ~3 s of tracing even with the compile cache warm).
    """
    carry = texture and model.kind == "scanline" and getattr(data, "kind", None) in ("ratio", "brdf")
    plain = _Search(model, identity_whitened(data) if carry else data, testable, lm_steps, chunk)
    cur = plain.residual_view(_fit_baseline(plain))

    def make(d):
        return _Search(model, d, testable, lm_steps, chunk)

    def textured(pred, rho, known=False):
        """The run's search with the texture measured on the residuals about ``pred``, and its summary (``known``:
        the texture was found on the baseline, so it is carried whatever its significance now)."""
        got = with_texture(data, pred, rho, significant=known)
        if got is None:  # no texture left: white noise, in the identity's layout (the run's compiled program)
            return _with_holdout(plain), None
        data_tex, tex, cross = got
        search = make(data_tex)
        search.cross = cross
        search.recheck = VariogramRecheck(make, data, pred, rho)
        return _with_holdout(search, tex.get("levels")), tex

    if not carry:
        return _with_holdout(plain), cur, None
    search, tex = textured(cur.pred, cur.rho)
    if tex is None:  # no texture: the plain data (the identity costs a dense product per evaluation)
        return _with_holdout(make(data)), cur, None
    search.remeasure = TextureRemeasure(plain, textured)
    return search, search.residual_view(_fit_baseline(search)), tex


def _with_holdout(search: _Search, levels: dict | None = None) -> _Search:
    """``search`` with the hold-out check of winners (:mod:`wardjax.effects._holdout`) where its data allow it."""
    if search.model.kind == "scanline" and Holdout.applicable(search.data):
        search.holdout = Holdout(search.sibling, search.data, levels)
    return search


# NumPy's linear algebra here is on many small matrices (a Cholesky of (C N)² per scanline, NNLS on a few
# columns): BLAS threads cost more in hand-over than they save, and on a busy machine their spinning made the
# texture's covariance 20× slower in wall time. JAX keeps its own threads.
@threadpool_limits.wrap(limits=1, user_api="blas")
def discover(
    model,
    data,
    *,
    effects: tuple[Effect, ...] | None = None,
    max_steps: int = 4,
    alpha: float = 0.01,
    min_explained: float = 0.5,
    structure_p: float = 1e-3,
    lm_steps: int = 20,
    chunk: int = 64,
    keep_plot_data: bool = True,
    seed: int = 0,
    texture: bool = False,
    stop_within_noise: bool = True,
    progress: Callable[[str], object] = lambda _: None,
) -> DiscoveryReport:
    """Find, name and add the effects the data need beyond ``model``.

    Parameters
    ----------
    model
        A :class:`~wardjax.effects.ScanlineModel` or :class:`~wardjax.effects.ThresholdModel`
        (anything with ``kind``, ``base_params``, ``residuals``, ``predict``,
        ``covariates``, ``n_profiled``).
    data
        Its observations (:func:`~wardjax.effects.scanline_data`,
        :func:`~wardjax.effects.threshold_data`), with the noise σ.
    effects
        Candidate effects; default the library's effects for ``model.kind``.
    max_steps
        At most this many effects are added.
    alpha
        Family-wise level of the likelihood-ratio test, Bonferroni-corrected
        over the candidates of a step.
    min_explained
        A winner must remove at least this fraction of the current excess
        ``χ² − dof``, unless it leaves no significant gap (see the module
        docstring).
    structure_p
        Level (Bonferroni over covariates) below which residual structure is
        reported as unexplained.
    lm_steps, chunk
        Levenberg–Marquardt step cap; fits solved together in one batch. A fit
        that decides (the baseline, the winner, close runners-up) is continued
        past the cap; the others are reported as lower bounds. 20 steps: most
        candidates converge within it, and the few that crawl (a second lobe
        or retroreflection far from the data) no longer cost the run.
    keep_plot_data
        Keep residuals and covariates (≤ 20,000 points) for the plots.
    seed
        Seeds the subsample kept for plots.
    stop_within_noise
        Stop rule: once an effect has closed the gap to within what noise
        alone gives, ``χ² − dof ≤ 2 √(2 dof)`` (two SDs of χ² under the noise
        model), nothing further is added and the report says "nothing further
        needed". The first effect is judged by its own evidence (ΔBIC and the
        LR test), which is more powerful than the gap: a γ mismatch that ρd,
        ρs and α absorb to Δχ² ≈ 30 leaves a baseline gap within the noise
        and is still named.
    texture
        Carry the probe's ρd texture in the model as a Gaussian process whose
        autocovariance is estimated from the baseline's residuals
        (:mod:`wardjax.effects._texture`), where it is significant.
    progress
        Told ``"step k: testing n candidate effects"`` as each step begins.

    Returns
    -------
    DiscoveryReport
        ``found`` (effect names, in order), ``gap`` (after each step, from the
        baseline), the steps with parameters ± σ and evidence, and the
        unexplained structure.
    """
    t0 = time.perf_counter()
    _check_inputs(model, data, alpha)
    testable, skipped = _split_library(model, data, effects)
    search, cur, tex = _baseline(model, data, testable, lm_steps, chunk, texture)
    sample = None
    if keep_plot_data:
        sample = plot_sampler(search.mask, int(search.mask.sum()) if search.mask is not None else cur.r.size, seed)
    run = _Steps(cur)
    stopped = run.search(search, max_steps, alpha, min_explained, structure_p, stop_within_noise, sample, progress)
    cur, states, found, steps, partial = run.cur, run.states, run.found, run.steps, run.partial
    mask, st = search.mask, cur.state
    # the verdict follows the gap (_verdict), under either of the texture's covariances, as the stop rule does
    within = stopped or _gap_p(st.chi2, st.dof) >= structure_p or run.final_within(structure_p)
    r_flat, covs = _flat(cur.r.reshape(np.shape(cur.pred)), mask), {k: _flat(x, mask) for k, x in cur.covs.items()}
    unexplained, structure = unexplained_structure(r_flat, covs, st, partial, structure_p, within)
    return DiscoveryReport(
        model=getattr(model, "title", type(model).__name__),
        model_kind=model.kind,
        n_obs=search.n_obs,
        n_profiled=search.n_prof,
        baseline=states[0],
        final=cur.state,
        found=found,
        gap=[s.gap for s in states],
        steps=steps,
        unexplained=unexplained,
        structure=structure,
        not_detectable=[(n, w) for n, w, c in skipped if c],
        not_testable=[(n, w) for n, w, c in skipped if not c],
        partial=[c.effect for c in partial],
        tested=[e.name for e in testable],
        seconds=time.perf_counter() - t0,
        ambiguous=run.ambiguous,
        settings={
            "alpha": alpha,
            "min_explained": min_explained,
            "structure_p": structure_p,
            "max_steps": max_steps,
            "criterion": "BIC+LR",
            "texture": tex,
            "texture_after": run.textures,
            "stop_rule": f"χ² − dof ≤ {_NOISE_Z:g}·√(2 dof)" if stop_within_noise else None,
            "stopped_within_noise": stopped,
            "variogram_gap": run.variogram_gap,
        },
    )
