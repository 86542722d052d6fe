"""The values the noise floor biased: dropped from discovery's evidence.

The reconstruction masks a pixel whose lamp signal ``lit − dark`` falls below
``fit.noise_floor`` (:attr:`wardjax.MaskReason.BELOW_NOISE`). Where the true
signal is within a few noise SDs of that floor the cut is a *truncation*: the
pixels that survive are the ones the noise pushed up, so the mean of what is
left is biased upwards. For a truncated normal, ``E[v | v > c] = μ + σ
φ(a)/(1 − Φ(a))`` with ``a = (c − μ)/σ``: a floor one SD above the true
signal raises the surviving mean by ``1.5 σ``. On a dark glossy material (ρd
0.03 under a lobe 450× brighter) the diffuse floor sits at the noise floor:
the surviving values read +31 % on average, +116 % in the bins the floor
touched, a pattern that grows with the distance from the highlight, which
discovery then names retroreflection.

The bias vanishes where the floor is several SDs below the signal, and that is
where no pixel is masked. So, along each scanline and per channel, the tail the
floor reaches is dropped *by position*: on each side of the scanline's
brightest value, every value from the innermost bin holding a pixel masked
below the noise floor out to the scanline's end, and ``MARGIN`` bins more
towards the highlight. The cut must not be made on the values themselves: a
rule "drop what reads at or below the highest level a masked bin reached"
truncates again at that level (what survives just above it is what the noise
pushed up), and on the dark metal that second truncation left the dim
flanks +0.1 to +0.6 noise SDs high, which narrowed the fitted lobe (α −0.06 %,
z ≈ −2 on a capture with a noise-free standard). By position, the values left
read within a twentieth of an SD; a capture whose floor never bites loses
nothing.
"""

from __future__ import annotations

import numpy as np

__all__ = ["MARGIN", "floor_biased", "floor_fraction"]

# Bins dropped beyond the innermost masked one, towards the highlight: the bins next to it sit within a few
# noise SDs of the floor too, and "none of my pixels was masked" selects their noise upwards.
MARGIN = 2


def floor_fraction(low: np.ndarray, probe: np.ndarray, box: tuple[slice, slice], b: int) -> np.ndarray:
    """Per bin, the fraction of its probe pixels masked below the noise floor, scanlines first.

    Parameters
    ----------
    low, probe
        ``(H, W)`` bool: the pixel is masked ``BELOW_NOISE``; the pixel is on the probe.
    box, b
        The bins' box and size (:class:`wardjax.reconstruct.ScanlineBins`).

    Returns
    -------
    np.ndarray
        ``(S, N)`` in ``[0, 1]``, the layout of :func:`wardjax.reconstruct.bin_scanlines` (image columns as
        scanlines).
    """
    from ..reconstruct import bin_sums

    n = bin_sums(probe[box], b)
    return (bin_sums((low & probe)[box], b) / np.maximum(n, 1.0)).T


def floor_biased(f: np.ndarray, fraction: np.ndarray) -> np.ndarray:
    """Where the noise floor's truncation biases the values: ``(S, N, C)`` bool.

    Parameters
    ----------
    f
        ``(S, N, C)`` values along ``S`` scanlines, NaN where missing.
    fraction
        ``(S, N)``: the share of each bin's pixels masked below the noise floor (:func:`floor_fraction`).

    Returns
    -------
    np.ndarray
        ``True`` from each end of a scanline (per channel) to ``MARGIN`` bins past the innermost bin holding a
        pixel below the floor on that side of the scanline's brightest value (see the module docstring). All
        ``False`` where no pixel is below the floor.
    """
    n = f.shape[1]
    hit = np.broadcast_to((fraction > 0)[..., None], f.shape)
    idx = np.arange(n)[None, :, None]
    peak = np.argmax(np.where(np.isfinite(f), f, -np.inf), axis=1)[:, None, :]  # (S, 1, C)
    below = np.max(np.where(hit & (idx < peak), idx, -n), axis=1, keepdims=True)  # innermost hit before the peak
    above = np.min(np.where(hit & (idx > peak), idx, 2 * n), axis=1, keepdims=True)  # and after it
    return hit | (idx <= below + MARGIN) | (idx >= above - MARGIN)
