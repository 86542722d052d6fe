"""Bucketed array shapes, so that inputs of slightly different sizes share one compiled program.

A jitted kernel compiles once per input shape (seconds each on CPU). The
captures of one rig differ by a few pixels wherever the probe and standard
sit, so every size that follows from them (bands, crops, scanlines, samples
per scanline) is padded up to :func:`bucket` of itself and the padding is
masked out (zero weight, NaN values) or sliced off.
"""

from __future__ import annotations

import operator
from typing import SupportsIndex

import numpy as np


def bucket(n: SupportsIndex) -> int:
    """The size a compiled kernel is padded to: the smallest ``m ≥ n`` on the ladder ``2^j · {5, 6, 7, 8}/4``.

    For ``2^j < n ≤ 2^(j+1)``, ``m`` is ``n`` rounded up to a multiple of
    ``max(2^(j−2), 8)``: at most 25 % (or 7) over, so captures whose probe and
    standard sit in slightly different places share one compiled program
    instead of compiling (seconds) once per capture.
    """
    n = max(operator.index(n), 1)
    q = max(1 << max((n - 1).bit_length() - 3, 0), 8)
    return -(-n // q) * q


def pad_to_shape(a: np.ndarray, shape: tuple[SupportsIndex, ...], fill: float | int = 0) -> np.ndarray:
    """``a`` padded with ``fill`` at the end of its leading axes to ``shape``."""
    a = np.asarray(a)
    if a.shape[: len(shape)] == tuple(shape):
        return a
    return np.pad(
        a, [(0, t - n) for t, n in zip(shape, a.shape)] + [(0, 0)] * (a.ndim - len(shape)), constant_values=fill
    )
