"""Specular-lobe SD from a goniometric curve (smartphone paper, section 4 and Table III).

The paper's roughness correlate: a glossmeter's linear sensor gives the reflected signal
``v(θ)`` at angles ``θ`` around the specular direction. The minimum of the curve is
subtracted (to remove most of the diffuse floor), the rest is treated as a distribution
over angle, and its standard deviation is the lobe SD:

.. math::

    w(θ) = v(θ) - \\min_θ v, \\qquad
    \\bar θ = \\frac{\\int θ\\, w\\, dθ}{\\int w\\, dθ}, \\qquad
    \\mathrm{SD} = \\sqrt{\\frac{\\int (θ - \\bar θ)^2 w\\, dθ}{\\int w\\, dθ}}

(the integrals by the trapezoidal rule, so unevenly spaced angles are weighted by their
spacing). For a Gaussian lobe of SD σ on a constant floor, seen over a window much wider
than σ, the result is σ; a window only a few σ wide gives less, because the subtracted
minimum also removes the lobe's tails.

:func:`lobe_sd_percent_error` is the error convention of the paper's section 9, which
reproduces its six quoted figures from the Table III values: the larger SD over the
smaller, minus one, in percent.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["lobe_sd_from_gonio", "lobe_sd_percent_error"]


def lobe_sd_from_gonio(angles_deg: ArrayLike, values: ArrayLike) -> NDArray:
    """Lobe SD (degrees) of goniometric curves: minimum subtracted, SD of the rest over angle.

    Parameters
    ----------
    angles_deg
        Sensor angles in degrees, shape (n,), n ≥ 3, strictly increasing.
    values
        Reflected signal at those angles, shape (..., n); any positive scale.

    Returns
    -------
    ndarray
        Lobe SD in degrees, shape (...). NaN where a curve is flat (no lobe left after
        the minimum is subtracted) or holds a non-finite value.
    """
    th = np.asarray(angles_deg, dtype=np.float64)
    v = np.asarray(values, dtype=np.float64)
    if th.ndim != 1 or th.shape[0] < 3 or not np.all(np.diff(th) > 0):
        raise ValueError(f"angles_deg must be strictly increasing with shape (n ≥ 3,); got shape {th.shape}")
    if v.ndim < 1 or v.shape[-1] != th.shape[0]:
        raise ValueError(f"values must have shape (..., {th.shape[0]}) to match angles_deg; got {v.shape}")
    w = v - v.min(axis=-1, keepdims=True)
    mass = np.trapezoid(w, th, axis=-1)
    ok = np.isfinite(mass) & (mass > 0)
    safe = np.where(ok, mass, 1.0)
    mean = np.trapezoid(w * th, th, axis=-1) / safe
    var = np.trapezoid(w * (th - mean[..., None]) ** 2, th, axis=-1) / safe
    return np.asarray(np.where(ok, np.sqrt(np.clip(var, 0.0, None)), np.nan))


def lobe_sd_percent_error(measured: ArrayLike, estimated: ArrayLike) -> NDArray:
    """Percent error between measured and estimated lobe SDs, as the paper's section 9 quotes it.

    .. math:: e = 100 \\left(\\frac{\\max(s_m, s_e)}{\\min(s_m, s_e)} - 1\\right)

    Symmetric in its arguments, so an estimate twice or half the measurement is 100 % off.
    Both inputs must be positive; broadcasting applies.
    """
    m = np.asarray(measured, dtype=np.float64)
    e = np.asarray(estimated, dtype=np.float64)
    if not (np.all(m > 0) and np.all(e > 0)):
        raise ValueError(f"lobe SDs must be positive; got measured {m} and estimated {e}")
    return np.asarray(100.0 * (np.maximum(m, e) / np.minimum(m, e) - 1.0))
