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
    irradiance (smooth) and noise. Its level is not uniform (the lamp's
    falloff over it), and neither is its relative noise: where it is dim,
    read noise and quantisation weigh more (3–7× the variance over the
    mirror points of a 160 × 120 simulated probe, the highlight's on the
    quiet side). So ``c`` is local: at each raw pixel of the unsmoothed
    lit − dark crop on the standard (its margin holds the table, whose
    near-zero values give relative differences of order one), the squared
    relative second difference ``(Δ²v / √6 v)²`` along rows and along
    columns (over triples within 20 % of their centre, so none straddles
    the standard's edge), averaged over a Gaussian window
    of :data:`MAP_SCALE_PX` pixels (its mean is the noise variance, whatever
    the noise's distribution; ~1,600 triples), per channel; then read at each
    value's mirror point (:func:`standard_noise`). One median over the whole
    standard overstated the share of a dark metal's highlight by ~1.3× in
    variance. What reaches a bin of ``b × b`` probe pixels is ``c Σ K_b²``,
    ``K_b`` the smoothing kernel averaged over the bin (the mirror mapping
    taken as one standard pixel per probe pixel: exact in the simulated
    rig), added to the noise variance as ``c Σ K_b² f²``.

Between values
    The smoothed noise is shared by neighbouring bins, along the scanline and
    across scanlines (the standard is smoothed in two dimensions, and the
    mirror points of neighbouring image columns are neighbouring columns of the
    standard). The relative errors of two bins ``Δ = (Δs, Δn)`` bins apart
    correlate as ``√(c_i c_j) R(Δ)`` (``c`` varies little over the kernel),
    ``R(Δ) = Σ_p K_b(p) K_b(p + b Δ)`` the kernel's autocorrelation at the
    bins' pixel offset (:func:`bin_lag_correlation`; ``R(0) = Σ K_b²``).
    Summed over every lag, ``Σ R = 1/b²``: smoothing removes none of the
    noise's low frequencies, which is what a parameter fitted over many bins
    averages, so a per-value term alone (``R(0)``) understates the parameters'
    variance by up to ``1/(b² R(0))`` (28 at ``b = 1``, 7.9 at ``b = 2``,
    σ = 1.5 px). :mod:`wardjax.effects._standard_sigma` adds the lags to the
    fitted parameters' covariance.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

__all__ = ["bin_lag_correlation", "smoothing_factor", "standard_noise"]

MAP_SCALE_PX = 8.0  # the Gaussian window (σ, standard pixels) over which the local noise variance is averaged


def smoothing_factor(sigma_px: float, b: int) -> float:
    """``Σ K_b²``: the variance a unit white noise keeps after Gaussian smoothing (σ pixels) and a ``b × b`` mean."""
    from scipy.ndimage import gaussian_filter, uniform_filter

    n = 2 * math.ceil(4 * sigma_px) + 2 * b + 3
    img = np.zeros((n, n))
    img[n // 2, n // 2] = 1.0
    k = uniform_filter(gaussian_filter(img, sigma_px, mode="constant"), size=b, mode="constant")
    return float(np.sum(k * k))


def bin_lag_correlation(sigma_px: float, b: int) -> np.ndarray:
    """``R(Δ)`` ``(2L + 1, 2L + 1)``: the smoothed, ``b × b``-binned kernel's autocorrelation at bin lags
    ``Δ = (Δs, Δn)`` (centre: ``Δ = 0``, equal to :func:`smoothing_factor`), out to where it falls below 10⁻⁶ of it."""
    from scipy.ndimage import gaussian_filter, uniform_filter

    from ._texture import convolve_full

    n = 2 * math.ceil(4 * sigma_px) + 2 * b + 3
    img = np.zeros((n, n))
    img[n // 2, n // 2] = 1.0
    k = uniform_filter(gaussian_filter(img, sigma_px, mode="constant"), size=b, mode="constant")
    auto = convolve_full(k, k[::-1, ::-1])  # Σ_p k(p) k(p + d) at pixel offsets d; centre at n − 1
    reach = (n - 1) // b
    idx = n - 1 + b * np.arange(-reach, reach + 1)
    r = auto[np.ix_(idx, idx)]
    keep = np.flatnonzero(np.max(np.abs(r), axis=0) > 1e-6 * r[reach, reach])
    lag = int(np.max(np.abs(keep - reach))) if keep.size else 0
    out = r[reach - lag : reach + lag + 1, reach - lag : reach + lag + 1]
    return 0.5 * (out + out.T)


def _relative_noise_map(v: np.ndarray, scale_px: float = MAP_SCALE_PX) -> np.ndarray:
    """``c(p)`` ``(h, w, C)``: the local relative second-difference variance of ``v`` ``(h, w, C)`` (see above); NaN
    where no triple lies within a few ``scale_px`` of a pixel."""
    from scipy.ndimage import gaussian_filter

    out = np.full(v.shape, np.nan)
    for c in range(v.shape[-1]):
        x = v[..., c]
        acc, cnt = np.zeros(x.shape), np.zeros(x.shape)
        for a in (0, 1):
            x0, x1, x2 = (np.take(x, range(i, x.shape[a] - 2 + i), axis=a) for i in range(3))
            with np.errstate(invalid="ignore", divide="ignore"):
                r = (x0 - 2 * x1 + x2) / (np.sqrt(6.0) * x1)
            # triples on the standard only: across its edge (the table, the probe) the values jump
            on = (x1 > 0) & (np.abs(x0 - x1) < 0.2 * x1) & (np.abs(x2 - x1) < 0.2 * x1) & np.isfinite(r)
            centre = (slice(1, -1), slice(None)) if a == 0 else (slice(None), slice(1, -1))
            acc[centre] += np.where(on, r * r, 0.0)
            cnt[centre] += on
        num = gaussian_filter(acc, scale_px, mode="constant")
        den = gaussian_filter(cnt, scale_px, mode="constant")
        with np.errstate(invalid="ignore", divide="ignore"):
            out[..., c] = np.where(den > 1e-3, num / den, np.nan)
    return out


def standard_noise(cap, points: np.ndarray) -> np.ndarray:
    """``c`` ``(..., C)``: the standard's relative noise variance per raw pixel at the mirror points of ``points``
    ``(..., 3)`` (sample-plane positions, mm; the module's estimate).

    Zero where the standard is not smoothed: its noise is then white along
    the scanline, and the second differences count it; a ``b × b`` bin's
    share is ``c Σ K_b²``, ``σ² += share f²``. A mirror point off the
    estimate (a partial bin at the standard's edge) takes the median of ``c``
    over the standard.
    """
    from ..geometry import back_project, in_box, mirror_point, project
    from ..reconstruct import prepare_bands, sample_bilinear

    points = np.asarray(points, float)
    sigma_px = float(cap.config.fit.smooth_standard_px)
    if sigma_px <= 0:
        return np.zeros((*points.shape[:-1], 3))
    fit = cap.config.fit.model_copy(update={"smooth_standard_px": 0.0})
    raw = dataclasses.replace(cap, config=cap.config.model_copy(update={"fit": fit}))
    setup = prepare_bands(raw, dtype=np.float64)
    if setup.box is None:
        return np.zeros((*points.shape[:-1], 3))
    w, h = (int(v) for v in np.asarray(setup.kernel["std_size"]))
    std = np.asarray(setup.kernel["std"], float)[:h, :w]
    u0, v0 = np.asarray(setup.kernel["offset"], float)
    uu, vv = np.meshgrid(u0 + np.arange(w), v0 + np.arange(h))
    pts, hit = back_project(cap.rig.camera, uu, vv)
    on = hit & in_box(pts, cap.rig.standard_box())  # the crop's margin holds the table: no noise of the standard
    v = std[..., 0:3] - std[..., 3:6]
    v = np.where((std[..., 6:9] > 0) | ~on[..., None], np.nan, v)  # clipped pixels, off the standard
    cmap = _relative_noise_map(v)
    if not np.isfinite(cmap).any():
        return np.zeros((*points.shape[:-1], 3))
    uv, _ = project(cap.rig.camera, mirror_point(points))
    c = sample_bilinear(cmap, uv - np.array([u0, v0]))
    return np.where(np.isfinite(c), c, np.nanmedian(cmap.reshape(-1, cmap.shape[-1]), axis=0))
