"""Per-material lobes: the cluster count chosen by BIC of a mixture of lobes, each lobe refitted by hard EM.

The lobes of per-pixel fits (:func:`~wardjax.fit_scanlines`) on a sample of
:data:`_SEED_PIXELS` pixels are clustered by k-means in ``(log ρs, log α)``
for ``k = 1 … MAX_CLUSTERS``; each ``k`` is refitted on the pixels given by
hard EM (every pixel to the lobe of lowest ``χ²_pl − 2 log π_l``, its ρd
profiled; the lobes by :func:`._pixel_model.lobe_fit`), and the count of
lowest BIC of the mixture,

.. math::

    −2 \\sum_p \\log \\sum_l π_l e^{−χ²_{pl}/2} + (k(1+d) + k − 1) \\ln n,

is kept (``n`` the number of observations). A count whose clusters hold under
2 % of the pixels, or whose lobe no material has (ρs > 1, α at its bound), is
not considered; nor is one whose held-out χ² (:mod:`._pixel_heldout`: each
photo predicted from each pixel's other photos) is not below that of every
smaller count. Far from the data (bumps fitted flat) the BIC falls with every
lobe that fits a highlight of the fitted photos; the held-out photos refuse them.
Where no pixel has two usable photos (one photo) nothing can be held out, and
the BIC decides alone.
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
from scipy.cluster.vq import kmeans2

from . import _pixel_model as pm
from ._pixel_heldout import heldout_chi2
from ._scanline import fit_scanlines

__all__ = ["EM_ROUNDS", "MAX_CLUSTERS", "STEPS", "choose_clusters", "for_scanlines", "min_cluster_size"]

MAX_CLUSTERS = 4  # the largest count tried when the data choose it
STEPS = 8  # Levenberg–Marquardt steps per lobe fit (one compiled program for every call)
EM_ROUNDS = 4
_SEED_PIXELS = 4096  # pixels fitted alone to seed the clusters


def for_scanlines(f, w):
    """The 3-channel arrays :func:`fit_scanlines` takes (a grey channel repeated, its weight shared)."""
    if f.shape[-1] == 3:
        return f, w
    grey = np.sum(w * f, -1, keepdims=True) / np.maximum(np.sum(w, -1, keepdims=True), 1e-300)
    return np.repeat(grey, 3, -1), np.repeat(np.sum(w, -1, keepdims=True) / 3.0, 3, -1)


def min_cluster_size(p: int) -> int:
    """The fewest of ``p`` pixels a cluster must hold: 2 % of them, at least 10."""
    return max(10, p // 50)


def choose_clusters(data, geom, shared, d, n_clusters, seed, normalization, ln_n):
    """Choose the count and fit a lobe per cluster; returns ``(theta, s, labels, evidence)``.

    ``data = (f, w, wi, wo)`` and ``geom`` of the pixels the clusters are chosen on; ``shared = (θ, s, χ²)``
    the shared lobe's fit on them. Every count is fitted with :data:`MAX_CLUSTERS` lobe slots (unused ones
    parked with no pixels) so that one compiled program serves them all.
    """
    f, w, wi, wo = data
    p = f.shape[0]
    rng = np.random.default_rng(seed)
    sub = np.sort(rng.choice(p, size=min(p, _SEED_PIXELS), replace=False))
    fs, ws = for_scanlines(np.asarray(f[sub]), np.asarray(w[sub]))
    one = fit_scanlines(
        fs,
        np.asarray(wi[sub]),
        np.asarray(wo[sub]),
        weights=ws,
        mask=np.all(ws > 0, -1),
        normalization=normalization,
        errors="gauss_newton",
    )
    # Seeds only from lobes a material can have: a bump's or a noise spike's fit (ρs ≫ 1, α at its bound) would
    # pull a k-means centre of its own far from every material, and EM from there stays non-physical.
    a_one = one.params.alpha_x
    good = (
        one.ok
        & (one.params.rho_s > 0)
        & (one.params.rho_s <= 1.0)
        & (a_one > 1.01 * math.exp(pm.LOG_ALPHA_MIN))
        & (a_one < math.exp(pm.LOG_ALPHA_MAX) / 1.01)
    )
    feats = np.stack([np.log(one.params.rho_s[good]), np.log(one.params.alpha_x[good])], -1)
    theta1, s1, chi2_1 = shared
    slots = max(MAX_CLUSTERS, n_clusters or 0)
    counts = [n_clusters] if n_clusters else list(range(1, MAX_CLUSTERS + 1))
    min_size = min_cluster_size(p)
    bic: dict[int, float] = {}
    held: dict[int, float] = {}
    best = None
    for k in counts:
        if k == 1:
            cand = (theta1, s1, jnp.zeros(p, jnp.int32))
            loglike = -0.5 * float(jnp.sum(chi2_1))
            padded = (jnp.concatenate([theta1, jnp.zeros((slots - 1, d))]), jnp.concatenate([s1, jnp.zeros(slots - 1)]))
            log_pi = jnp.asarray(np.where(np.arange(slots) < 1, 0.0, -np.inf))
        else:
            if feats.shape[0] < 5 * k:
                break
            centres, _ = kmeans2(feats, k, rng=np.random.default_rng(seed), minit="++")
            theta = np.full((slots, d), math.log(0.1))
            theta[:k] = centres[:, 1:2]
            s = np.zeros(slots)
            s[:k] = np.exp(centres[:, 0])
            theta, s = jnp.asarray(theta), jnp.asarray(s)
            log_pi = jnp.asarray(np.where(np.arange(slots) < k, -math.log(k), -np.inf))
            for _ in range(EM_ROUNDS):
                labels = jnp.argmin(pm.assign_costs(theta, s, geom, f, w, n_lobes=slots) - 2.0 * log_pi[None], 1)
                labels = labels.astype(jnp.int32)
                theta, s, _ = pm.lobe_fit(theta, labels, geom, f, w, n_lobes=slots, steps=STEPS)
                share = np.bincount(np.asarray(labels), minlength=slots) / p
                log_pi = jnp.asarray(np.where(share > 0, np.log(np.maximum(share, 1e-300)), -np.inf))
            costs = pm.assign_costs(theta, s, geom, f, w, n_lobes=slots)
            labels = jnp.argmin(costs - 2.0 * log_pi[None], 1).astype(jnp.int32)
            sizes = np.bincount(np.asarray(labels), minlength=slots)[:k]
            s_k, a_k = np.asarray(s[:k]), np.exp(np.asarray(theta[:k]))
            if np.any(sizes < min_size) or np.any(s_k > 1.0) or np.any(a_k <= 1.01 * math.exp(pm.LOG_ALPHA_MIN)):
                continue  # a cluster the data do not support, or a lobe no material has (ρs > 1, α at its bound)
            loglike = float(jnp.sum(jax.scipy.special.logsumexp(log_pi[None] - 0.5 * costs, axis=1)))
            cand = (theta[:k], s[:k], labels)
            padded = (theta, s)
        bic[k] = -2.0 * loglike + (k * (1 + d) + k - 1) * ln_n
        score, n_held = heldout_chi2(*padded, log_pi, geom, f, w)
        held[k] = float(score)
        if int(n_held) > 0 and any(held[k] >= v for j, v in held.items() if j < k):
            continue  # a count must predict held-out photos better than every smaller one (._pixel_heldout)
        if best is None or bic[k] < bic[best[0]]:
            best = (k, cand)
    if best is None:
        best = (1, (theta1, s1, jnp.zeros(p, jnp.int32)))
    k, (theta, s, labels) = best
    return theta, s, labels, {"bic": bic, "heldout_chi2": held, "n_clusters": k}
