"""A step's record in the report: its parameters, evidence and gap, and the residuals kept for the plots."""

from __future__ import annotations

import numpy as np

from ._effect import Effect
from ._report import Candidate, Step

__all__ = ["flat", "make_step", "plot_sampler"]

_PLOT_MAX = 20_000


def flat(a, mask):
    """``a`` at the values of ``mask`` (all of ``a`` where ``mask`` is None), flat."""
    a = np.asarray(a)
    return a[mask] if mask is not None else a.ravel()


def plot_sampler(mask, n_flat: int, seed: int):
    """A function flattening an array of the data's shape to the points kept for the plots.

    Keeps all ``n_flat`` points, or a fixed random subsample of ``_PLOT_MAX``
    of them (seeded by ``seed``) so that the report stays small on large data;
    the same points are kept before and after every step.
    """
    pick = None
    if n_flat > _PLOT_MAX:
        pick = np.sort(np.random.default_rng(seed).choice(n_flat, _PLOT_MAX, replace=False))

    def sample(a):
        v = flat(a, mask)
        return v[pick] if pick is not None else v

    return sample


def make_step(e: Effect, win: Candidate, cands: list[Candidate], cur, new, sample) -> Step:
    """The report's record of adding ``e``: its parameters ± σ, the evidence, the gap and the plot data.

    The plot data (residuals against the effect's covariate before and after)
    are kept only when ``sample`` is given and the covariate exists.
    """
    plot = None
    if sample is not None and e.covariate in cur.covs:
        plot = {
            "covariate": e.covariate,
            "x_before": sample(cur.covs[e.covariate]),
            "r_before": sample(cur.r.reshape(np.shape(cur.pred))),
            "x_after": sample(new.covs[e.covariate]),
            "r_after": sample(new.r.reshape(np.shape(new.pred))),
        }
    return Step(
        effect=e.name,
        title=e.title,
        side=e.side,
        params=new.state.values[e.name],
        stderr=new.state.sigma[e.name],
        evidence=win,
        candidates=cands,
        gap_before=cur.state.gap,
        gap_after=new.state.gap,
        plot=plot,
    )
