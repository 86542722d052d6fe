"""Lobes found on a sample of the pixels, finished on all of them in one pass.

The lobes (and the cluster count) are searched for on a sample of ``S`` of the
``P`` pixels (:mod:`._pixel_sample`), which places each within ``√(P/S)`` of
its σ on all pixels: close enough that one Gauss–Newton step on all pixels
reaches the optimum. One pass over the pixels assigns each pixel the lobe of
lowest ``χ²_pl − 2 log π_l`` (``π`` the sample's shares) and builds each lobe's
Gram matrix of ``(f̃, B̃, ∂B̃/∂θ…)`` at the sample's lobe (the notation of
:mod:`._pixel_model`: ``x̃`` is ``x`` with each pixel's ρd projected out);
from it, the step in ``φ = (s, θ)`` solves the normal equations of the
linearised model ``s B + δs B + s Σ_j δθ_j ∂B/∂θ_j``,

.. math::

    \\begin{pmatrix} G_{BB} & s G_{BB'} \\\\ s G_{B'B} & s^2 G_{B'B'} \\end{pmatrix}
    \\begin{pmatrix} δs \\\\ δθ \\end{pmatrix} =
    \\begin{pmatrix} G_{Bf} − s G_{BB} \\\\ s (G_{B'f} − s G_{B'B}) \\end{pmatrix}

(Gauss–Newton, Nocedal & Wright eq. 10.23). The same pass gives each lobe's
χ² before the step, ``G_ff − 2 s G_Bf + s² G_BB``; the caller's one pass for
every pixel's ρd (linear at fixed lobes), σ and χ² then checks the step: a lobe
whose χ² did not fall keeps the sample's values (and that pass is run again).
"""

from __future__ import annotations

import functools
import math

import jax
import jax.numpy as jnp
import numpy as np

from . import _pixel_model as pm

__all__ = ["log_shares", "refine_on_all", "steps_that_failed"]


def log_shares(labels_sample, n_lobes: int) -> np.ndarray:
    """``(L,)`` ``log π`` of each lobe's share of the sample's pixels (``−∞`` for an empty one)."""
    share = np.bincount(np.asarray(labels_sample), minlength=n_lobes) / max(int(labels_sample.shape[0]), 1)
    return np.where(share > 0, np.log(np.maximum(share, 1e-300)), -math.inf)


@functools.partial(jax.jit, static_argnames="n_lobes")
def refine_on_all(theta, s, log_pi, geom, f, w, *, n_lobes: int):
    """One pass over all pixels: labels, and one Gauss–Newton step of every lobe (module docstring).

    ``theta (L, d)``, ``s (L,)`` the sample's lobes, ``log_pi (L,)`` its shares. Returns the stepped
    ``theta``, ``s``, ``labels (P,)`` and each lobe's χ² before the step ``(L,)``.
    """
    if n_lobes == 1:
        labels = jnp.zeros(f.shape[0], jnp.int32)
    else:
        costs = pm.assign_costs(theta, s, geom, f, w, n_lobes=n_lobes)
        labels = jnp.argmin(costs - 2.0 * log_pi[None], 1).astype(jnp.int32)
    gram = pm.lobe_gram(theta, labels, geom, f, w, n_lobes=n_lobes)
    d = theta.shape[-1]
    g_bb, g_bf = gram[:, 1, 1], gram[:, 1, 0]
    g_pb, g_pf, g_pp = gram[:, 2:, 1], gram[:, 2:, 0], gram[:, 2:, 2:]
    ss = s[:, None]
    top = jnp.concatenate([g_bb[:, None], ss * g_pb], -1)  # (L, 1+d)
    low = jnp.concatenate([ss[..., None] * g_pb[..., None], (s * s)[:, None, None] * g_pp], -1)  # (L, d, 1+d)
    info = jnp.concatenate([top[:, None], low], 1)
    rhs = jnp.concatenate([(g_bf - s * g_bb)[:, None], ss * (g_pf - ss * g_pb)], -1)
    tiny = 1e-12 * jnp.maximum(jnp.diagonal(info, axis1=1, axis2=2), 1e-300)
    delta = jnp.linalg.solve(info + tiny[:, :, None] * jnp.eye(1 + d)[None], rhs[..., None])[..., 0]
    delta = jnp.nan_to_num(delta)  # a lobe no pixel took keeps its values
    s_new = jnp.maximum(s + delta[:, 0], 0.0)
    theta_new = jnp.clip(theta + jnp.clip(delta[:, 1:], -1.0, 1.0), pm.LOG_ALPHA_MIN, pm.LOG_ALPHA_MAX)
    before = gram[:, 0, 0] - s * (2.0 * g_bf - s * g_bb)
    return theta_new, s_new, labels, before


def steps_that_failed(pixel_chi2, labels, before, n_lobes: int) -> np.ndarray:
    """``(L,)`` True where a lobe's χ² after the step, ``Σ_{p∈l} χ²_p``, is not below its χ² before.

    A step must lower χ² by more than rounding (10⁻⁹ of it): where the lobe is barely identified (one
    photo per pixel, each pixel's ρd absorbing its value) χ² is flat along ρs, and a step along that
    valley would move ρs (and every pixel's ρd with it) for nothing.
    """
    after = np.bincount(np.asarray(labels), weights=np.asarray(pixel_chi2), minlength=n_lobes)
    b = np.asarray(before)
    return after >= b - 1e-9 * np.abs(b)
