"""Lens falloff (vignetting) calibrated from a flat-field photo.

A flat field is a photo of a uniformly lit, uniform target (a white sheet
under overcast light, a light box) taken with the lens and focus of the
capture. Its falloff away from the image centre is modelled as an even
polynomial in the normalised radius (Kang & Weiss 2000; the polynomial form
of Goldman 2010, eq. 5)::

    V(r) = 1 + a₁ r² + a₂ r⁴ + a₃ r⁶,   r = |(u, v) − (cx, cy)| / half-diagonal

fitted by linear least squares to the flat field's luminance (with its
value at the centre as a fourth unknown). A photo divided by ``V`` reads as if the lens had no
falloff.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

__all__ = ["Vignetting", "fit_vignetting", "radius_map"]


def radius_map(height: int, width: int) -> np.ndarray:
    """``(H, W)`` distance of each pixel centre from the image centre, in units of the half-diagonal."""
    v, u = np.mgrid[0:height, 0:width].astype(np.float64)
    half_diag = 0.5 * np.hypot(width - 1, height - 1)
    return np.hypot(u - (width - 1) / 2, v - (height - 1) / 2) / max(half_diag, 1e-12)


class Vignetting(NamedTuple):
    """The falloff ``V(r) = 1 + a₁ r² + a₂ r⁴ + a₃ r⁶`` (``coeffs = (a₁, a₂, a₃)``) and its fit's RMS residual."""

    coeffs: tuple[float, float, float]
    rms: float

    def gain(self, height: int, width: int) -> np.ndarray:
        """``(H, W)`` relative sensitivity ``V`` of each pixel (1 at the centre)."""
        r2 = radius_map(height, width) ** 2
        a1, a2, a3 = self.coeffs
        return 1.0 + r2 * (a1 + r2 * (a2 + r2 * a3))


def fit_vignetting(flat: np.ndarray, *, saturation: float = 1.0) -> Vignetting:
    """Fit :class:`Vignetting` to a linear flat-field image.

    Parameters
    ----------
    flat
        ``(H, W)`` or ``(H, W, C)`` linear values of the flat-field photo.
    saturation
        Values at or above this are left out of the fit (clipped).

    Returns
    -------
    Vignetting
        The coefficients; the RMS of the fit's relative residual says how well the
        flat field follows a radial falloff (a non-uniformly lit target does not).
    """
    a = np.asarray(flat, np.float64)
    lum = a.mean(axis=-1) if a.ndim == 3 else a
    h, w = lum.shape
    r = radius_map(h, w)
    ok = np.isfinite(lum) & (lum > 0) & (lum < saturation)
    if ok.sum() < 10 or not (ok & (r < 0.25)).any():
        raise ValueError("the flat field has too few usable pixels near its centre (dark, clipped or not finite)")
    # lum = b₀ (1 + a₁ r² + a₂ r⁴ + a₃ r⁶): linear in (b₀, b₀a₁, b₀a₂, b₀a₃)
    r2 = r[ok] ** 2
    design = np.stack([np.ones_like(r2), r2, r2**2, r2**3], -1)
    b, *_ = np.linalg.lstsq(design, lum[ok], rcond=None)
    coeffs = b[1:] / b[0]
    fitted = design @ b
    rms = float(np.sqrt(np.mean((lum[ok] / fitted - 1.0) ** 2)))
    return Vignetting((float(coeffs[0]), float(coeffs[1]), float(coeffs[2])), rms)
