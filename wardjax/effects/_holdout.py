"""The hold-out check of a winner: fitted on one half of the scanlines, it must explain the other half.

Why
    ΔBIC and the likelihood-ratio test price an effect's parameters against
    the noise model. Where that model is off — noise correlated by the
    standard's smoothing, texture that the covariance misreads — every Δχ² is
    inflated alike, and an effect that only fits this capture's noise
    (a γ of Δχ² 33 on an untouched desk capture) passes both. A prediction
    of data the fit has not seen does not depend on that scale: an effect
    fitted to noise predicts the held-out scanlines *worse* than the model
    without it (by about its ``k`` parameters' variance), a present effect
    predicts them better by about its own Δχ².

The check (two-fold, by alternate blocks of the scanlines)
    The scanlines (image columns) are cut into contiguous blocks of at least
    ``_MIN_SCANLINES``, so that texture shared by neighbouring columns does
    not leak across, and the blocks are dealt alternately to two folds
    (:func:`fold_blocks`). For each fold ``A`` the current model and the model
    with the winner are refitted on ``A`` alone, from where they stand on all
    the data, with their priors centred where every fit's are (the layout's
    initial values); both then predict the other fold ``B`` with their shared
    parameters held (ρd per scanline profiled, as in every fit). The held-out
    gain is ``Σ_B χ²_B(current) − χ²_B(winner)`` over both folds. The winner
    is added only if the gain is at least ``HOLDOUT_SHARE`` of its in-sample
    Δχ² (for a present effect the gain is about its Δχ² less a few ``k``; for
    noise it is negative on average).

    The read is *inconclusive*, and then vetoes nothing, where a fold cannot
    pin the model the effect is added to: the current model refitted on the
    fold loses more χ² on the other fold (against the current model fitted to
    all the data) than the winner's whole in-sample Δχ². Its own held-out
    loss is then larger than anything the effect could win back, and the
    gain measures the two refits' lobe misfits, not the effect. A fold
    without the scanlines nearest the stripline cannot pin a narrow lobe
    (marble's α 0.048): on textured marble the anisotropy truly present read
    negative gains there. For a well-pinned fold the loss is about the
    current model's parameter count.

    Why blocks and not the two halves of the image: across the columns the
    half-vector azimuth (anisotropy's covariate), the image position (a lamp
    field's) and the lobe's place change monotonically, so a half predicts
    the other half by extrapolating in the effect's own covariate. Its gain
    then swings by many times the effect's Δχ² (the anisotropy of an untouched
    wood desk, Δχ² 46–63, read gains of +1,068 at 160 × 120 and −200 at
    320 × 240, which refused it; with alternate blocks, +100). With alternate
    blocks each fold spans the image and predicts the other by interpolation.

    The scanline levels' Gaussian process (:mod:`~wardjax.effects._levels`)
    is restricted to each half with the covariance estimated on all of them.
    Every refit shares the run's compiled program (same shapes; masked
    scanlines give zero residuals).
"""

from __future__ import annotations

import dataclasses
import functools
import math
from collections.abc import Callable

import numpy as np

from ._levels import subset_whitening
from ._report import FitState, HoldoutRead

__all__ = ["HOLDOUT_SHARE", "Holdout", "HoldoutRead"]

HOLDOUT_SHARE = 0.25  # the held-out gain a winner needs, as a fraction of its in-sample Δχ²
_MIN_SCANLINES = 8  # each half at least this many scanlines with data; each block of a fold too
_PIN_RATIO = 4.0  # the folds read the effect alike where each pins its θ this well: tr(Σ_A Σ_B⁻¹)/k either way
_MAX_PAIRS = 3  # a fold is at most this many blocks, alternating with the other fold's


def fold_blocks(n: int) -> np.ndarray:
    """The fold ``(n,)`` (0 or 1) of each of ``n`` scanlines in image order: alternate contiguous blocks of at least
    ``_MIN_SCANLINES``, at most ``2 _MAX_PAIRS`` of them (two blocks, the halves, below ``4 _MIN_SCANLINES``)."""
    pairs = max(1, min(_MAX_PAIRS, n // (2 * _MIN_SCANLINES)))
    return (np.arange(n) * (2 * pairs) // max(n, 1)) % 2


class Holdout:
    """Refits states on halves of the scanlines and scores their prediction of the other half.

    ``make_search(data)`` is the run's ``_Search`` constructor (same shapes: one compiled program);
    ``data`` the run's data; ``levels`` the levels' covariance summary (``rho``, ``nugget``, ``sd``) or ``None``.
    """

    def __init__(self, make_search: Callable, data, levels: dict | None = None):
        self._make, self._data, self._levels = make_search, data, levels

    @staticmethod
    def applicable(data) -> bool:
        """Whether the data have scanlines enough for two halves (a scanline model's data)."""
        m = np.asarray(getattr(data, "mask", np.zeros((0,))))
        return m.ndim == 3 and int(np.sum(m.any(axis=(1, 2)))) >= 2 * _MIN_SCANLINES

    def _half(self, keep: np.ndarray):
        data = self._data
        mask = np.asarray(data.mask) & keep[:, None, None]
        new = dataclasses.replace(data, mask=mask)
        if data.levels is not None:
            P, a = data.levels
            P = np.asarray(P)
            used = np.flatnonzero(np.any(P != 0, axis=0))
            Ph = np.zeros_like(P)
            if self._levels is not None and used.size:
                lv = self._levels
                s2 = lv["sd"] ** 2 / (1.0 + lv["nugget"])
                sub = used[keep[used]]
                if sub.size >= _MIN_SCANLINES:
                    w = subset_whitening(P.shape[1], sub, lv["rho"], lv["nugget"], s2)
                    Ph[: w.shape[0]] = w
            new = dataclasses.replace(new, levels=(Ph, a))
        return new

    @functools.cached_property
    def _folds(self):
        """The folds' searches ``(train, test)``: one set of alternate blocks against the other, and the reverse."""
        seen = np.flatnonzero(np.asarray(self._data.mask).any(axis=(1, 2)))
        first = np.zeros(np.shape(self._data.y)[0], bool)
        first[seen[fold_blocks(len(seen)) == 0]] = True
        a, b = self._make(self._half(first)), self._make(self._half(~first))
        return ((a, b), (b, a))

    @staticmethod
    def _chi2_at(search, st: FitState, u) -> float:
        """χ² of ``search``'s data at the parameters ``u`` with ``st``'s effects on (nothing refitted but ρd).

        One evaluation of the residuals (the run's residual program; ρd is profiled in closed form), not a
        solve with nothing free: the values' whitened residuals and the scanline levels' ``P ℓ``, ``ℓ = ρd a``.
        """
        view = search.residual_view(dataclasses.replace(st, u=np.asarray(u)))
        return float(np.sum(view.r**2)) + view.levels_chi2

    @staticmethod
    def _train(search, st: FitState, anchor):
        r = search.fit([(st.u, list(st.free), st.active, anchor)])[0]
        return search.refine(r, st.active)

    def __call__(self, cur: FitState, new: FitState, dchi2: float) -> HoldoutRead | None:
        """The hold-out read of ``new`` (the model with the winner) against ``cur``; ``None`` if a fit fails.

        The winner's own parameters ``θ`` are fitted on one fold ``A`` and *held* on the other, ``B``, where the
        current model's parameters are refitted in both models: ``B`` pins its own lobe, so the read does not
        depend on how well one fold extrapolates the lobe to the other. The direction's gain
        ``χ²_B(current) − χ²_B(winner, θ_A)`` is at most ``Δχ²_B``, the winner's in-sample Δχ² on ``B`` alone,
        and for noise its mean is ``−tr(Σ_A Σ_B⁻¹)`` (``Σ`` the folds' covariances of ``θ``). The winner passes
        where the gain over both directions is positive and at least ``HOLDOUT_SHARE`` of ``Σ Δχ²_B``. Where one
        fold pins ``θ`` far worse than the other (``tr(Σ_A Σ_B⁻¹)`` above ``_PIN_RATIO`` per parameter either
        way: the effect's signature lies where one fold has no scanlines) that fold can neither teach nor test
        it: the read is *inconclusive* (``lost`` holds that ratio) and vetoes nothing.
        """
        own = [j for j in new.free if j not in set(cur.free)]  # the winner's parameters
        fits = []
        for train, _ in self._folds:  # the winner fitted on each fold alone, with its θ's covariance there
            r = self._train(train, new, train.layout.u_initial())
            cov = np.asarray(train.state_of(r, new.active).cov)[np.ix_(own, own)]
            fits.append((np.asarray(r[0]), cov))
        try:
            c0, c1 = fits[0][1], fits[1][1]
            ratio = max(float(np.trace(np.linalg.solve(c1, c0))), float(np.trace(np.linalg.solve(c0, c1))))
        except np.linalg.LinAlgError:
            ratio = math.inf
        if not ratio <= _PIN_RATIO * len(own):  # one fold barely sees the effect: it can neither teach nor test it
            return HoldoutRead(math.nan, math.nan, True, True, ratio)
        gain, base = 0.0, 0.0
        for (_, test), (u_a, _), (u_b, _) in zip(self._folds, fits, fits[::-1]):
            anchor = test.layout.u_initial()
            u0 = np.array(new.u, copy=True)
            u0[own] = u_a[own]
            held = dataclasses.replace(new, u=u0, free=tuple(j for j in new.free if j not in own))
            c_cur = self._chi2_at(test, cur, self._train(test, cur, anchor)[0])
            g = c_cur - self._chi2_at(test, new, self._train(test, held, anchor)[0])
            d_b = c_cur - self._chi2_at(test, new, u_b)
            if not (math.isfinite(g) and math.isfinite(d_b)):
                return None
            gain, base = gain + g, base + max(d_b, 0.0)
        share = gain / max(base, 1e-300)
        return HoldoutRead(gain, share, bool(gain > 0 and share >= HOLDOUT_SHARE))
