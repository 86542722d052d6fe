"""The fits one discovery run shares: the problem, the parameter layout, the solver settings and their compiled program.

Every fit of a run (the baseline, each candidate, each continuation) is
solved at one padded parameter width and batch width, so one compiled
program serves them all; :class:`_View` is a fitted state with what the
structure tests read off it.
"""

from __future__ import annotations

import contextlib
import functools
import math
import threading
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from . import _exported
from ._effect import Effect, Param
from ._holdout import Holdout
from ._recheck import VariogramRecheck
from ._remeasure import TextureRemeasure
from ._report import FitState
from ._solve import _cov_full, _fit_batch, _Layout, _residual_view, static_key
from ._texture_term import CrossTexture

_SOLO_MIN_OBS = 20_000  # from this many residuals on, each fit is solved alone (_fit_batch)
_REFINE_ROUNDS = 11  # more rounds of lm_steps for an unconverged fit that matters (_Search.refine): 240 steps in all


class _View(NamedTuple):
    """A fitted state with what the tests read off it: whitened residuals, prediction and covariates."""

    state: FitState
    r: np.ndarray
    pred: np.ndarray
    covs: dict
    rho: np.ndarray | None = None  # profiled ρd (S, 1, C) of a scanline model
    levels_chi2: float = 0.0  # the scanline levels' share of χ² (wardjax.effects._levels)


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
        self._warming: threading.Thread | None = None  # the residual view's program compiling (warm_view)
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

    def warm_view(self) -> None:
        """Compile the residual view's program in a background thread, while the caller compiles the fits'.

        XLA compiles with the GIL released, so on two cores the two programs
        compile side by side (a cold ``wardjax diagnose`` compiles both
        before its first structure test). The thread evaluates the view at
        the initial values and drops the result; :meth:`residual_view` waits
        for it, so the program is compiled once. An error there is left to
        the first real call to raise.
        """

        def compile_it():
            with contextlib.suppress(Exception):  # the first real call raises it
                self._view_arrays(self.layout.u_initial(), ())

        self._warming = threading.Thread(target=compile_it, name="wardjax-warm-view", daemon=True)
        self._warming.start()

    def _view_arrays(self, u, active):
        """``_residual_view``'s arrays (device) at parameters ``u`` with the effects ``active`` switched on."""
        act = np.array([i in active for i in range(len(self.testable))], bool)
        static = dict(model=self.model, effects=self.testable, layout_key=self.layout.key)
        with jax.enable_x64(True):  # the parameters too: outside, jnp.asarray would round them to float32
            fn = functools.partial(_residual_view, **static)
            args = (jnp.asarray(u), jnp.asarray(act), self.data_dev)
            return _exported.call("residual_view", fn, static_key(static), args)

    def _warmed(self) -> None:
        """Wait for :meth:`warm_view`'s thread, so that the view's program is compiled once."""
        if self._warming is not None:
            self._warming.join()
            self._warming = None

    def residuals_at(self, u, active):
        """The whitened values' residuals ``(M,)`` at parameters ``u`` with the effects ``active`` switched on: a
        device array, dispatched and not waited for (what
        :func:`~wardjax.effects._standard_sigma.whitened_jacobian` differences)."""
        self._warmed()
        return self._view_arrays(u, active)[0]

    def residual_view(self, st: FitState) -> _View:
        """Whitened residuals, prediction and covariates of ``st``: what the structure tests and plots read."""
        self._warmed()
        r, pred, rho, lv = self._view_arrays(st.u, st.active)
        r, pred = np.asarray(r), np.asarray(pred)
        rho = None if rho is None else np.asarray(rho)
        return _View(st, r, pred, self.model.covariates(self.data, pred), rho, float(lv))


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
