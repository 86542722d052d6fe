"""Bucketed array shapes, so that inputs of slightly different sizes share one compiled program.

A jitted kernel compiles once per input shape (seconds each on CPU). The
captures of one rig differ by a few pixels wherever the probe and standard
sit, so every size that follows from them (bands, crops, scanlines, samples
per scanline) is padded up to :func:`bucket` of itself and the padding is
masked out (zero weight, NaN values) or sliced off.
"""

from __future__ import annotations

import functools
import operator
from typing import SupportsIndex

import jax
import jax.numpy as jnp
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


def pad_to_shape(a, shape: tuple[SupportsIndex, ...], fill: float | int = 0):
    """``a`` padded with ``fill`` at the end of its leading axes to ``shape``.

    A :class:`jax.Array` is padded on its device by a compiled pad (no value
    travels through the host); anything else is padded as a NumPy array.
    """
    if not isinstance(a, jax.Array):
        a = np.asarray(a)
    if a.shape[: len(shape)] == tuple(shape):
        return a
    widths = tuple((0, int(t) - n) for t, n in zip(shape, a.shape)) + ((0, 0),) * (a.ndim - len(shape))
    if isinstance(a, jax.Array):
        nan = bool(np.isnan(fill))
        return _pad_on_device(a, widths=widths, nan=nan, fill=0 if nan else fill)
    return np.pad(a, widths, constant_values=fill)


@functools.partial(jax.jit, static_argnames=("widths", "nan", "fill"))
def _pad_on_device(a, *, widths, nan, fill):
    return jnp.pad(a, widths, constant_values=jnp.nan if nan else fill)
