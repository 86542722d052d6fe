"""The smoothed standard's noise in the fitted parameters' covariance: the lags the per-value σ cannot hold.

Why
    Every probe value is divided by the reflectance standard at its mirror
    point, smoothed first, so the standard's noise reaches the values as a
    relative error ``δy_i = f_i ε_i`` with ``Cov(ε_i, ε_j) = √(c_i c_j) R(Δ_ij)``
    (:mod:`~wardjax.effects._standard_noise`: ``c`` per value and channel, the
    standard's relative noise at the value's mirror point; ``R`` the smoothed,
    binned kernel's autocorrelation at the bins' lag ``Δ`` along and across
    the scanlines). The noise model holds its per-value share
    ``c_i R(0) f_i²``, which keeps the gap right; but smoothing keeps the noise's
    low frequencies (``Σ_Δ R = 1/b²`` against ``R(0)``), and a parameter
    fitted over many values averages exactly those. On a dark glossy sample,
    where the standard is much dimmer than the highlight and its noise
    dominates there, α's σ read ~2.4× too small without the lags.

The sandwich
    A fit's covariance is ``H⁻¹`` (``H = JᵀJ``, ``J`` the whitened residuals'
    Jacobian with ρd profiled). A perturbation ``δ`` of the values moves the
    whitened residuals by ``W (δ/σ)`` (``W`` the texture's whitening, ``I``
    under white noise) and the estimate by ``−H⁻¹ Jᵀ W (δ/σ)`` (the profile's
    projection is idempotent, so the profiled ``J`` already carries it). With
    ``A = (Wᵀ J H⁻¹) · √c f/σ`` the lags add (White 1980's sandwich over the
    covariance the fit did not assume)

        ΔCov = Σ_{Δ ≠ 0 in lags} R(Δ) Σ_i A_i A_{i+Δ}ᵀ      per channel, summed over channels.

    Under white noise every lag but ``Δ = 0`` is added. Where the texture is
    carried, its covariance was measured along each scanline on residuals
    that hold the standard's noise too, so only the lags across scanlines
    (``Δs ≠ 0``) are added. The scanlines' levels term, where present, enters
    ``H`` as fitted; its rows are not perturbed (a second-order share).
"""

from __future__ import annotations

import dataclasses

import numpy as np
from scipy import fft as sfft

from ._evidence import _lr_p
from ._gls import _back_whiten_columns
from ._report import Candidate, FitState
from ._texture_term import is_identity_whitening

# the forward differences' relative step: truncation (~h) and rounding (~ε/h) errors both ≲ 10⁻⁶ of the Jacobian
_STEP = 1e-6

__all__ = [
    "jacobian_at",
    "lag_form",
    "needs_jacobian",
    "standard_deflated",
    "whitened_jacobian",
    "widened_report",
    "with_standard",
]


def whitened_jacobian(search, u: np.ndarray, free, active) -> np.ndarray:
    """``∂r/∂u`` ``(S, N, C, K)`` of the whitened values' residuals ``r`` (ρd profiled) at ``u`` against its ``K``
    parameters ``free`` (the effects ``active`` switched on), in units of ``1/σ``.

    Forward differences through the residual view's program (``search.residuals_at``), step
    ``h_j = 10⁻⁶ max(1, |u_j|)``: within 10⁻⁶ of the Jacobian's largest entry of forward-mode autodiff (the tests
    compare the two; a weak column's own error ~10⁻⁵ of its scale, as central differences', set by the residuals'
    rounding), far below what a σ is known to. The ``K + 1`` evaluations (``K`` is 2–5 in a discovery run) are
    dispatched before any is read, so they may run side by side. The view's program is compiled in every run
    anyway; a Jacobian program of its own cost ~3 s of compiling alone, about twice that in a cold run where it
    shared two cores with the fits' program, and no less than the differences when warm.
    """
    u = np.asarray(u, np.float64)
    shape = np.shape(search.data.y)
    steps = [_STEP * max(1.0, abs(float(u[j]))) for j in free]
    calls = [search.residuals_at(u, active)]
    for j, h in zip(free, steps):
        v = u.copy()
        v[j] += h
        calls.append(search.residuals_at(v, active))
    r0, *r = (np.asarray(x, np.float64).reshape(shape) for x in calls)
    return np.stack([(rj - r0) / h for rj, h in zip(r, steps)], -1) if r else np.zeros((*shape, 0))


def jacobian_at(search, u: np.ndarray, free, active) -> np.ndarray:
    """``Wᵀ ∂r/∂u`` ``(S, N, C, K)`` (:func:`whitened_jacobian`; ``Wᵀ`` the texture's whitening transposed, none
    where the data are not whitened): the whitened residuals' Jacobian back in units of ``1/σ``."""
    J = whitened_jacobian(search, u, free, active)
    W = getattr(search.data, "whiten", None)
    return J if W is None else _back_whiten_columns(np.asarray(W, np.float64), J)


def needs_jacobian(search) -> bool:
    """Whether the fits of ``search`` have the standard's lags added to their σ (:func:`with_standard`)."""
    return getattr(search.data, "standard", None) is not None and getattr(search.model, "kind", None) == "scanline"


def lag_form(a: np.ndarray, c: np.ndarray, R: np.ndarray, columns: np.ndarray, across_only: bool) -> np.ndarray:
    """``Σ_ch Σ_{Δ ≠ 0} R(Δ) Σ_i √(c_i c_{i+Δ}) a_i a_{i+Δ}ᵀ`` ``(K, K)`` for ``a`` ``(S, N, C, K)`` on the bin grid.

    ``c`` ``(C,)`` or per value ``(S, N, C)``; ``R`` ``(2L + 1, 2L + 1)`` indexed ``[Δs, Δn]`` (centre ``Δ = 0``);
    scanline ``s`` is bin column ``columns[s]``; ``across_only`` keeps the lags with ``Δs ≠ 0``.

    With ``g = √c a`` on the grid, the sum is ``Σ_i g_i b_iᵀ``, ``b_i = Σ_Δ R'(Δ) g_{i+Δ}`` (``R'`` the kept
    lags): ``b`` is one FFT correlation of every channel and parameter with ``R'`` (zero beyond the grid), the
    sum one matrix product — not a pass over the grid per lag (25× faster at 11 × 11 lags).
    """
    _, n, c_n, k = a.shape
    lag = R.shape[0] // 2
    grid = np.zeros((int(columns.max()) + 1, n, c_n, k))
    grid[columns] = a * np.sqrt(np.broadcast_to(np.asarray(c, float), a.shape[:3]))[..., None]
    kept = np.array(R, float, copy=True)
    kept[lag, lag] = 0.0
    if across_only:
        kept[lag] = 0.0
    fshape = [sfft.next_fast_len(q + 2 * lag, real=True) for q in grid.shape[:2]]
    spectrum = (
        np.asarray(sfft.rfftn(grid, fshape, axes=(0, 1)))
        * np.asarray(sfft.rfftn(kept[::-1, ::-1], fshape))[..., None, None]
    )
    b = np.asarray(sfft.irfftn(spectrum, fshape, axes=(0, 1)))[lag : lag + grid.shape[0], lag : lag + n]
    out = grid.reshape(-1, k).T @ b.reshape(-1, k)
    return 0.5 * (out + out.T)


def with_standard(search, st: FitState) -> FitState:
    """``st`` (a :class:`~wardjax.effects._report.FitState` fitted under ``search``) with the smoothed standard's
    lags in its covariance and σ; ``st`` itself where the data carry no standard's noise."""
    if not needs_jacobian(search) or not st.free:
        return st
    c, R, columns = (np.asarray(x) for x in search.data.standard)
    free = list(st.free)
    cov_b = np.asarray(st.cov)[np.ix_(free, free)]
    if not np.all(np.isfinite(cov_b)):
        return st
    data = search.data
    y, sig, mask = (np.asarray(x) for x in (data.y, data.sigma, data.mask))
    W = getattr(data, "whiten", None)
    textured = W is not None and not is_identity_whitening(np.asarray(W))
    a = (jacobian_at(search, st.u, st.free, st.active) @ cov_b) * np.where(mask, y / sig, 0.0)[..., None]
    cov = np.array(st.cov, copy=True)
    cov[np.ix_(free, free)] = cov_b + lag_form(a, c, R, columns, across_only=textured)
    return dataclasses.replace(st, cov=cov, sigma=search.layout.sigma(st.u, cov))


def widened_report(base_search, final_search, baseline: FitState, final: FitState, steps: list):
    """The states a report reads σ from, with the smoothed standard's noise shared between values in their σ
    (:func:`with_standard`): ``(baseline, final, steps)``.

    The baseline under the search it was fitted in; the final model, every step's winner and the last step's
    candidates that enter the model average (:func:`~wardjax.effects._averaging.model_averaged`) under the final
    search (an earlier step's texture covariance differs from it by a re-measurement).
    """
    if getattr(base_search.data, "standard", None) is None:
        return baseline, final, steps
    done: dict[int, FitState] = {}

    def widen(search, st: FitState) -> FitState:
        if id(st) not in done:
            done[id(st)] = with_standard(search, st)
        return done[id(st)]

    baseline = widen(base_search, baseline)
    final = widen(final_search, final)
    out = []
    for i, step in enumerate(steps):
        st = step.evidence.state
        ev = step.evidence if st is None else dataclasses.replace(step.evidence, state=widen(final_search, st))
        cands = step.candidates
        if i == len(steps) - 1:
            cands = [
                dataclasses.replace(c, state=widen(final_search, c.state))
                if c.state is not None and c.physical and c.delta_bic > 0
                else c
                for c in cands
            ]
        stderr = ev.state.sigma.get(step.effect, step.stderr) if ev.state is not None else step.stderr
        out.append(dataclasses.replace(step, evidence=ev, candidates=cands, stderr=stderr))
    return baseline, final, out


def standard_deflated(search, win: Candidate) -> Candidate:
    """``win`` with its Δχ² divided by the standard's design effect in ΔBIC and the p-value (a first-order Rao–Scott
    correction, as the texture's between scanlines: :meth:`~wardjax.effects._texture_term.CrossTexture.deflate`).

    The white-noise Δχ² of an effect is ``θ̂ᵀ Σ⁻¹ θ̂`` over its parameters; the standard's low frequencies move
    ``θ̂`` by more than ``Σ`` says (:func:`with_standard`), so under the null its mean is ``tr(Σ⁻¹ Σ')``, not ``k``:
    ``D = tr(Σ⁻¹ Σ')/k ≥ 1``. A smooth effect (a per-channel specular scale, an offset, a gradient) is what the
    standard's shared noise mimics on a dark glossy sample, where ``D`` reaches several.
    """
    st = win.state
    if st is None or getattr(search.data, "standard", None) is None or win.delta_chi2 <= 0:
        return win
    idx = [j for j in search.layout.slices.get(win.effect, []) if j in st.free]
    if not idx:
        return win
    nom = np.asarray(st.cov)[np.ix_(idx, idx)]
    wide = np.asarray(with_standard(search, st).cov)[np.ix_(idx, idx)]
    try:
        d = float(np.trace(np.linalg.solve(nom, wide))) / len(idx)
    except np.linalg.LinAlgError:
        return win
    if not np.isfinite(d) or d <= 1.0:
        return win
    dchi2 = (win.delta_bic + win.k * search.ln_n) / d  # the Δχ² ΔBIC rests on (the texture's deflation kept)
    e = next(t for t in search.testable if t.name == win.effect)
    return dataclasses.replace(
        win,
        delta_bic=dchi2 - win.k * search.ln_n,
        p_value=_lr_p(dchi2, e, win.k),
        design_effect=win.design_effect * d,
    )
