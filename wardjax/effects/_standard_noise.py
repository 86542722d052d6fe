"""The standard's noise in the reconstructed BRDF: what smoothing the standard leaves of it, after binning.

Why
    The reconstruction divides each probe pixel by the standard's image at
    its mirror point, smoothed first (``fit.smooth_standard_px``, a Gaussian
    of σ pixels). The standard's sensor noise therefore reaches ``f`` as a
    relative error ``f · ε``, ``ε`` the smoothed noise, correlated over a few
    pixels along the scanline. Second differences (the capture's white-noise
    estimate, :mod:`wardjax.effects._capture`) cancel a component that
    smooth, so without this term the noise of a 320 × 240 capture binned
    2 × 2 is underestimated by about a tenth in variance
    (``tests/test_effects.py``).

The estimate
    The standard is uniform and Lambertian, so its pixels hold nothing but
    irradiance (smooth) and noise: the relative noise variance per pixel,
    ``c = median((Δ²v / √6)² / v²) / 0.4549`` per channel (``Δ²`` the second
    difference along rows and columns of the raw, unsmoothed lit − dark
    crop, over triples within 20 % of their centre, so none straddles the
    standard's edge; the median of ``χ²₁`` is 0.4549). What reaches a bin of ``b × b`` probe pixels is
    ``c Σ K_b²``, ``K_b`` the smoothing kernel averaged over the bin (the
    mirror mapping taken as one standard pixel per probe pixel), added to the
    noise variance as ``c Σ K_b² f²``.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

__all__ = ["standard_noise_share"]

_CHI2_1_MEDIAN = 0.454936


def smoothing_factor(sigma_px: float, b: int) -> float:
    """``Σ K_b²``: the variance a unit white noise keeps after Gaussian smoothing (σ pixels) and a ``b × b`` mean."""
    from scipy.ndimage import gaussian_filter, uniform_filter

    n = 2 * math.ceil(4 * sigma_px) + 2 * b + 3
    img = np.zeros((n, n))
    img[n // 2, n // 2] = 1.0
    k = uniform_filter(gaussian_filter(img, sigma_px, mode="constant"), size=b, mode="constant")
    return float(np.sum(k * k))


def _relative_noise(v: np.ndarray) -> np.ndarray:
    """``c`` per channel: the median relative second-difference variance of ``v`` ``(h, w, C)`` (see above)."""
    out = np.zeros(v.shape[-1])
    for c in range(v.shape[-1]):
        x = v[..., c]
        r2 = []
        for a in (0, 1):
            x0, x1, x2 = (np.take(x, range(i, x.shape[a] - 2 + i), axis=a) for i in range(3))
            with np.errstate(invalid="ignore", divide="ignore"):
                r = (x0 - 2 * x1 + x2) / (np.sqrt(6.0) * x1)
            # triples on the standard only: across its edge (the table, the probe) the values jump
            on = (x1 > 0) & (np.abs(x0 - x1) < 0.2 * x1) & (np.abs(x2 - x1) < 0.2 * x1)
            r2.append((r * r)[np.isfinite(r) & on])
        vals = np.concatenate(r2)
        out[c] = float(np.median(vals)) / _CHI2_1_MEDIAN if vals.size >= 16 else 0.0
    return out


def standard_noise_share(cap, b: int) -> np.ndarray:
    """``(C,)``: the relative variance the smoothed standard adds to a ``b × b`` bin's BRDF value, ``σ² += share f²``.

    Zero where the standard is not smoothed: its noise is then white along
    the scanline, and the second differences count it.
    """
    from ..reconstruct import prepare_bands

    sigma_px = float(cap.config.fit.smooth_standard_px)
    if sigma_px <= 0:
        return np.zeros(3)
    fit = cap.config.fit.model_copy(update={"smooth_standard_px": 0.0})
    raw = dataclasses.replace(cap, config=cap.config.model_copy(update={"fit": fit}))
    setup = prepare_bands(raw, dtype=np.float64)
    if setup.box is None:
        return np.zeros(3)
    w, h = (int(v) for v in np.asarray(setup.kernel["std_size"]))
    std = np.asarray(setup.kernel["std"], float)[:h, :w]
    v = std[..., 0:3] - std[..., 3:6]
    v = np.where(std[..., 6:9] > 0, np.nan, v)  # clipped pixels
    return _relative_noise(v) * smoothing_factor(sigma_px, b)
