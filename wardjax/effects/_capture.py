"""A capture folder as discovery data: what ``wardjax diagnose CAPTURE`` runs on.

The reconstruction is the capture pipeline's (:func:`wardjax.reconstruct_brdf`
against the mirror point on the standard, the standard smoothed as
:func:`wardjax.fit_capture` does, off-standard pixels masked, probe pixels
the sensor clipped kept as censored lower bounds); the image columns
through the probe are the scanlines, binned ``b × b`` so that at most
``max_samples`` pixels per channel enter (the binning ``fit_capture`` uses).

Noise
    A capture carries no per-pixel σ. It is estimated from the data with the
    difference-based pseudo-residuals of Gasser, Sroka & Jennen-Steinmetz
    (1986, Biometrika 73, 625): along each scanline::

        ε̃_i = (y_{i−1} − 2 y_i + y_{i+1}) / √6,   E[ε̃_i²] = σ²  (white noise)

    The second difference cancels the signal's level *and* gradient, so the
    smooth change of the BRDF along a scanline (the highlight's flanks, the
    diffuse shading) does not count as noise; first differences did, and
    overestimated σ by ≈ 1.4 on a clean simulated capture (the gap read 0.53
    instead of ≈ 1). ``ε̃²`` is regressed on the level ``ȳ_i = (y_{i−1} + y_i
    + y_{i+1})/3`` — uncorrelated with ``ε̃_i`` for white noise, so the
    regression is unbiased — and on the lamp's inverse irradiance ``w =
    r²/cos θi`` as ``σ² = s0 w² + s1 ȳ w + s2 ȳ²`` (read floor, shot noise,
    a relative term: the sensor's noise divided by the irradiance the ratio
    takes out, :func:`~wardjax.effects._noise.noise_columns`), non-negative
    least squares, per channel. With ``σ²`` in ``ȳ`` alone the whitened
    residuals of a clean 160 × 120 capture ran from 0.5 near the lamp to 2.2
    far from it; with ``w`` 0.95–1.3.
    The standard's own noise, smoothed (``fit.smooth_standard_px``), is
    correlated along the scanline and escapes second differences; it is
    measured on the standard and added (:mod:`~wardjax.effects._standard_noise`).
    What remains biased upwards: the highlight's curvature where it is sharp
    on the pixel grid, and fine texture of the probe, which this estimate
    counts as noise.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ..capture import CAPTURE_FILE, Capture, CaptureError
from ._floor import floor_biased, floor_fraction
from ._models import ScanlineData, inv_irradiance, scanline_data
from ._noise import noise_columns
from ._pixel_levels import alternative_levels, pixel_levels
from ._standard_noise import bin_lag_correlation, smoothing_factor, standard_noise

__all__ = ["capture_data"]


def _noise_model(f: np.ndarray, exact: np.ndarray | None = None, w: np.ndarray | None = None) -> np.ndarray:
    """σ per value from second-difference pseudo-residuals along axis 1 (see the module docstring).

    Parameters
    ----------
    f
        ``(S, N, C)`` values along ``S`` scanlines, NaN where missing; a
        triple with a missing value is skipped.
    exact
        Optional ``(S, N, C)`` bool: only triples of these values enter the
        fit (censored values are bounds, not noisy measurements); σ is still
        given at every value.
    w
        Optional ``(S, N)`` inverse lamp irradiance ``r²/cos θi`` (any
        scale): the sensor's noise enters the BRDF divided by the irradiance
        (:func:`~wardjax.effects._noise.noise_columns`). ``None``: 1.

    Returns
    -------
    np.ndarray
        ``(S, N, C)``: ``σ = √(s0 w² + s1 f w + s2 f²)`` with ``s0, s1, s2 ≥ 0``
        fitted per channel to ``ε̃² = (f_{i−1} − 2 f_i + f_{i+1})² / 6`` against
        the triple's mean level and ``w``.
    """
    from scipy.optimize import nnls

    g = f if exact is None else np.where(exact, f, np.nan)
    w = np.ones(f.shape[:2]) if w is None else np.asarray(w, float)
    w = w / max(float(np.nanmean(w)), 1e-300)
    e2 = (g[:, :-2] - 2.0 * g[:, 1:-1] + g[:, 2:]) ** 2 / 6.0
    lvl = (g[:, :-2] + g[:, 1:-1] + g[:, 2:]) / 3.0
    wl = (w[:, :-2] + w[:, 1:-1] + w[:, 2:]) / 3.0
    sig = np.empty_like(f)
    for c in range(f.shape[-1]):
        ok = np.isfinite(e2[..., c]) & np.isfinite(lvl[..., c]) & np.isfinite(wl)
        ee, ll = e2[..., c][ok], lvl[..., c][ok]
        if ee.size < 8:
            raise CaptureError(CAPTURE_FILE, None, "too few neighbouring probe values to estimate the noise")
        scale = max(float(np.mean(np.abs(ll))), 1e-30)
        coef, _ = nnls(noise_columns(ll / scale, wl[ok]), ee)
        coef[0] = max(coef[0], 1e-12 * max(float(np.mean(ee)), 1e-30))
        sig[..., c] = np.sqrt(noise_columns(np.abs(f[..., c]) / scale, w) @ coef)
    return sig


def capture_data(cap: Capture, *, max_samples: int = 20_000, band_rows: int = 512) -> ScanlineData:
    """Reconstructed BRDF scanlines of a loaded capture, with positions, lamp and estimated noise.

    Probe pixels the sensor clipped enter as *censored* observations
    (``ScanlineData.censored``): their clip level as a BRDF value
    (:attr:`wardjax.pipeline.Reconstruction.f_clip`) is a lower bound on the
    true value, which the saturation effect fits with the censored
    likelihood. A bin holding any clipped pixel is censored, its value the
    mean of its values and bounds, a lower bound on its true mean
    (:func:`wardjax.pipeline._bin_scanlines`). A scanline is kept if it has
    ``MIN_SCANLINE_SAMPLES`` uncensored values (ρd is profiled from those);
    the noise model is fitted to uncensored triples only. Values the noise
    floor's cut biased upwards (the dim tail of a scanline where pixels fell
    below ``fit.noise_floor``) are dropped (:mod:`~wardjax.effects._floor`).

    Parameters
    ----------
    cap
        A :class:`~wardjax.Capture` (``method = "scanline"``).
    max_samples
        Bin the probe so that at most this many pixels per channel remain.
    band_rows
        Rows processed at a time.
    """
    from ..reconstruct import (
        MIN_SCANLINE_SAMPLES,
        MaskReason,
        bin_scanlines,
        check_measured,
        check_probe,
        mask_counts,
        prepare_bands,
        reconstruct_capture,
    )

    if cap.method != "scanline":
        raise CaptureError(CAPTURE_FILE, "method", f"diagnose needs method = 'scanline', got {cap.method!r}")
    cfg, rig = cap.config, cap.rig
    setup = prepare_bands(cap, band_rows=band_rows, dtype=np.float64)
    check_probe(cap, setup, band_rows)  # the checks wardjax fit applies: a capture it refuses is refused here
    rec = reconstruct_capture(cap, band_rows=band_rows, dtype=np.float64, clip_bounds=True, setup=setup)
    check_measured(cap, mask_counts(rec.probe, rec.flags), int((rec.probe & np.isfinite(rec.f_r).all(-1)).sum()))
    bins = bin_scanlines(rec, max_samples)  # scanlines = image columns
    F, cens = bins.f_r, bins.censored
    # values the noise floor's cut biased upwards are no evidence (wardjax.effects._floor)
    low = (rec.flags & MaskReason.BELOW_NOISE) > 0
    F = np.where(floor_biased(F, floor_fraction(low, rec.probe, bins.box, bins.b)) & ~cens, np.nan, F)
    keep = np.sum(np.all(np.isfinite(F) & ~cens, axis=-1), axis=1) >= MIN_SCANLINE_SAMPLES  # uncensored values
    if not keep.any():
        raise CaptureError(cfg.images.lit, None, f"no image column holds {MIN_SCANLINE_SAMPLES} usable probe values")
    F, cens = F[keep], cens[keep]
    wi, pts = bins.wi[keep], bins.points[keep]
    sigma = _noise_model(F, exact=~cens, w=inv_irradiance(pts, rig.lamp, wi))
    # the smoothed standard's noise, which second differences do not see (wardjax.effects._standard_noise)
    c = standard_noise(cap, pts)  # at each value's mirror point: the standard's level, and its noise, vary
    sigma_px = float(cap.config.fit.smooth_standard_px)
    share = c * smoothing_factor(sigma_px, bins.b) if sigma_px > 0 else np.zeros_like(c)
    sigma = np.sqrt(sigma * sigma + share * np.where(np.isfinite(F), F, 0.0) ** 2)
    # ... and which the fitted parameters average over many values: their covariance needs its lags too
    standard = None
    if sigma_px > 0 and np.any(c > 0):
        standard = (c, bin_lag_correlation(sigma_px, bins.b), np.flatnonzero(keep))  # c: (S, N, C), as F
    data = scanline_data(
        F,
        wi,
        bins.wo[keep],
        sigma,
        points=pts,
        lamp=np.asarray(rig.lamp, float),
        kind="ratio",
        rho_standard=float(np.mean(cap.rho_standard)),
        censored=cens,
        camera=rig.camera,
    )
    # the pixel levels behind each value, for the encoding effect (wardjax.effects._pixel_levels)
    binned = lambda img: bin_scanlines(rec._replace(f_r=img, f_clip=None), max_samples).f_r[keep]
    levels = pixel_levels(cap, setup, rec, binned)
    dark = (levels.pop("dark_pixel"), levels.pop("dark_room")) if cap.dark is not None else None
    enc, extra = cap.config.images.encoding, ("glare",)
    if enc in ("srgb", "gamma2.2"):  # the other encoding's reading of each level
        levels.update(alternative_levels(levels, F, enc))
        extra += ("encoding_alternative",)
    data = dataclasses.replace(data, pixels=levels, dark=dark, available=tuple(sorted(data.available + extra)))
    return data if standard is None else dataclasses.replace(data, standard=standard)
