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

import numpy as np
from scipy.special import chdtrc

from ._evidence import _NOISE_Z, _dominant_first, _gap_p
from ._holdout import HOLDOUT_SHARE
from ._photo_model import RADIAL, PhotoData
from ._photo_report import PhotoDiscoveryReport, PhotoStep, lobes_table
from ._photo_states import STRUCTURAL, PhotoState, StateFit, fit_state, held_chi2
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
    return 2 * int(ev.get("normals", {}).get("n_pixels", 0))


def _score(name: str, state: PhotoState, cur: StateFit, ref: Callable[[], StateFit], data: PhotoData, ln_n: float):
    """The candidate ``name`` on top of ``state``: its :class:`Candidate` and fit."""
    new = fit_state(state.plus(name), data, start=cur.shared)
    base = ref() if name in STRUCTURAL and cur.pixel is None else cur  # compared on the same fitter's footing
    k = _k(name, new)
    dchi2 = base.chi2 - new.chi2 if k > 0 else 0.0
    if name == "varying_specular" and k > 0:  # the mixture's deviance, which prices each problem's choice of lobe
        bic = getattr(new.pixel, "evidence", {})["clusters"]["bic"]
        dchi2 = bic[1] - bic[k // 3 + 1] + k * ln_n
    p = float(chdtrc(k, dchi2)) if k > 0 and dchi2 > 0 else 1.0
    excess = max(cur.chi2 - cur.dof, 1e-300)
    cand = Candidate(
        effect=name,
        k=k,
        delta_chi2=float(dchi2),
        delta_bic=float(dchi2 - k * ln_n),
        p_value=p,
        explained=float(dchi2 / excess),
        structure_p=math.nan,
        physical=True,
        gap_p_after=_gap_p(new.chi2, new.dof),
    )
    return cand, new


def _halves(state: PhotoState, data: PhotoData) -> tuple[np.ndarray, np.ndarray] | None:
    """The hold-out's halves ``(P, V)``: image halves, or alternate views where parameters are per problem."""
    if state.normals:
        a = data.fold == 0
    else:
        a = np.broadcast_to((data.column < 0.5)[:, None], data.fold.shape)
    b = ~a
    seen = data.w.any(-1)
    if min(int(np.sum(seen & a)), int(np.sum(seen & b))) < _MIN_HALF_OBS:
        return None
    return a, b


def holdout(cur: PhotoState, new: PhotoState, data: PhotoData, dchi2: float, start) -> HoldoutRead | None:
    """Both models fitted on each half predict the other; ``None`` where the data have no two halves."""
    halves = _halves(new, data)
    if halves is None:
        return None
    gain = 0.0
    for train, test in (halves, halves[::-1]):
        fc = fit_state(cur, data, train, start=start, pixels=bool(new.structural))
        fn = fit_state(new, data, train, start=start)
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
    state, cur = PhotoState(), fit_state(PhotoState(), data)
    baseline, gaps, steps, partial, ambiguous = cur, [cur.gap], [], [], []
    for _ in range(max_steps):
        if steps and _within_noise(cur):
            break
        remaining = [n for n in names if n not in (*state.radial, *state.structural)]
        if not remaining:
            break
        progress(f"step {len(steps) + 1}: testing {len(remaining)} candidate effects ({', '.join(remaining)})")
        ref: list[StateFit] = []

        def on_pixels(state=state) -> StateFit:
            if not ref:
                ref.append(fit_state(state, data, pixels=True))
            return ref[0]

        scored = {c.effect: (c, f) for c, f in (_score(n, state, cur, on_pixels, data, ln_n) for n in remaining)}
        cands = _dominant_first(sorted((c for c, _ in scored.values()), key=lambda c: -c.delta_bic))
        chosen = None
        for c in cands:
            if not (c.delta_bic > 0 and c.p_value * len(remaining) < alpha):
                break
            progress(f"step {len(steps) + 1}: hold-out check of {c.effect}")
            hold = holdout(state, state.plus(c.effect), data, c.delta_chi2, cur.shared)
            c = dataclasses.replace(c, holdout=hold)
            if hold is not None and not hold.passed:
                partial.append(c)
                continue
            chosen = c
            break
        if chosen is None:
            break
        new = scored[chosen.effect][1]
        ambiguous += _ambiguous(chosen, cands, data)
        params, sigma = _step_params(chosen.effect, new)
        title = RADIAL[chosen.effect].title if chosen.effect in RADIAL else STRUCTURAL[chosen.effect]
        steps.append(PhotoStep(chosen.effect, title, params, sigma, chosen, cands, cur.gap, new.gap))
        state, cur = state.plus(chosen.effect), new
        gaps.append(cur.gap)
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
    )
