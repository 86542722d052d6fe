"""A capture folder as discovery data: what ``wardjax diagnose CAPTURE`` runs on.

The reconstruction is the capture pipeline's (:func:`wardjax.reconstruct_brdf`
against the mirror point on the standard, the standard smoothed as
:func:`wardjax.fit_capture` does, saturated and off-standard pixels masked);
the image columns through the probe are the scanlines, binned ``b × b`` so
that at most ``max_samples`` pixels per channel enter (as ``fit_capture``
bins for its fit).

Noise
    A capture carries no per-pixel σ. It is estimated from the data: along
    each scanline the differences of neighbouring binned values, ``d``,
    against their level ``ȳ``; ``E[d²/2] = s0² + s1² ȳ²`` (a floor plus a
    relative term) is fitted by least squares over all scanlines, per
    channel. Fine texture of the probe counts as noise by this estimate.
"""

from __future__ import annotations

import math

import numpy as np

from ..capture import CAPTURE_FILE, Capture, CaptureError
from ._models import ScanlineData, scanline_data

__all__ = ["capture_data"]


def _noise_model(f: np.ndarray) -> np.ndarray:
    """σ per value from neighbour differences along axis 1, ``σ² = s0² + s1² y²`` per channel."""
    d = np.diff(f, axis=1)
    m = 0.5 * (f[:, 1:] + f[:, :-1])
    sig = np.empty_like(f)
    for c in range(f.shape[-1]):
        ok = np.isfinite(d[..., c]) & np.isfinite(m[..., c])
        dd, mm = 0.5 * d[..., c][ok] ** 2, m[..., c][ok]
        if dd.size < 4:
            raise CaptureError(CAPTURE_FILE, None, "too few neighbouring probe values to estimate the noise")
        X = np.stack([np.ones_like(mm), mm**2], -1)
        coef, *_ = np.linalg.lstsq(X, dd, rcond=None)
        coef = np.maximum(coef, [1e-12 * max(np.mean(dd), 1e-30), 0.0])
        sig[..., c] = np.sqrt(coef[0] + coef[1] * f[..., c] ** 2)
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
    from ..pipeline import reconstruct_capture

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
    keep = np.sum(np.all(np.isfinite(F), axis=-1), axis=1) >= 8
    if not keep.any():
        raise CaptureError(cfg.images.lit, None, "no image column holds 8 usable probe values")
    F, WI, WO, P = F[keep], WI[keep], WO[keep], P[keep]
    sigma = _noise_model(F)
    return scanline_data(F, WI, WO, sigma, points=P, lamp=np.asarray(rig.lamp, float), kind="ratio",
                         rho_standard=float(np.mean(cap.rho_standard)))
