"""The spatial-frequency spectrum of a reflected grating (the smartphone paper's Fig. 9c, as a profile spectrum).

The region's luminance (RGB averaged) is averaged along the bars into one
profile ``p(x)``; its amplitude spectrum, under a Hann window ``w`` and
relative to the mean level, is

.. math::

    A(f) = \\frac{2\\,|\\mathrm{DFT}[(p - \\bar p)\\,w](f)|}{\\bar p \\sum w}

so that a sinusoid ``p̄ (1 + m cos 2πf₀x)`` at a DFT frequency gives ``A(f₀) = m``
(its modulation) and a square wave of contrast ``m`` gives ``4m/π`` at its
fundamental and ``4m/(3π)`` at the third harmonic. A blurred reflection keeps
the fundamental longer than the harmonics; the paper compares real and
rendered reflections by slanted-edge MTFs (:func:`wardjax.render.slanted_edge_mtf`),
which the validation notebook also computes on one reflected edge.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

__all__ = ["GratingSpectrum", "grating_spectrum"]


class GratingSpectrum(NamedTuple):
    """What :func:`grating_spectrum` measured: ``frequency`` (cycles per pixel), ``amplitude`` (relative to the
    mean), the ``profile`` across the bars and its ``mean``."""

    frequency: np.ndarray
    amplitude: np.ndarray
    profile: np.ndarray
    mean: float


def grating_spectrum(region, *, axis: int = 1) -> GratingSpectrum:
    """Amplitude spectrum of the profile across a grating's bars (see the module docstring).

    Parameters
    ----------
    region
        ``(H, W)`` or ``(H, W, 3)`` linear values holding the grating.
    axis
        The image axis across the bars (1: bars run top to bottom).
    """
    img = np.asarray(region, np.float64)
    if img.ndim == 3:
        img = img.mean(axis=-1)
    if img.ndim != 2 or img.shape[axis] < 8 or not np.all(np.isfinite(img)):
        raise ValueError(f"grating_spectrum: expected a finite (H, W) region at least 8 pixels across, got {img.shape}")
    profile = img.mean(axis=1 - axis)
    mean = float(profile.mean())
    if not mean > 0:
        raise ValueError("grating_spectrum: the region's mean level must be > 0")
    w = 0.5 - 0.5 * np.cos(2 * np.pi * np.arange(profile.size) / profile.size)  # periodic Hann
    amp = 2 * np.abs(np.fft.rfft((profile - mean) * w)) / (mean * w.sum())
    return GratingSpectrum(np.fft.rfftfreq(profile.size), amp, profile, mean)
