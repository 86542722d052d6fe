"""Per-item outcome codes: failure is data, raised only at the boundary."""

from __future__ import annotations

import enum

import numpy as np

__all__ = ["Status"]


class Status(enum.IntEnum):
    """Outcome of one fit (one scanline, one joint fit).

    Stored as small integers in result arrays (``res.status``); compare with
    the members (``res.status == Status.CONVERGED``) or read names with
    :meth:`Status.names`.

    ``CONVERGED``
        The remaining Gauss–Newton step is below a thousandth of the
        parameter's standard error: the optimum is found to well within its
        own uncertainty.
    ``MAX_STEPS``
        The step budget ran out before that test passed; the parameters are
        the best point found and usually close, but not certified.
    ``NONFINITE``
        NaN or inf appeared in the parameters, the χ² or the covariance, or
        rounding made them invalid (a negative χ² or variance: float32 sums
        that cancel).
    ``INSUFFICIENT_DATA``
        ``α`` is not identified by the data: too few valid samples, no
        specular lobe detected (it lowers χ² by less than 25 residual
        variances, a 5σ likelihood-ratio test against a lobe-free model), or
        a lobe whose width is unresolved (σ_α/α > 1) — a scanline that misses
        the highlight, say. The parameters are reported but not certified.
    ``AT_BOUND``
        The roughness ended on its search bound with the gradient pointing
        outward: the data favour a lobe narrower or wider than the model
        allows, and the estimate is not an interior optimum.
    """

    CONVERGED = 0
    MAX_STEPS = 1
    NONFINITE = 2
    INSUFFICIENT_DATA = 3
    AT_BOUND = 4

    @classmethod
    def names(cls, codes) -> np.ndarray:
        """Lower-case names for an array of codes, e.g. ``"converged"``."""
        table = np.array([m.name.lower() for m in cls])
        return table[np.asarray(codes, dtype=int)]
