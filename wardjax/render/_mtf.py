"""The slanted-edge MTF (ISO 12233 style): sharpness of an edge in a photograph or a render.

The smartphone paper compares the sharpness of gratings reflected in real and
rendered surfaces by the slanted-edge MTF (its Fig. 9c). The algorithm, on a
region holding one straight edge a few degrees off the image's vertical:

1. **Edge location**: per row, the centroid of the row's derivative
   (a second pass under a Hamming window centred on the first line fit), and a
   least-squares line ``x = a + b y`` through the centroids; the edge angle is
   ``atan b``.
2. **Super-sampled edge spread function**: every pixel's signed distance to the
   line along its normal, ``d = (x − a − b y) cos θ``, binned in bins of
   ``Δ = 1/oversample`` pixel; the ESF is the mean value per bin. The slant
   spreads the pixel centres evenly over the bins.
3. **Line spread function**: the central difference of the ESF, windowed by
   a Hamming window centred on its centroid.
4. **MTF**: ``|FFT(LSF)|`` normalised at zero frequency, frequencies in cycles
   per pixel along the edge normal, divided by the transfer of the binning
   (``sinc(f Δ)``) and of the central difference (``sinc(2 f Δ)``).

For a Gaussian blur of standard deviation ``σ`` (pixels) integrated over
square pixels the result is ``exp(−2π²σ²f²) · sinc(f)`` (normalised sinc),
which the tests check.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

__all__ = ["EdgeMTF", "slanted_edge_mtf"]


class EdgeMTF(NamedTuple):
    """What :func:`slanted_edge_mtf` measured.

    Attributes
    ----------
    frequency
        Cycles per pixel along the edge normal, from 0 to ``oversample / 2``.
    mtf
        The modulation transfer, 1 at zero frequency.
    angle
        The edge's angle from the image's vertical (radians; the image is
        transposed first when the edge is nearer horizontal, ``transposed``).
    esf, lsf
        The super-sampled edge and (windowed) line spread functions, bins of ``bin_width`` px.
    bin_width
        ``1 / oversample`` pixel.
    transposed
        The edge was nearer horizontal and the image was read transposed.
    """

    frequency: np.ndarray
    mtf: np.ndarray
    angle: float
    esf: np.ndarray
    lsf: np.ndarray
    bin_width: float
    transposed: bool


def _centroids(img: np.ndarray, window_centre: np.ndarray | None) -> np.ndarray:
    """Per row, the centroid (column) of the absolute derivative, optionally under a Hamming window."""
    deriv = np.abs(np.diff(img, axis=1))  # sample j sits at column j + 0.5
    cols = np.arange(deriv.shape[1]) + 0.5
    if window_centre is not None:
        half = deriv.shape[1] / 2
        u = np.clip((cols[None, :] - window_centre[:, None]) / half, -1, 1)
        deriv = deriv * (0.54 + 0.46 * np.cos(np.pi * u))
    return (deriv @ cols) / np.maximum(deriv.sum(axis=1), 1e-300)


def slanted_edge_mtf(image, *, oversample: int = 4) -> EdgeMTF:
    """The MTF of a slanted edge (ISO 12233 style); see the module docstring for the algorithm.

    Parameters
    ----------
    image
        ``(H, W)`` (or ``(H, W, 3)``, averaged over channels) linear values of a
        region with one straight edge 2–20° off vertical or horizontal, the
        edge crossing every row (column).
    oversample
        Bins per pixel of the edge spread function (ISO 12233: 4).

    Returns
    -------
    EdgeMTF
    """
    img = np.asarray(image, np.float64)
    if img.ndim == 3:
        img = img.mean(axis=-1)
    if img.ndim != 2 or min(img.shape) < 8:
        raise ValueError(f"slanted_edge_mtf: expected an (H, W) region of at least 8 × 8 pixels, got {img.shape}")
    if not np.all(np.isfinite(img)):
        raise ValueError("slanted_edge_mtf: the region holds NaN or infinite values")
    gy, gx = (float(np.abs(np.diff(img, axis=a)).sum()) for a in (0, 1))
    transposed = gy > gx
    if transposed:
        img = img.T
    rows = np.arange(img.shape[0], dtype=np.float64)
    c = _centroids(img, None)
    b, a = np.polyfit(rows, c, 1)
    b, a = np.polyfit(rows, _centroids(img, a + b * rows), 1)
    cos = 1.0 / np.hypot(1.0, b)
    d = (np.arange(img.shape[1])[None, :] - (a + b * rows)[:, None]) * cos
    # Bins every row covers: up to the nearest image side from the edge.
    reach = min(float(d[:, 0].max()) * -1, float(d[:, -1].min()))
    delta = 1.0 / oversample
    nb = int(np.floor(reach / delta))
    k = np.floor(d / delta).astype(np.int64) + nb
    ok = (k >= 0) & (k < 2 * nb)
    counts = np.bincount(k[ok], minlength=2 * nb)
    sums = np.bincount(k[ok], weights=img[ok], minlength=2 * nb)
    centres = (np.arange(2 * nb) - nb + 0.5) * delta
    filled = counts > 0
    esf = np.interp(centres, centres[filled], sums[filled] / counts[filled])
    lsf = np.zeros_like(esf)
    lsf[1:-1] = (esf[2:] - esf[:-2]) / 2.0
    if lsf.sum() < 0:
        lsf = -lsf
    mid = float((centres * lsf).sum() / lsf.sum())
    half = float(min(mid - centres[0], centres[-1] - mid))
    u = np.clip((centres - mid) / half, -1, 1)
    lsf_w = lsf * (0.54 + 0.46 * np.cos(np.pi * u))
    spectrum = np.abs(np.fft.rfft(lsf_w))
    f = np.fft.rfftfreq(lsf_w.size, d=delta)
    mtf = spectrum / spectrum[0] / (np.sinc(f * delta) * np.sinc(2 * f * delta))
    return EdgeMTF(f, mtf, float(np.arctan(b)), esf, lsf_w, delta, bool(transposed))
