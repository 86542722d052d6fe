"""Lobes found on a sample of the pixels, then refined on all of them.

A lobe is one to three numbers shared by many pixels; its profiled χ² is a sum
over its pixels, so a random sample of ``S`` of the ``P`` pixels places the
minimum within ``√(P/S)`` of the lobe's σ on all of them. The search — the
grid in ``log α``, the Levenberg–Marquardt steps, and for clusters the
k-means, EM rounds and BIC of every count — runs on a sample of
:data:`LOBE_SAMPLE` pixels; then, on all pixels, each pixel takes the lobe of
lowest ``χ²_pl − 2 log π_l`` (``π`` the sample's shares), the lobes take a few
Levenberg–Marquardt steps (from that close a Gauss–Newton step converges at
once), and the pixels are assigned again. With at most :data:`LOBE_SAMPLE`
pixels everything runs on all of them.
"""

from __future__ import annotations

import math

import jax.numpy as jnp
import numpy as np

from . import _pixel_model as pm

__all__ = ["LOBE_SAMPLE", "POLISH", "assign", "pixel_sample", "spread", "take"]

LOBE_SAMPLE = 16384  # above this many pixels the lobes are searched for on a sample of them
POLISH = 2  # Levenberg–Marquardt steps of the lobes on all pixels after the sample's search


def pixel_sample(p: int, seed: int) -> np.ndarray | None:
    """``(S,)`` sorted indices of :data:`LOBE_SAMPLE` pixels drawn without replacement, or ``None`` for all."""
    if p <= LOBE_SAMPLE:
        return None
    return np.sort(np.random.default_rng(seed).choice(p, size=LOBE_SAMPLE, replace=False))


def take(idx, geom: pm.PixelGeometry, *arrays):
    """``geom`` and ``arrays`` (``(P, …)`` each) restricted to the pixels ``idx`` (all where ``None``)."""
    if idx is None:
        return (geom, *arrays)
    i = jnp.asarray(idx)
    return (pm.PixelGeometry(*(x[i] for x in geom)), *(x[i] for x in arrays))


def assign(theta, s, log_pi, geom, f, w):
    """``(P,)`` each pixel's lobe: lowest ``χ²_pl − 2 log π_l`` (``theta (L, d)``, ``s``, ``log_pi (L,)``)."""
    costs = pm.assign_costs(theta, s, geom, f, w, n_lobes=int(theta.shape[0]))
    return jnp.argmin(costs - 2.0 * jnp.asarray(log_pi)[None], 1).astype(jnp.int32)


def spread(theta, s, labels_sample, geom, f, w, steps: int = POLISH):
    """Lobes found on a sample, carried to all ``P`` pixels; returns ``theta``, ``s``, ``labels (P,)``.

    The sample's labels give the shares ``π``; all pixels are assigned, the lobes refined by ``steps``
    Levenberg–Marquardt steps on all of them, and the pixels assigned again under the refined lobes.
    """
    k = int(theta.shape[0])
    share = np.bincount(np.asarray(labels_sample), minlength=k) / max(int(labels_sample.shape[0]), 1)
    log_pi = np.where(share > 0, np.log(np.maximum(share, 1e-300)), -math.inf)
    labels = assign(theta, s, log_pi, geom, f, w)
    theta, s, _ = pm.lobe_fit(theta, labels, geom, f, w, n_lobes=k, steps=steps)
    return theta, s, assign(theta, s, log_pi, geom, f, w)
