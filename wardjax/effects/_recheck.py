"""The partial-match guard's second opinion on a textured capture: the gap a winner leaves, under the variogram.

Why a second covariance
    ``discover`` refuses a strongly supported winner that explains less than
    half the excess and leaves a significant gap (:mod:`wardjax.effects._discover`,
    "Guard against confident wrong names"): a large discrepancy that a library
    effect only dents. On a textured capture the gap left is read under the
    texture's covariance measured from products about each scanline's mean
    (:func:`~wardjax.effects._texture.lag_covariances`), whose bias bends the
    long lags on textures smooth along the scanline: there a clean capture's
    gap can sit a few SD above 1, and a correct winner on top of it looks
    like a dent in something bigger. The covariance from the cross-variogram
    has no such bias but, as the covariance of every fit, costs power on
    library effects. So it is read only here: the current model and the
    winner are refitted under it, from where they stand, and the guard holds
    only if it holds under both covariances.

    A relaxation that must be earned: the winner is let through only where it
    pays for its parameters under the variogram's covariance too
    (:meth:`~wardjax.effects._report.VariogramRead.names`), not merely because
    the gap it leaves there is small — where the gap before it is small as
    well, it explains nothing. The evidence (ΔBIC, LR) is untouched, and
    nothing is computed unless the guard is about to refuse. A library winner on a smooth texture typically
    leaves a gap within about 1.02 under the variogram; an out-of-library
    effect such as a blurred frame leaves one well above it.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable

from ._evidence import _gap_p
from ._report import FitState, VariogramRead
from ._texture_term import with_texture

__all__ = ["VariogramRecheck"]


class VariogramRecheck:
    """Refits a state under the texture's covariance from the variogram; built on first use.

    ``make_search(data)`` is the run's ``_Search`` constructor over other
    data (same shapes: the run's compiled program serves it); ``data``,
    ``pred`` and ``rho`` are what :func:`~wardjax.effects._texture_term.with_texture`
    measured the texture from (the data, the baseline's prediction ``(S, N, C)``
    and profiled ρd ``(S, 1, C)`` under an identity whitening).
    """

    def __init__(self, make_search: Callable, data, pred, rho):
        self._make, self._inputs = make_search, (data, pred, rho)

    @functools.cached_property
    def _search(self):
        """The run's search over the data whitened by the variogram's covariance; ``None`` if it finds no texture."""
        textured = with_texture(*self._inputs, variogram=True)
        return None if textured is None or textured.refused else self._make(textured.data)

    def _refit(self, search, st: FitState) -> FitState:
        r = search.fit([(st.u, list(st.free), st.active)])[0]
        return search.state_of(search.refine(r, st.active), st.active)

    def gap_p(self, st: FitState) -> tuple[float, float] | None:
        """``(gap, P(χ²_dof ≥ χ²))`` of ``st`` refitted under the variogram's covariance; ``None`` where it finds no
        texture or the refit is not finite: the final state's second reading, so that "unexplained" is said only
        where the gap exceeds the noise under both covariances the decisions read."""
        search = self._search
        if search is None:
            return None
        b = self._refit(search, st)
        return (b.gap, _gap_p(b.chi2, b.dof)) if math.isfinite(b.chi2) else None

    def __call__(self, cur: FitState, new: FitState) -> VariogramRead | None:
        """``new`` against ``cur``, both refitted under the variogram's covariance; ``None`` where it finds no
        texture or a refit is not finite."""
        search = self._search
        if search is None:
            return None
        b, w = self._refit(search, cur), self._refit(search, new)
        if not (math.isfinite(b.chi2) and math.isfinite(w.chi2)):
            return None
        d = max(b.chi2 - w.chi2, 0.0)
        return VariogramRead(w.gap, _gap_p(w.chi2, w.dof), d / max(b.chi2 - b.dof, d, 1e-300), b.gap, d)
