"""One photo held out of a multi-photo pixel fit: fit the others, render it, and measure the error.

The measure users of multi-view capture compare methods by: with ``K`` photos
of a sample, :func:`~wardjax.fit_pixels` fits the ``K − 1`` others and
:func:`~wardjax.predict_pixels` renders photo ``k`` from the fit; the error is

.. math::

    \\mathrm{RMSE}_k = \\sqrt{\\tfrac{1}{PC} \\sum_{p,c} (\\hat f_{pkc} - f_{pkc})^2},
    \\qquad σ_k = \\sqrt{\\tfrac{1}{PC} \\sum_{p,c} σ_{pkc}^2}

over the pixels ``p`` and channels ``c`` seen in photo ``k`` (weight > 0), with
``σ = w^{-1/2}`` the noise of its values when ``weights`` are given: a model
that holds predicts the photo to ``RMSE_k / σ_k ≈ 1`` (the prediction's own
error adds a little).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from jaxtyping import ArrayLike

from ._pixels import PixelFit, fit_pixels, predict_pixels

__all__ = ["HeldOutPhoto", "heldout_pixels"]


class HeldOutPhoto(NamedTuple):
    """Photo ``k`` predicted by a fit of the other photos (:func:`heldout_pixels`).

    Attributes
    ----------
    fit
        :class:`~wardjax.fit.PixelFit` of the other ``K − 1`` photos.
    observed, predicted
        ``(P, C)`` photo ``k``'s BRDF estimates and their prediction (NaN where the photo has no weight).
    rmse
        RMS of ``predicted − observed`` over the pixels and channels seen (sr⁻¹).
    noise
        RMS of the noise σ of those values (``weights^{-1/2}``); NaN without ``weights``.
    """

    fit: PixelFit
    observed: np.ndarray
    predicted: np.ndarray
    rmse: float
    noise: float

    @property
    def ratio(self) -> float:
        """``rmse / noise``: 1 is the floor."""
        return self.rmse / self.noise


def heldout_pixels(
    f_r: ArrayLike, wi: ArrayLike, wo: ArrayLike, k: int, *, weights: ArrayLike | None = None, **fit_kwargs
) -> HeldOutPhoto:
    """Fit every photo but ``k`` with :func:`~wardjax.fit_pixels` and predict photo ``k``.

    Parameters
    ----------
    f_r, wi, wo
        ``(P, K, C)`` BRDF estimates and ``(P, K, 3)`` unit directions, as :func:`~wardjax.fit_pixels` takes.
    k
        The photo held out, ``0 ≤ k < K``.
    weights
        ``(P, K, C)`` ``1/σ²`` (optional); the noise RMS is reported where given.
    **fit_kwargs
        Passed to :func:`~wardjax.fit_pixels` (``lobe``, ``normals``, ``normalization``, ``height_field``, …).
    """
    f = np.asarray(f_r, np.float64)
    n = f.shape[1] if f.ndim == 3 else 0
    if f.ndim != 3 or n < 2:
        raise ValueError(f"f_r has shape {f.shape}; holding a photo out needs (P, K, C) with K ≥ 2")
    if not 0 <= int(k) < n:
        raise ValueError(f"k = {k} is not a photo of the {n}: expected 0 ≤ k < {n}")
    wi, wo = np.asarray(wi, np.float64), np.asarray(wo, np.float64)
    keep = [i for i in range(n) if i != int(k)]
    w = None if weights is None else np.broadcast_to(np.asarray(weights, np.float64), f.shape)
    fit = fit_pixels(f[:, keep], wi[:, keep], wo[:, keep], weights=None if w is None else w[:, keep], **fit_kwargs)
    pred = np.asarray(predict_pixels(fit, wi[:, [k]], wo[:, [k]]))[:, 0]
    seen = np.ones(pred.shape, bool) if w is None else w[:, k] > 0
    obs = np.where(seen, f[:, k], np.nan)
    pred = np.where(seen, pred, np.nan)
    rmse = float(np.sqrt(np.nanmean((pred - obs) ** 2)))
    noise = float("nan") if w is None else float(np.sqrt(np.mean(1.0 / w[:, k][seen])))
    return HeldOutPhoto(fit, obs, pred, rmse, noise)
