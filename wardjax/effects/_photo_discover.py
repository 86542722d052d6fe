"""``discover_photo``: the effects a photograph capture needs beyond the paper's model, each on its evidence.

Algorithm (the standard of :func:`wardjax.effects.discover`)
    1. Fit the baseline: ρd per problem (a pixel, or a block of pixels that
       share it), one lobe shared by the sample. The *gap* is ``χ²/dof``
       against the pixel noise model of the capture.
    2. Fit the current model plus each candidate not yet added:
       ``vignetting`` and ``flash_falloff`` (radial gains, :mod:`._photo_model`),
       ``varying_specular`` (a lobe per material cluster) and ``normals`` (a
       normal per problem), :mod:`._photo_states`.
    3. Score each by ``ΔBIC = Δχ² − k ln N`` (``k`` its parameters: 2, 1,
       three per extra cluster — ρs, α and its share —, two per problem that
       keeps a normal) and the likelihood-ratio p-value ``P(χ²_k ≥ Δχ²)``;
       a candidate that lowers χ² at least as much with no more parameters
       goes first (``_evidence._dominant_first``).
    4. The best candidate with ``ΔBIC > 0`` and a p-value below ``alpha``
       (Bonferroni over the step's candidates) must then predict data it was
       not fitted to: fitted on one half, it must lower χ² on the other half
       (both ways; the held-out gain at least ``HOLDOUT_SHARE`` of its Δχ²,
       :mod:`wardjax.effects._holdout`). The halves are the left and right
       halves of the image, or, for effects with parameters per problem
       (normals), alternate views of every problem (photos alternate, a
       block's pixels alternate as a checkerboard). A candidate that fails
       is reported as not predicting, and the next one is tried.
       Once the model carries structure (lobes per cluster, normals), a
       radial candidate is scored and held out with that structure held
       as fitted (:mod:`._photo_held`, halves of alternate views) and only
       the winner is refitted in full; a step whose model has a lobe no
       material has (:mod:`._photo_checks`) tries the radial candidates
       first, on the shared lobe held within ``α ≤ 1``, ``ρs ≤ 1``. With
       one photo ``normals`` is not tried (not identifiable).
    5. Add it, repeat until no candidate earns its place, ``max_steps``, or
       the gap is within the noise (``χ² − dof ≤ 2 √(2 dof)``, the stop rule
       of :func:`~wardjax.effects.discover`).

Vignetting and flash falloff are both radial; with the lamp at the lens
(a phone's flash) the lens and the lamp see every point at nearly the same
angle, and one photo cannot tell them apart: when both are supported the
report names the winner and says so.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable, Sequence
from typing import NamedTuple

import numpy as np
from scipy.special import chdtrc

from ._evidence import _NOISE_Z, _dominant_first, _gap_p
from ._holdout import HOLDOUT_SHARE
from ._photo_checks import not_identifiable, residual_where, unphysical
from ._photo_held import HeldStructure, chi2_gains_held, fit_gains_held
from ._photo_model import RADIAL, PhotoData
from ._photo_report import PhotoDiscoveryReport, PhotoStep, lobes_table
from ._photo_states import NORMALS, STRUCTURAL, PhotoState, StateFit, fit_state, held_chi2
from ._report import Candidate, HoldoutRead

__all__ = ["PHOTO_EFFECTS", "discover_photo"]

PHOTO_EFFECTS = (*RADIAL, *STRUCTURAL)
_COLOCATED = 0.05  # lamp–lens distance over the camera's distance below which the two radial effects are one
_AMBIGUOUS_BIC = 6.0  # as discover's: a runner-up within this ΔBIC is named beside the winner
_MIN_HALF_OBS = 50  # each half of a hold-out at least this many observations


def _within_noise(fit: StateFit) -> bool:
    return bool(fit.chi2 - fit.dof <= _NOISE_Z * math.sqrt(2.0 * fit.dof))


def _k(name: str, fit: StateFit) -> int:
    """The parameters a candidate spends (counted in ΔBIC and the LR test)."""
    if name in RADIAL:
        return len(RADIAL[name].params)
    ev = getattr(fit.pixel, "evidence", {})
    if name == "varying_specular":
        return 3 * (int(ev.get("clusters", {}).get("n_clusters", 1)) - 1)
    if name == "height_field":  # a height per problem, less the constant
        return int(np.shape(getattr(fit.pixel, "rho_d", ()))[0]) - 1
    return 2 * int(ev.get("normals", {}).get("n_pixels", 0))


def _candidate(name: str, k: int, dchi2: float, cur: StateFit, chi2_new: float, ln_n: float) -> Candidate:
    p = float(chdtrc(k, dchi2)) if k > 0 and dchi2 > 0 else 1.0
    excess = max(cur.chi2 - cur.dof, 1e-300)
    return Candidate(
        effect=name,
        k=k,
        delta_chi2=float(dchi2),
        delta_bic=float(dchi2 - k * ln_n),
        p_value=p,
        explained=float(dchi2 / excess),
        structure_p=math.nan,
        physical=True,
        gap_p_after=_gap_p(chi2_new, max(cur.dof - k, 1)),
    )


def _score(name: str, state: PhotoState, cur: StateFit, ref: Callable[[], StateFit], data: PhotoData, ln_n: float):
    """The candidate ``name`` on top of ``state``: its :class:`Candidate` and fit."""
    new = fit_state(state.plus(name), data, start=cur.shared, normals_from=_normals_held(name, state, cur))
    base = ref() if name in STRUCTURAL and cur.pixel is None else cur  # compared on the same fitter's footing
    k = _k(name, new)
    dchi2 = base.chi2 - new.chi2 if k > 0 else 0.0
    if name == "varying_specular" and k > 0:  # the mixture's deviance, which prices each problem's choice of lobe
        bic = getattr(new.pixel, "evidence", {})["clusters"]["bic"]
        dchi2 = bic[1] - bic[k // 3 + 1] + k * ln_n
    return _candidate(name, k, dchi2, cur, new.chi2, ln_n), new


def _normals_held(name: str, state: PhotoState, cur: StateFit) -> StateFit | None:
    """The fit whose normals a candidate is scored at: lobes per cluster on a model with normals are fitted
    at the current normals (refitted in full only if chosen), as radial gains on a held structure."""
    return cur if name == "varying_specular" and state.normals and cur.pixel is not None else None


class _Held(NamedTuple):
    """The current structure held (:mod:`._photo_held`) and the current gains refitted on it."""

    structure: HeldStructure
    base: object  # SharedFit


def refit_with_structure(state: PhotoState, data: PhotoData, start, gains_fit, rounds: int = 3) -> StateFit:
    """A radial winner scored on a held structure, refitted in full: the structure (lobes, their count, normals)
    at the held gains, then the gains on that new structure, alternately, while χ² falls; the best fit kept.

    The gains of the held fit were made with the old structure, which had absorbed part of the gain (lobes per
    cluster fitting a radial falloff, say); once the structure is refitted without that part (fewer clusters),
    the gains must follow it, or the refit keeps a gain fitted for a structure it no longer has."""
    best = fit_state(state, data, start=start, gains_from=gains_fit)
    for _ in range(rounds - 1):
        gains_fit = fit_gains_held(state.radial, data, HeldStructure.of(best.pixel, data), best.shared)
        new = fit_state(state, data, start=start, gains_from=gains_fit)
        if new.chi2 >= best.chi2 * (1 - 1e-6):
            break
        best = new
    return best


def _score_held(name: str, state: PhotoState, cur: StateFit, held: _Held, data: PhotoData, ln_n: float):
    """A radial candidate on the current structure held: its :class:`Candidate` and its gains (a ``SharedFit``)."""
    names = (*state.radial, name)
    new = fit_gains_held(names, data, held.structure, cur.shared)
    k = len(RADIAL[name].params)
    return _candidate(name, k, held.base.chi2 - new.chi2, cur, new.chi2, ln_n), new  # pyright: ignore[reportAttributeAccessIssue]


def _halves(state: PhotoState, data: PhotoData, views: bool = False) -> tuple[np.ndarray, np.ndarray] | None:
    """The hold-out's halves ``(P, V)``: image halves, or alternate views where parameters are per problem
    (or ``views``: where the structure is held as fitted to every view, so that each half spans the image)."""
    if state.normals or views:
        a = data.fold == 0
    else:
        a = np.broadcast_to((data.column < 0.5)[:, None], data.fold.shape)
    b = ~a
    seen = data.w.any(-1)
    if min(int(np.sum(seen & a)), int(np.sum(seen & b))) < _MIN_HALF_OBS:
        return None
    return a, b


def holdout(
    cur: PhotoState,
    new: PhotoState,
    data: PhotoData,
    dchi2: float,
    start,
    held: _Held | None = None,
    normals_from: StateFit | None = None,
) -> HoldoutRead | None:
    """Both models fitted on each half predict the other; ``None`` where the data have no two halves.

    With ``held`` (a radial candidate on a model with structure) the structure stays as fitted to all the
    data and only the gains are fitted on each half (:mod:`._photo_held`); the halves are then alternate
    views, each spanning the image: image halves would ask the gains fitted on one side to make up for
    the held structure's errors on the other. With ``normals_from`` both models are fitted at its normals.
    """
    halves = _halves(new, data, views=held is not None)
    if halves is None:
        return None
    gain = 0.0
    for train, test in (halves, halves[::-1]):
        if held is not None:
            hs = held.structure
            fc = fit_gains_held(cur.radial, data, hs, start, train)
            fn = fit_gains_held(new.radial, data, hs, start, train)
            g = chi2_gains_held(fc, cur.radial, data, hs, test) - chi2_gains_held(fn, new.radial, data, hs, test)
        else:
            fc = fit_state(cur, data, train, start=start, pixels=bool(new.structural), normals_from=normals_from)
            fn = fit_state(new, data, train, start=start, normals_from=normals_from)
            g = held_chi2(fc, cur, data, test, train) - held_chi2(fn, new, data, test, train)
        if not math.isfinite(g):
            return None
        gain += g
    share = gain / max(dchi2, 1e-300)
    return HoldoutRead(float(gain), float(share), bool(gain > 0 and share >= HOLDOUT_SHARE))


def _ambiguous(win: Candidate, cands: list[Candidate], data: PhotoData) -> list[tuple[str, str, float]]:
    if win.effect not in RADIAL:
        return []
    return [
        (win.effect, c.effect, win.delta_bic - c.delta_bic)
        for c in cands
        if c.effect in RADIAL
        and c.effect != win.effect
        and c.delta_bic > 0
        and (win.delta_bic - c.delta_bic < _AMBIGUOUS_BIC or data.lamp_offset < _COLOCATED)
    ]


def _step_params(name: str, fit: StateFit) -> tuple[dict, dict]:
    if name in RADIAL:
        names = RADIAL[name].params
        return dict(zip(names, fit.shared.effects[name])), dict(zip(names, fit.shared.sigma[name]))
    ev = getattr(fit.pixel, "evidence", {})
    if name == "varying_specular":
        return {"n_clusters": ev.get("clusters", {}).get("n_clusters", 1)}, {}
    return {"pixels_with_normal": ev.get("normals", {}).get("n_pixels", 0)}, {}


def discover_photo(
    data: PhotoData,
    *,
    candidates: Sequence[str] | None = None,
    max_steps: int = 4,
    alpha: float = 0.01,
    name: str = "",
    progress: Callable[[str], object] = lambda _: None,
) -> PhotoDiscoveryReport:
    """Find, name and add the effects a photograph capture needs beyond the paper's model.

    Parameters
    ----------
    data
        The capture's problems (``wardjax.run.photo_data`` builds them from a loaded capture).
    candidates
        Effects to try, from ``PHOTO_EFFECTS`` (default all).
    max_steps
        At most this many effects are added.
    alpha
        Family-wise level of the likelihood-ratio test, Bonferroni-corrected over a step's candidates.
    name
        The capture's name, for the report.
    progress
        Called with a line per stage.
    """
    names = tuple(PHOTO_EFFECTS if candidates is None else candidates)
    bad = [n for n in names if n not in PHOTO_EFFECTS]
    if bad:
        raise ValueError(f"unknown photo effects {bad}; expected names from {list(PHOTO_EFFECTS)}")
    if data.n_obs < 10:
        raise ValueError(f"{name or 'the capture'} has {data.n_obs} usable observations; discovery needs 10 or more")
    t0 = time.time()
    ln_n = math.log(max(data.n_obs, 2))
    skipped = {n: why for n, why in not_identifiable(data).items() if n in names}
    names = tuple(n for n in names if n not in skipped)
    state, cur = PhotoState(), fit_state(PhotoState(), data)
    baseline, gaps, steps, partial, ambiguous, broken, refused = cur, [cur.gap], [], [], [], [], []
    for _ in range(max_steps):
        if steps and _within_noise(cur):
            break
        remaining = [n for n in names if n not in (*state.radial, *state.structural)]
        if state.normals:  # a normal per problem is in the model, free or on a height field: not the other
            remaining = [n for n in remaining if n not in NORMALS]
        if not remaining:
            break
        why = unphysical(cur, state, data)
        if why:
            progress(f"step {len(steps) + 1}: the lobe is no material's ({why}); radial effects first, lobe bounded")
            if not (state.structural or state.bounded):  # refit with the lobe held physical: no lobe to build on
                before, state = cur, dataclasses.replace(state, bounded=True)
                cur = fit_state(state, data, start=cur.shared)
                broken.append({"step": len(steps), "why": why, "gap": before.gap, "gap_bounded": cur.gap})
            else:
                broken.append({"step": len(steps), "why": why, "gap": cur.gap, "gap_bounded": None})
        found = _step(state, cur, remaining, bool(why), data, ln_n, alpha, len(steps) + 1, progress)
        partial += found.partial
        refused += found.refused
        chosen, new = found.chosen, found.fit
        if chosen is None or new is None:
            if state.bounded and not steps:  # nothing found on the bounded lobe: the baseline as fitted stands
                state, cur = PhotoState(), baseline
            break
        ambiguous += _ambiguous(chosen, found.candidates, data)
        params, sigma = _step_params(chosen.effect, new)
        title = RADIAL[chosen.effect].title if chosen.effect in RADIAL else STRUCTURAL[chosen.effect]
        steps.append(PhotoStep(chosen.effect, title, params, sigma, chosen, found.candidates, cur.gap, new.gap))
        state, cur = state.plus(chosen.effect), new
        gaps.append(cur.gap)
    progress("where the residual lives")
    return PhotoDiscoveryReport(
        name=name,
        n_obs=data.n_obs,
        grid=data.grid,
        found=[s.effect for s in steps],
        gap=gaps,
        steps=steps,
        partial=partial,
        ambiguous=ambiguous,
        baseline={"rho_s": baseline.shared.rho_s, "alpha": baseline.shared.alpha, "chi2": baseline.chi2},
        final_chi2=cur.chi2,
        final_dof=cur.dof,
        within_noise=_within_noise(cur),
        lobes=lobes_table(cur),
        labels=np.asarray(getattr(cur.pixel, "labels", np.zeros(data.f.shape[0], int))),
        lamp_offset=data.lamp_offset,
        settings={"alpha": alpha, "max_steps": max_steps, "candidates": list(names), "holdout_share": HOLDOUT_SHARE},
        seconds=time.time() - t0,
        n_photos=data.n_photos,
        not_identifiable=skipped,
        unphysical=broken,
        where=residual_where(cur, state, data),
        refused=refused,
    )


class _Found(NamedTuple):
    chosen: Candidate | None
    fit: StateFit | None
    candidates: list
    partial: list
    refused: list


def _step(state, cur, remaining, radial_first, data, ln_n, alpha, i, progress) -> _Found:
    """One step: score the candidates (the radial ones alone first when ``radial_first``), the best that passes
    its evidence and hold-out chosen, refitted in full where it was scored on a held structure."""
    held = None
    if state.structural:
        hs = HeldStructure.of(cur.pixel, data)
        held = _Held(hs, fit_gains_held(state.radial, data, hs, cur.shared))
    groups = [[n for n in remaining if n in RADIAL], [n for n in remaining if n not in RADIAL]]
    groups = [g for g in groups if g] if radial_first else [remaining]
    ref: list[StateFit] = []

    def on_pixels() -> StateFit:
        if not ref:
            ref.append(fit_state(state, data, pixels=True))
        return ref[0]

    all_cands, partial, refused = [], [], []
    for group in groups:
        progress(f"step {i}: testing {len(group)} candidate effects ({', '.join(group)})")
        scored = {}
        for n in group:
            if held is not None and n in RADIAL:
                c, fit = _score_held(n, state, cur, held, data, ln_n)
            else:
                c, fit = _score(n, state, cur, on_pixels, data, ln_n)
            scored[n] = (c, fit)
        cands = _dominant_first(sorted((c for c, _ in scored.values()), key=lambda c: -c.delta_bic))
        all_cands += cands
        for c in cands:
            if not (c.delta_bic > 0 and c.p_value * len(remaining) < alpha):
                break
            progress(f"step {i}: hold-out check of {c.effect}")
            on_held = held if c.effect in RADIAL else None
            normals_held = _normals_held(c.effect, state, cur)
            hold = holdout(state, state.plus(c.effect), data, c.delta_chi2, cur.shared, on_held, normals_held)
            c = dataclasses.replace(c, holdout=hold)
            if hold is not None and not hold.passed:
                partial.append(c)
                continue
            fit = scored[c.effect][1]
            if on_held is not None:
                progress(f"step {i}: {c.effect} refitted with the structure")
                fit = refit_with_structure(state.plus(c.effect), data, cur.shared, fit)
                # the structure refitted (its count chosen anew) may lose what the gain won on it held: the effect
                # is added only if the refit lowers the gap (χ²/dof), what the steps report
                if fit.gap >= cur.gap:
                    progress(f"step {i}: {c.effect} refitted with the structure does not lower the gap; not added")
                    refused.append(_refused(i, c, cur, fit))
                    continue
            elif normals_held is not None:
                progress(f"step {i}: {c.effect} refitted with its normals")
                fit = fit_state(state.plus(c.effect), data, start=cur.shared)
            return _Found(c, fit, all_cands, partial, refused)
    return _Found(None, None, all_cands, partial, refused)


def _refused(i: int, c: Candidate, cur: StateFit, fit: StateFit) -> dict:
    """A radial effect that passed its evidence and hold-out on the held structure, refused because the
    structure refitted with it does not lower the gap: its step, why, the gap before and after, its parameters."""
    sd = fit.shared.sigma.get(c.effect, ())
    return {
        "step": i,
        "effect": c.effect,
        "why": "refitted with the structure it does not lower the gap (χ²/dof)",
        "gap_before": cur.gap,
        "gap_after": fit.gap,
        "delta_bic_held": c.delta_bic,
        "params": dict(zip(RADIAL[c.effect].params, fit.shared.effects.get(c.effect, ()))),
        "stderr": dict(zip(RADIAL[c.effect].params, sd)),
    }
