"""A capture folder as discovery data: what ``wardjax diagnose CAPTURE`` runs on.

The reconstruction is the capture pipeline's (:func:`wardjax.reconstruct_brdf`
against the mirror point on the standard, the standard smoothed as
:func:`wardjax.fit_capture` does, saturated and off-standard pixels masked);
the image columns through the probe are the scanlines, binned ``b × b`` so
that at most ``max_samples`` pixels per channel enter (as ``fit_capture``
bins for its fit).

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
    regression is unbiased — as ``σ² = s0 + s1 ȳ + s2 ȳ²`` (read floor, shot
    noise, a relative term), non-negative least squares, per channel.
    What remains biased upwards: the highlight's curvature where it is sharp
    on the pixel grid, and fine texture of the probe, which this estimate
    counts as noise.
"""

from __future__ import annotations

import math

import numpy as np

from ..capture import CAPTURE_FILE, Capture, CaptureError
from ._models import ScanlineData, scanline_data

__all__ = ["capture_data"]


def _noise_model(f: np.ndarray) -> np.ndarray:
    """σ per value from second-difference pseudo-residuals along axis 1 (see the module docstring).

    Parameters
    ----------
    f
        ``(S, N, C)`` values along ``S`` scanlines, NaN where missing; a
        triple with a missing value is skipped.

    Returns
    -------
    np.ndarray
        ``(S, N, C)``: ``σ = √(s0 + s1 f + s2 f²)`` with ``s0, s1, s2 ≥ 0`` fitted
        per channel to ``ε̃² = (f_{i−1} − 2 f_i + f_{i+1})² / 6`` against the
        triple's mean.
    """
    from scipy.optimize import nnls

    e2 = (f[:, :-2] - 2.0 * f[:, 1:-1] + f[:, 2:]) ** 2 / 6.0
    lvl = (f[:, :-2] + f[:, 1:-1] + f[:, 2:]) / 3.0
    sig = np.empty_like(f)
    for c in range(f.shape[-1]):
        ok = np.isfinite(e2[..., c]) & np.isfinite(lvl[..., c])
        ee, ll = e2[..., c][ok], lvl[..., c][ok]
        if ee.size < 8:
            raise CaptureError(CAPTURE_FILE, None, "too few neighbouring probe values to estimate the noise")
        scale = max(float(np.mean(np.abs(ll))), 1e-30)
        X = np.stack([np.ones_like(ll), ll / scale, (ll / scale) ** 2], -1)
        coef, _ = nnls(X, ee)
        coef[0] = max(coef[0], 1e-12 * max(float(np.mean(ee)), 1e-30))
        fc = np.abs(f[..., c]) / scale
        sig[..., c] = np.sqrt(coef[0] + coef[1] * fc + coef[2] * fc**2)
    return sig


def capture_data(cap: Capture, *, max_samples: int = 20_000, band_rows: int = 512) -> ScanlineData:
    """Reconstructed BRDF scanlines of a loaded capture, with positions, lamp and estimated noise.

    Parameters
    ----------
    cap
        A :class:`~wardjax.Capture` (``method = "scanline"``).
    max_samples
        Bin the probe so that at most this many pixels per channel remain.
    band_rows
        Rows processed at a time.
    """
    from ..pipeline import MIN_SCANLINE_SAMPLES, reconstruct_capture

    if cap.method != "scanline":
        raise CaptureError(CAPTURE_FILE, "method", f"diagnose needs method = 'scanline', got {cap.method!r}")
    cfg, rig = cap.config, cap.rig
    rec = reconstruct_capture(cap, band_rows=band_rows, dtype=np.float64)
    f_r, wi, wo, probe = rec.f_r, rec.wi, rec.wo, rec.probe
    pts = np.nan_to_num(rec.points)
    n_probe = int(probe.sum())
    if n_probe == 0:
        raise CaptureError(CAPTURE_FILE, "camera", "no pixel of the image sees the probe")
    rows = np.flatnonzero(probe.any(axis=1))
    colz = np.flatnonzero(probe.any(axis=0))
    sl = (slice(rows[0], rows[-1] + 1), slice(colz[0], colz[-1] + 1))
    b = max(1, math.ceil(math.sqrt(n_probe / max_samples)))

    def binned(a, fill):
        a = a[sl]
        hh, ww = a.shape[:2]
        a = np.pad(a, [(0, (-hh) % b), (0, (-ww) % b)] + [(0, 0)] * (a.ndim - 2), constant_values=fill)
        hh, ww = a.shape[:2]
        return a.reshape(hh // b, b, ww // b, b, *a.shape[2:])

    fb = binned(f_r, np.nan)
    fin = np.isfinite(fb)
    n_f = fin.sum(axis=(1, 3))
    f_bin = np.where(n_f >= max(1, b * b / 2), np.where(fin, fb, 0).sum(axis=(1, 3)) / np.maximum(n_f, 1), np.nan)
    pb = binned(probe, False)
    n_p = np.maximum(pb.sum(axis=(1, 3)), 1)[..., None]
    geo = {k: binned(a, 0.0).sum(axis=(1, 3)) / n_p for k, a in (("wi", wi), ("wo", wo), ("pts", pts))}
    for k in ("wi", "wo"):
        nrm = np.linalg.norm(geo[k], axis=-1, keepdims=True)
        geo[k] = np.where(nrm > 0, geo[k] / np.where(nrm > 0, nrm, 1), np.array([0.0, 0.0, 1.0]))
    # scanlines = image columns
    F = f_bin.transpose(1, 0, 2)
    WI, WO, P = (geo[k].transpose(1, 0, 2) for k in ("wi", "wo", "pts"))
    keep = np.sum(np.all(np.isfinite(F), axis=-1), axis=1) >= MIN_SCANLINE_SAMPLES
    if not keep.any():
        raise CaptureError(cfg.images.lit, None, f"no image column holds {MIN_SCANLINE_SAMPLES} usable probe values")
    F, WI, WO, P = F[keep], WI[keep], WO[keep], P[keep]
    sigma = _noise_model(F)
    return scanline_data(F, WI, WO, sigma, points=P, lamp=np.asarray(rig.lamp, float), kind="ratio",
                         rho_standard=float(np.mean(cap.rho_standard)))
