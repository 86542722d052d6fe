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
import time
from collections.abc import Callable

import numpy as np
from threadpoolctl import threadpool_limits

from ._candidates import _deflated, _rank_candidates, _rechecked
from ._discrepancy import discrepancy
from ._effect import Effect
from ._evidence import _NOISE_Z, _gap_p, _lr_p, _within_noise
from ._holdout import Holdout
from ._inputs import _check_inputs, _split_library
from ._recheck import VariogramRecheck
from ._remeasure import TextureRemeasure
from ._report import Candidate, DiscoveryReport, FitState, Step
from ._search import _Search, _View
from ._standard_sigma import standard_deflated, widened_report, with_standard
from ._step_record import flat as _flat
from ._step_record import make_step, plot_sampler
from ._structure import _binned_test
from ._texture_term import identity_whitened, with_texture
from ._verdict import unexplained_structure

__all__ = ["discover"]

# An effect named on a gap that stays beyond the noise is taken back where, fitted, it leaves more than this share of
# the binned structure (χ² − bins) along its own telling covariate (``_Steps.unsigned``). Measured on scanline draws
# of the bench's geometry: a present effect leaves 0.0–0.1 % (anisotropy beside a 1–3 % stripe along the scanlines,
# gaps 1.26–3.4 after it); an effect standing in for one outside the library 17–41 % (room light read as anisotropy
# on a Radiance capture, 17 %; a tone curve's shoulder read as retroreflection, 22–41 %).
_SIGNATURE_LEFT = 0.1
# ... and only where what is left lies along that covariate: its binned χ² more than this times the median of the
# other covariates'. A misfit of the model elsewhere projects onto every covariate alike: on CUReT samples, whose
# Ward misfit dwarfs any effect (gaps 15–30 after it), a Fresnel rise or retroreflection left 13–42 % of its
# covariate's structure at 0.8–1.2 times the others'; room light read as anisotropy left 12 times the others'.
_ALONG = 3.0
_AMBIGUOUS_BIC = 6.0  # a confusable runner-up within this ΔBIC of the winner is named too (Kass & Raftery: < 6)
# effects whose signatures one capture may not tell apart: a lamp field follows image position, anisotropy the
# half-vector azimuth, the Fresnel rise the incidence angle, and across one capture's scanlines they covary (on
# textured captures the Fresnel rise, one parameter, took the ramp across the image); a camera response compresses
# the highlight against each channel's diffuse floor, which a per-channel specular scale mimics; a mis-declared
# encoding lifts the darks, as light from the room in the lit frame does; veiling glare is that light plus a share
# of the frame spread wide, which a uniform veil alone approaches
_CONFUSABLE = {
    "illumination_gradient": ("anisotropy", "fresnel"),
    "anisotropy": ("illumination_gradient",),
    "fresnel": ("illumination_gradient",),
    "gamma": ("coloured_specular",),
    "coloured_specular": ("gamma",),
    "ambient": ("encoding", "glare"),
    "encoding": ("ambient",),
    "glare": ("ambient",),
}
# where the step's leader loses its evidence under the texture measured on its own residuals (``_reread``), this
# many runners-up are read there too, in rank order: a leader that nests another (glare nests the veil) may rank
# first only by taking texture the re-measured covariance then holds
_REREAD_RUNNERS_UP = 2


def _fit_baseline(search: _Search) -> FitState:
    """Fit the model without effects from all its starts and keep the lowest χ², continued if it stopped early.

    Non-finite fits never win; the best one is continued because its
    parameters are reported and every candidate starts from it.
    """
    res = search.fit(search.baseline_jobs)
    best = search.refine(min(res, key=lambda t: t[1] if np.isfinite(t[1]) else np.inf))
    return search.state_of(best, ())


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

    def unsigned(self, structure_p: float, within: bool) -> None:
        """Where a gap beyond the noise remains (not ``within``), take back the last named effect while the final
        residuals still follow its own telling covariate: significant there (binned test at ``structure_p`` over the
        covariates, as the verdict's), more than :data:`_SIGNATURE_LEFT` of that covariate's structure before it
        was fitted, and concentrated there (:data:`_ALONG`).

        An effect that is present, once fitted, leaves next to nothing against the covariate its signature is
        written in (the half-vector azimuth for anisotropy, the predicted level for a response), even with an
        effect outside the library beside it: that effect's residual only projects onto the covariate, as onto
        every other (:data:`_ALONG`). Where a sizeable share of the structure along its own covariate is left
        after it is fitted, and more there than along the others, the effect took part of a discrepancy whose
        form is not its own: it is reported as a partial match, not named, and the model before it is the final
        one.
        """
        search = self.cur_search
        while not within and self.found and search is not None:
            cur, name = self.cur, self.found[-1]
            covariate = next(e for e in search.testable if e.name == name).covariate
            if covariate not in cur.covs:
                return
            r_after = _flat(cur.r.reshape(np.shape(cur.pred)), search.mask)
            tests = {k: _binned_test(r_after, _flat(x, search.mask)) for k, x in cur.covs.items()}
            chi2, bins, p, *_ = tests[covariate]
            others = float(np.median([t[0] for k, t in tests.items() if k != covariate] or [np.inf]))
            if not (p < structure_p / max(len(tests), 1) and chi2 > _ALONG * others):
                return
            before = search.residual_view(self.states[-2])  # only where the cheap tests did not settle it
            r_before = _flat(before.r.reshape(np.shape(before.pred)), search.mask)
            chi2_0, bins_0, *_ = _binned_test(r_before, _flat(before.covs[covariate], search.mask))
            left = (chi2 - bins) / max(chi2_0 - bins_0, 1e-300)
            if not left > _SIGNATURE_LEFT:
                return
            step = self.steps.pop()
            self.found.pop()
            self.states.pop()
            self.partial.append(dataclasses.replace(step.evidence, signature=(covariate, chi2, bins, p, left)))
            self.ambiguous = [a for a in self.ambiguous if a[0] != name]
            self.cur = before

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
            search0, cur0 = search, cur  # the step's covariance before any re-measurement
            win, ranked_bic = cands[0], cands[0].delta_bic  # ΔBIC on the runners-up's scale (one covariance)
            read = _reread(search, cur, win, by_effect, remaining)  # the covariance where the leader cannot hide
            if read is not None and not _justified(read[2], len(remaining), alpha):
                # the leader's evidence was the covariance's: the runners-up read where they cannot hide either;
                # one that stands there takes the step, the leader entered with its evidence there (neither named
                # beside it nor averaged over)
                for c in cands[1 : _REREAD_RUNNERS_UP + 1]:
                    other = None if not c.delta_bic > 0 else _reread(search, cur, c, by_effect, remaining)
                    if other is not None and _justified(other[2], len(remaining), alpha):
                        cands = [c, read[2], *(x for x in cands[1:] if x is not c)]
                        read, win, ranked_bic = other, c, c.delta_bic
                        break
            if read is not None:
                search, cur, win, summary = read
                # the model averaging reads its fit there, weighed on the runners-up's scale
                cands = [dataclasses.replace(win, delta_bic=ranked_bic) if c.effect == win.effect else c for c in cands]
            # the smoothed standard's shared noise (wardjax.effects._standard_sigma)
            d_texture = win.design_effect
            win = standard_deflated(search, win)
            if not _justified(win, len(remaining), alpha):
                break
            # a leader that nests a runner-up (glare nests the veil) must pay for its extra parameters on their own
            extra = _extra_bic(search, win, d_texture)
            inner = _nested_runner_up(search, win, cands) if extra is not None and extra <= 0 else None
            if inner is not None and extra is not None:
                other = _reread(search0, cur0, inner, by_effect, remaining)
                in_search, in_read = (search0, inner) if other is None else (other[0], other[2])
                in_win = standard_deflated(in_search, in_read)
                if _justified(in_win, len(remaining), alpha):
                    # the reduced form takes the step; the leader's evidence is its own and its extra parameters'
                    fallen = dataclasses.replace(win, delta_bic=inner.delta_bic + extra)
                    rest = (c for c in cands if c.effect not in (inner.effect, win.effect))
                    cands = [dataclasses.replace(in_read, delta_bic=inner.delta_bic), fallen, *rest]
                    read, win, ranked_bic = other, in_win, inner.delta_bic
                    search, cur = (search0, cur0) if other is None else other[:2]
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
            if read is not None:  # the step stands under the new covariance: the model before it too
                self.states[-1] = cur.state
                self.textures.append(read[3])
            self.ambiguous += [
                (win.effect, c.effect, margin)
                for c in cands[1:]
                if c.effect in _CONFUSABLE.get(win.effect, ())
                and c.delta_bic > 0
                and (margin := _margin(search, win, c, ranked_bic, extra)) < _AMBIGUOUS_BIC
            ]
            i_win = next(i for i in remaining if testable[i].name == win.effect)
            new = search.residual_view(win.state if read is not None else by_effect[i_win])
            self.steps.append(make_step(testable[i_win], win, cands, cur, new, sample))
            self.found.append(testable[i_win].name)
            self.cur, self.cur_search = new, search
            self.states.append(new.state)
        return False


def _nests(search: _Search, name: str) -> str | None:
    """The effect ``name``'s reduced form (:attr:`~wardjax.effects._effect.Effect.nests`), or ``None``."""
    nests = next(t for t in search.testable if t.name == name).nests
    return None if nests is None else nests[0]


def _extra_bic(search: _Search, win: Candidate, d_texture: float) -> float | None:
    """ΔBIC of ``win``'s extra parameters over the effect it nests (:attr:`~wardjax.effects._effect.Effect.nests`),
    on their own: their Wald χ² from their absent values under the covariance the effect's evidence is read on
    (the smoothed standard's lags in it, :func:`~wardjax.effects._standard_sigma.with_standard`, and divided by the
    texture's design effect between scanlines ``d_texture``), less ``ln n`` per parameter. ``None`` where ``win``
    nests no effect, has no fit or no finite covariance, or holds its extra parameters."""
    e = next(t for t in search.testable if t.name == win.effect)
    if e.nests is None or win.state is None:
        return None
    st = with_standard(search, win.state)
    own = {p.name: (j, p) for j, p in zip(search.layout.slices[e.name], e.params)}
    extra = [own[n] for n in e.nests[1] if own[n][0] in st.free]
    if not extra:
        return None
    idx = [j for j, _ in extra]
    d = np.array([st.u[j] - p.to_u(p.absent) for j, p in extra])
    try:
        chi2 = float(d @ np.linalg.solve(np.asarray(st.cov)[np.ix_(idx, idx)], d)) / max(d_texture, 1.0)
    except np.linalg.LinAlgError:
        return None
    return chi2 - len(idx) * search.ln_n if np.isfinite(chi2) else None


def _nested_runner_up(search: _Search, win: Candidate, cands: list[Candidate]) -> Candidate | None:
    """The runner-up of the effect ``win`` nests, where it has a fit, is physical and is worth its parameters."""
    inner = _nests(search, win.effect)
    return next(
        (c for c in cands[1:] if c.effect == inner and c.state is not None and c.physical and c.delta_bic > 0), None
    )


def _margin(search: _Search, win: Candidate, c: Candidate, ranked_bic: float, extra: float | None) -> float:
    """How far ``win`` leads the runner-up ``c`` for the "not told apart" rule: their ΔBICs' difference; for a nested
    pair the extra parameters' own ΔBIC (``extra``, :func:`_extra_bic`), and never where ``c`` nests ``win`` (the
    extra parameters did not pay: the reduced form stands alone)."""
    if _nests(search, c.effect) == win.effect:
        return np.inf
    if extra is not None and _nests(search, win.effect) == c.effect:
        return extra
    return ranked_bic - c.delta_bic


def _justified(win: Candidate, tested: int, alpha: float) -> bool:
    """Whether a step's candidate is worth its parameters and significant among the ``tested`` ones (Bonferroni)."""
    return win.delta_bic > 0 and win.p_value * tested < alpha


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
    physical = e.physical(after.values[e.name])
    dchi2 = max(before.chi2 - after.chi2, 0.0) if physical else 0.0
    cand = dataclasses.replace(
        win,
        physical=physical,
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
    """The run's :class:`_Search`, its fitted baseline's :class:`_View` and the texture summary (``None`` where no
    texture is found; with ``refused`` where the dark frame refutes it, the noise then white).

    With the texture to be carried, the baseline that measures it is fitted
    under an identity whitening: the same numbers as white noise and the same
    compiled program as every fit after it (one program to trace and compile
    per run, not two: ~3 s of tracing even with the compile cache warm). The
    baseline under the texture's covariance is then refitted from that fit
    (its multi-start chose the basin), not from every start again. Where no
    texture is found, or the dark frame refutes it, the run stays in the
    identity's layout: its dense product per evaluation cost nothing
    measurable on a 320 × 240 capture, the plain layout's second program
    20 s of a cold run's compiling (56 → 38 s).
    """
    carry = texture and model.kind == "scanline" and getattr(data, "kind", None) in ("ratio", "brdf")
    plain = _Search(model, identity_whitened(data) if carry else data, testable, lm_steps, chunk)
    plain.warm_view()  # its program compiles while the baseline's fits compile theirs
    cur = plain.residual_view(_fit_baseline(plain))

    def make(d):
        return _Search(model, d, testable, lm_steps, chunk)

    def textured(pred, rho):
        """The run's search with the texture measured on the residuals about ``pred``, and its summary (white
        noise, in the identity's layout, where the residuals show no significant texture)."""
        got = with_texture(data, pred, rho)
        if got is None or got.refused:  # none left (or refuted): white noise, in the identity's layout
            return _with_holdout(plain), None if got is None else got.summary
        tex = got.summary
        search = make(got.data)
        search.cross = got.cross
        search.recheck = VariogramRecheck(make, data, pred, rho)
        return _with_holdout(search, tex.get("levels")), tex

    if not carry:
        return _with_holdout(plain), cur, None
    search, tex = textured(cur.pred, cur.rho)
    if tex is None or "refused" in tex:  # white noise in the identity's layout, the program the baseline compiled
        return search, cur, tex
    search.remeasure = TextureRemeasure(plain, textured)
    # from the white-noise baseline, where the multi-start found its basin: one start, not all of them again
    return search, search.residual_view(TextureRemeasure.refit(search, cur.state)), tex


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
    keep_plot_data, seed
        Keep residuals and covariates (≤ 20,000 points, a subsample seeded by ``seed``) for the plots.
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
    n_plot = int(search.mask.sum()) if search.mask is not None else cur.r.size
    sample = plot_sampler(search.mask, n_plot, seed) if keep_plot_data else None
    run = _Steps(cur)
    stopped = run.search(search, max_steps, alpha, min_explained, structure_p, stop_within_noise, sample, progress)
    # the verdict follows the gap (_verdict), under either of the texture's covariances, as the stop rule does
    within = stopped or _gap_p(run.cur.state.chi2, run.cur.state.dof) >= structure_p or run.final_within(structure_p)
    run.unsigned(structure_p, within)  # a gap remains: an effect named on it must have matched its own signature
    cur, states, found, steps, partial = run.cur, run.states, run.found, run.steps, run.partial
    unexplained, structure, disc = _final_reading(run, search.mask, structure_p, within)
    base_st, final_st, steps = widened_report(search, run.cur_search or search, states[0], cur.state, steps)
    return DiscoveryReport(
        model=getattr(model, "title", type(model).__name__),
        model_kind=model.kind,
        n_obs=search.n_obs,
        n_profiled=search.n_prof,
        baseline=base_st,
        final=final_st,
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
        discrepancy=disc,
    )


def _final_reading(run: _Steps, mask, structure_p: float, within: bool):
    """The verdict's lines and binned tests for the final model (:mod:`wardjax.effects._verdict`), and where a gap
    beyond the noise remains (not ``within``) on scanline data the discrepancy term's reading
    (:mod:`wardjax.effects._discrepancy`), else ``None``: ``(unexplained, structure, discrepancy)``."""
    cur = run.cur
    r_flat, covs = _flat(cur.r.reshape(np.shape(cur.pred)), mask), {k: _flat(x, mask) for k, x in cur.covs.items()}
    unexplained, structure = unexplained_structure(r_flat, covs, cur.state, run.partial, structure_p, within)
    if within or run.cur_search is None or run.cur_search.model.kind != "scanline":
        return unexplained, structure, None
    return unexplained, structure, discrepancy(run.cur_search, cur.state, r_flat, covs, structure)
