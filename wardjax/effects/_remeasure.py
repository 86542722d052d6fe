"""The texture's covariance measured again once an effect is named: from the residuals of the model with it.

Why
    On a textured capture ``discover`` carries the probe's ρd texture as a
    Gaussian process whose covariance is measured on the *baseline's*
    residuals (:mod:`wardjax.effects._texture_term`). Those residuals still
    hold the effect that is missing. Off the highlight most of it is
    smooth along the scanline and shared by every scanline — anisotropy
    widens the lobe's tails, a ramp tilts the floor — and the lag products
    take it for texture. Once the effect is fitted, the covariance measured
    on the baseline's residuals is too large by that share, and the gap
    after the effect falls below 1 (0.82–0.89 on untouched desk and marble
    captures after anisotropy): "gap after" no longer says whether anything
    is left, and a second effect is discounted by the first's signal. On an
    untextured capture the baseline's misfit alone can read as a "texture"
    of a percent or two.

The step
    At each step the leader — the candidate with the best evidence under the
    current covariance — is refitted under white noise (the identity
    whitening: the same compiled program), the texture and noise are
    measured on its residuals exactly as on the baseline's, and the current
    model and the leader are both refitted under the new covariance, from
    where they stand. The leader's evidence (Δχ², ΔBIC, the LR test, the
    design effect) is read there and the decision to add it is taken on that
    reading (``discover``'s ``_reread``): the effect's signal no longer
    discounts its own evidence (an untouched textured desk read a baseline
    gap of 0.95 and anisotropy was refused). A step's gap before → after
    compares the two models under one covariance, and the next step starts
    from it. A leader that is not added leaves the run as it was: the
    covariance measured without it stands.

    The texture is carried on only where the significance test finds it on
    the new residuals, as on the baseline's; elsewhere the noise is white at
    the capture's own σ. On an untextured capture the baseline's misfit
    reads as texture; once the effect is fitted, what the lag products take
    from its residuals is a few tenths of a percent of uncorrelated variance
    (lag-1 correlation ≈ 0), noise by another name. Carried on, it took a
    share of the noise: the gap after anisotropy read 0.89–0.92 on three
    untextured captures drawn by Radiance (the desk, the marble, an
    anisotropic satin), 7–10 SD below 1; with white noise there, 0.97–1.03.
"""

from __future__ import annotations

import math
from collections.abc import Callable

from ._report import FitState

__all__ = ["TextureRemeasure"]


class TextureRemeasure:
    """Re-measures the texture on a named effect's residuals and refits the step's states under it.

    ``plain`` is the run's search over the data under the identity whitening
    (what the baseline's texture was measured on); ``textured(pred, rho)``
    returns the run's search with the texture measured on residuals about
    ``pred`` (profiled ρd ``rho``), and the texture summary (``None`` where
    none is significant).
    """

    def __init__(self, plain, textured: Callable):
        self.plain, self._textured = plain, textured

    @staticmethod
    def refit(search, st: FitState) -> FitState:
        """``st`` refitted under ``search``'s data from where it stands (its free parameters and effects)."""
        r = search.fit([(st.u, list(st.free), st.active)])[0]
        return search.state_of(search.refine(r, st.active), st.active)

    def __call__(self, before: FitState, after: FitState):
        """``(search, before', after', summary)``: the run's new search and both states refitted under it.

        ``None`` where a refit is not finite (the step then stands as it was).
        """
        white = self.refit(self.plain, after)
        if not math.isfinite(white.chi2):
            return None
        view = self.plain.residual_view(white)
        search, summary = self._textured(view.pred, view.rho)
        b, a = self.refit(search, before), self.refit(search, after)
        if not (math.isfinite(b.chi2) and math.isfinite(a.chi2)):
            return None
        return search, b, a, summary
