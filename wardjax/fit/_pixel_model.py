"""The per-pixel Ward model of a few photographs, and its lobes fitted by variable projection.

Pixel ``p`` holds ``K`` observations ``f[p, k, c]`` (sr⁻¹, channels ``c``)
with weights ``w[p, k, c] = 1/σ²``, directions ``ωi``, ``ωo`` in the sample
frame (z the mean normal). With a per-pixel normal ``n_p`` (z when flat) the
photographs' BRDF estimates, made with the mean normal's ``cos θi``, follow

.. math::

    f[p,k,c] ≈ q[p,k]\\,a[p,c] + s_{l(p)}\\,B[p,k](θ_{l(p)}),\\qquad
    a = ρ_d/π,\\quad q = \\frac{n_p·ω_i}{z·ω_i},\\quad
    B = q\\,N\\,\\frac{\\exp(-h_x'^2/(h_z'^2 α_x^2) - h_y'^2/(h_z'^2 α_y^2))}{α_x α_y}

(Ward 1992, the image-based paper's eq. "f_r,Ward", in the frame of ``n_p``
whose ``x'`` is the tangent projected on its plane), with ``l(p)`` the lobe
that pixel ``p`` carries and ``θ = (log αx, log αy)`` (isotropic: one
``log α``). Given the lobes the model is linear in ``a`` (per pixel) and
``s = ρs`` (per lobe): variable projection (Golub & Pereyra 1973). With
``x̃ = x − q ⟨q, x⟩/⟨q, q⟩`` (the weighted projection per pixel and channel;
``⟨x, y⟩ = Σ_k w x y``),

* ``a[p, c] = ⟨q, f − s B⟩ / ⟨q, q⟩``,
* ``s_l = max(Σ_{p∈l} ⟨B̃, f̃⟩, 0) / Σ_{p∈l} ⟨B̃, B̃⟩``,
* ``χ²_l(θ_l) = Σ_{p∈l} ⟨f̃, f̃⟩ − s_l (2 Σ⟨B̃, f̃⟩ − s_l Σ⟨B̃, B̃⟩)``,

so each lobe is a 1- or 2-parameter problem whatever the number of pixels
(lobes separate: every pixel belongs to one). It is solved by a grid in
``log α`` and Levenberg–Marquardt steps in Kaufman's Gauss–Newton form
(:func:`lobe_fit`); one pass over the pixels per step builds every lobe's
Gram matrix of ``(f̃, B̃, ∂B̃/∂θ)``.

Covariance (Gauss–Newton, linearised at the optimum): a lobe's parameters
``φ = (s, θ)`` have ``Σ_φ = (Σ_{p∈l} Σ_c ⟨D̃, D̃ᵀ⟩)⁻¹`` with ``D = ∂(sB)/∂φ``
(the Schur complement of the per-pixel block), and ``a[p, c]`` has variance
``1/⟨q, q⟩ + gᵀ Σ_φ g`` with ``g = −⟨q, D⟩/⟨q, q⟩`` (how ``a`` follows the lobe).
"""

from __future__ import annotations

import functools
import math
from typing import NamedTuple

import jax
import jax.numpy as jnp

from ..ward import ward_geometry

__all__ = [
    "LOG_ALPHA_MAX",
    "LOG_ALPHA_MIN",
    "PixelGeometry",
    "assign_costs",
    "basis",
    "flat_geometry",
    "geometry",
    "lobe_covariance",
    "lobe_fit",
    "lobe_grid",
    "lobe_gram",
    "lobe_profile",
    "local_frame",
    "pixel_chi2",
]

# α searched within [1e-3, 2]: below, no photograph resolves a lobe; above, it is flat.
LOG_ALPHA_MIN = math.log(1e-3)
LOG_ALPHA_MAX = math.log(2.0)
# The starting grid in log α (α 0.005 … 1, 15 points, ×1.46 apart).
_GRID = tuple(math.log(0.005) + i * (math.log(1.0) - math.log(0.005)) / 14 for i in range(15))
_COS_EPS = 1e-12


class PixelGeometry(NamedTuple):
    """What the lobes need of ``K`` views of each pixel in the frame of its normal: ``(P, K)`` each.

    ``u = h_x'²/h_z'²``, ``v = h_y'²/h_z'²``, ``g`` the normalisation ``N`` (0 where
    a direction is under the pixel's horizon), ``q = (n·ωi)/(z·ωi)`` the shading ratio.
    """

    u: jax.Array
    v: jax.Array
    g: jax.Array
    q: jax.Array


def local_frame(normals: jax.Array, tangent: jax.Array) -> tuple[jax.Array, jax.Array]:
    """``(…, 3)`` unit normals, a ``(3,)`` tangent → the local ``x'`` and ``y' = n × x'`` axes."""
    t = jnp.broadcast_to(tangent, normals.shape)
    x = t - jnp.sum(t * normals, -1, keepdims=True) * normals
    x = x / jnp.linalg.norm(x, axis=-1, keepdims=True)
    return x, jnp.cross(normals, x)


def geometry(wi: jax.Array, wo: jax.Array, normals: jax.Array, tangent: jax.Array, normalization: str):
    """:class:`PixelGeometry` of ``(…, K, 3)`` directions seen from ``(…, 3)`` normals."""
    x, y = local_frame(normals, tangent)
    n, x, y = normals[..., None, :], x[..., None, :], y[..., None, :]

    def to_local(d):
        return jnp.stack([jnp.sum(d * x, -1), jnp.sum(d * y, -1), jnp.sum(d * n, -1)], -1)

    li, lo = to_local(wi), to_local(wo)
    geom = ward_geometry(li, lo, normalization)
    zi = wi[..., 2]
    q = jnp.where(geom.valid & (zi > _COS_EPS), li[..., 2] / jnp.where(zi > _COS_EPS, zi, 1.0), 0.0)
    return PixelGeometry(geom.u, geom.v, geom.g, q)


def flat_geometry(wi: jax.Array, wo: jax.Array, tangent: jax.Array, normalization: str) -> PixelGeometry:
    """:func:`geometry` at the flat normal ``z`` for every pixel, in one rotation of the directions.

    The local frame is then the same for all pixels, ``(t, z × t, z)``: the directions are rotated by
    one ``3 × 3`` matrix instead of projected on per-pixel axes, and ``q`` is 1 wherever the view is
    valid. The same values as :func:`geometry` with ``normals = z``.
    """
    z = jnp.asarray([0.0, 0.0, 1.0], tangent.dtype)
    rot = jnp.stack([tangent, jnp.cross(z, tangent), z])  # rows x', y', z
    geom = ward_geometry(wi @ rot.T, wo @ rot.T, normalization)
    return PixelGeometry(geom.u, geom.v, geom.g, jnp.where(geom.valid & (wi[..., 2] > _COS_EPS), 1.0, 0.0))


def _theta2(theta: jax.Array) -> jax.Array:
    """``(…, d)`` → ``(…, 2)``: ``(log αx, log αy)``, the isotropic ``log α`` repeated."""
    return jnp.concatenate([theta, theta], -1) if theta.shape[-1] == 1 else theta


def basis(geom: PixelGeometry, theta: jax.Array) -> jax.Array:
    """``B (P, K)``, the lobe per unit ρs times ``q``, with ``theta (P, d)`` per pixel."""
    t = _theta2(theta)
    ex, ey = jnp.exp(-2.0 * t[:, 0])[:, None], jnp.exp(-2.0 * t[:, 1])[:, None]
    scale = jnp.exp(-(t[:, 0] + t[:, 1]))[:, None]
    return geom.q * geom.g * scale * jnp.exp(-(geom.u * ex + geom.v * ey))


def _derivatives(geom: PixelGeometry, theta: jax.Array, b: jax.Array) -> list[jax.Array]:
    """``∂B/∂θ_j (P, K)``: ``B (2u/αx² − 1)``, ``B (2v/αy² − 1)``; isotropic ``B (2(u+v)/α² − 2)``."""
    t = _theta2(theta)
    ex, ey = jnp.exp(-2.0 * t[:, 0])[:, None], jnp.exp(-2.0 * t[:, 1])[:, None]
    if theta.shape[-1] == 1:
        return [b * (2.0 * (geom.u * ex + geom.v * ey) - 2.0)]
    return [b * (2.0 * geom.u * ex - 1.0), b * (2.0 * geom.v * ey - 1.0)]


class _Stats(NamedTuple):
    """What the Gram matrices need of the data, whatever the lobe: per pixel ``(P, K)`` or ``(P, C)``.

    ``qw = w q (P, K, C)``; ``wsum = Σ_c w``, ``fsum = Σ_c w f`` ``(P, K)``; ``inv = 1/⟨q, q⟩`` and
    ``fq = ⟨q, f⟩`` ``(P, C)``; ``ff = Σ_c ⟨f̃, f̃⟩ (P,)``.
    """

    qw: jax.Array
    wsum: jax.Array
    fsum: jax.Array
    inv: jax.Array
    fq: jax.Array
    ff: jax.Array


def _stats(q: jax.Array, f: jax.Array, w: jax.Array) -> _Stats:
    qw = w * q[..., None]
    sq = jnp.sum(qw * q[..., None], 1)
    inv = jnp.where(sq > 0, 1.0 / jnp.where(sq > 0, sq, 1.0), 0.0)
    fq = jnp.sum(qw * f, 1)
    ff = jnp.sum(jnp.sum(w * f * f, 1) - fq * fq * inv, -1)
    return _Stats(qw, jnp.sum(w, -1), jnp.sum(w * f, -1), inv, fq, ff)


def _gram(cols: list[jax.Array], st: _Stats) -> jax.Array:
    """``(P, m+1, m+1)``: ``Σ_c ⟨x̃_i, x̃_j⟩`` of ``(f, cols…)``, projected per pixel and channel.

    The columns ``(P, K)`` are the same in every channel, so their products need the channel sums
    ``Σ_c w`` and ``Σ_c w f`` only; the projection needs ``⟨q, x⟩`` per channel.
    """
    xq = [jnp.sum(st.qw * x[..., None], 1) for x in cols]
    m = len(cols) + 1
    entries: dict[tuple[int, int], jax.Array] = {(0, 0): st.ff}
    for i, x in enumerate(cols, 1):
        entries[0, i] = entries[i, 0] = jnp.sum(st.fsum * x, 1) - jnp.sum(st.fq * xq[i - 1] * st.inv, -1)
        for j in range(i, m):
            y = cols[j - 1]
            entries[i, j] = entries[j, i] = jnp.sum(st.wsum * x * y, 1) - jnp.sum(xq[i - 1] * xq[j - 1] * st.inv, -1)
    return jnp.stack([jnp.stack([entries[i, j] for j in range(m)], -1) for i in range(m)], -2)


def _lobe_gram(theta, labels, geom, st, n_lobes, derivatives=True):
    """Per lobe ``(L, m, m)`` Gram matrix of ``(f, B, ∂B/∂θ…)``, summed over its pixels."""
    theta_p = theta[labels]
    b = basis(geom, theta_p)
    cols = [b] + (_derivatives(geom, theta_p, b) if derivatives else [])
    return jax.ops.segment_sum(_gram(cols, st), labels, num_segments=n_lobes)


def _profile(gram):
    """``(χ², s)`` per lobe from its Gram matrix: ``s = max(⟨B̃,f̃⟩, 0)/⟨B̃,B̃⟩``, ``χ² = ⟨f̃,f̃⟩ − s(2⟨B̃,f̃⟩ − s⟨B̃,B̃⟩)``."""
    bf, bb = gram[:, 1, 0], gram[:, 1, 1]
    s = jnp.maximum(bf, 0.0) / jnp.where(bb > 0, bb, 1.0)
    return gram[:, 0, 0] - s * (2.0 * bf - s * bb), s


def lobe_gram(theta, labels, geom, f, w, *, n_lobes: int):
    """Per lobe ``(L, 2+d, 2+d)`` Gram matrix of ``(f̃, B̃, ∂B̃/∂θ…)`` at ``theta (L, d)``, summed over its pixels."""
    return _lobe_gram(theta, labels, geom, _stats(geom.q, f, w), n_lobes)


def lobe_profile(theta, labels, geom, f, w, n_lobes: int):
    """Per lobe ``(χ²_l, s_l)``, each ``(L,)``, at ``theta (L, d)`` (ρd and ρs profiled out)."""
    return _profile(_lobe_gram(theta, labels, geom, _stats(geom.q, f, w), n_lobes, derivatives=False))


def pixel_chi2(theta, s, labels, geom, f, w):
    """``(P,)`` each pixel's χ² under its lobe ``(θ, s)[labels]``, its ρd profiled."""
    gram = _gram([basis(geom, theta[labels])], _stats(geom.q, f, w))
    s_p = s[labels]
    return gram[:, 0, 0] - s_p * (2.0 * gram[:, 1, 0] - s_p * gram[:, 1, 1])


@functools.partial(jax.jit, static_argnames=("n_lobes",))
def lobe_grid(labels, geom, f, w, *, n_lobes: int):
    """``(L,)`` a starting ``log α`` per lobe: the best of :data:`_GRID` and the vertex of its parabola."""
    ts = jnp.asarray(_GRID, f.dtype)
    ones = jnp.ones((n_lobes, 1), f.dtype)
    st = _stats(geom.q, f, w)
    c = jax.lax.map(lambda t: _profile(_lobe_gram(t * ones, labels, geom, st, n_lobes, derivatives=False))[0], ts)
    i = jnp.clip(jnp.argmin(c, 0), 1, len(_GRID) - 2)
    c0, c1, c2 = (jnp.take_along_axis(c, (i + o)[None], 0)[0] for o in (-1, 0, 1))
    h = ts[1] - ts[0]
    den = c0 - 2.0 * c1 + c2
    off = jnp.where(den > 0, 0.5 * h * (c0 - c2) / jnp.where(den > 0, den, 1.0), 0.0)
    return ts[i] + jnp.clip(off, -h, h)


@functools.partial(jax.jit, static_argnames=("n_lobes", "steps"))
def lobe_fit(theta0, labels, geom, f, w, *, n_lobes: int, steps: int = 8):
    """Fit the lobes' ``theta (L, d)`` from ``theta0`` by Levenberg–Marquardt on the profiled χ².

    Kaufman's Gauss–Newton form of variable projection: with the lobe's
    Gram matrix ``G`` of ``(f̃, B̃, B̃'…)``, the gradient is
    ``−2s(G[B',f] − s G[B',B])`` and the curvature
    ``2s²(G[B',B'] − G[B',B] G[B,B']/G[B,B])``. Every lobe takes the same
    number of steps; a step is kept per lobe only where it lowers χ².
    Returns ``theta (L, d)``, ``s (L,)``, ``chi2 (L,)``.
    """
    d = theta0.shape[-1]
    eye = jnp.eye(d, dtype=theta0.dtype)

    st = _stats(geom.q, f, w)

    def gram_of(theta):
        return _lobe_gram(theta, labels, geom, st, n_lobes)

    def step(_, state):
        theta, gram, lam = state
        chi2, s = _profile(gram)
        bb = jnp.where(gram[:, 1, 1] > 0, gram[:, 1, 1], 1.0)
        gpf, gpb = gram[:, 2:, 0], gram[:, 2:, 1]
        grad = -2.0 * s[:, None] * (gpf - s[:, None] * gpb)
        hess = 2.0 * (s * s)[:, None, None] * (gram[:, 2:, 2:] - gpb[:, :, None] * gpb[:, None, :] / bb[:, None, None])
        damped = hess + lam[:, None, None] * (hess * eye[None]) + 1e-300 * eye[None]
        delta = jnp.linalg.solve(damped, grad[..., None])[..., 0]
        delta = jnp.clip(jnp.nan_to_num(delta), -1.0, 1.0)
        trial = jnp.clip(theta - delta, LOG_ALPHA_MIN, LOG_ALPHA_MAX)
        g_new = gram_of(trial)
        ok = _profile(g_new)[0] < chi2
        theta = jnp.where(ok[:, None], trial, theta)
        gram = jnp.where(ok[:, None, None], g_new, gram)
        return theta, gram, jnp.where(ok, 0.1 * lam, 10.0 * lam)

    state = (theta0, gram_of(theta0), jnp.full(n_lobes, 1e-3, theta0.dtype))
    theta, gram, _ = jax.lax.fori_loop(0, steps, step, state)
    chi2, s = _profile(gram)
    return theta, s, chi2


@functools.partial(jax.jit, static_argnames=("n_lobes",))
def lobe_covariance(theta, s, labels, geom, f, w, *, n_lobes: int):
    """Gauss–Newton covariances: lobes ``(L, 1+d, 1+d)`` in ``(s, θ)`` and ``var a`` per pixel ``(P, C)``.

    Not scaled by χ²/dof (the caller does so for unweighted data).
    """
    theta_p, s_p = theta[labels], s[labels]
    b = basis(geom, theta_p)
    cols = [b] + [s_p[:, None] * x for x in _derivatives(geom, theta_p, b)]  # D (P, K) each
    q = geom.q
    sq = jnp.sum(w * (q * q)[..., None], 1)  # (P, C)
    inv = jnp.where(sq > 0, 1.0 / jnp.where(sq > 0, sq, 1.0), 0.0)
    qw = w * q[..., None]
    dq = jnp.stack([jnp.sum(qw * x[..., None], 1) for x in cols], -1)  # (P, C, m) ⟨q, D⟩
    wsum = jnp.sum(w, -1)  # D is the same in every channel: Σ_c ⟨D_i, D_j⟩ needs Σ_c w only
    dd = jnp.stack([jnp.stack([jnp.sum(wsum * x * y, 1) for y in cols], -1) for x in cols], -2)  # (P, m, m)
    proj = dd - jnp.sum(dq[..., :, None] * dq[..., None, :] * inv[..., None, None], 1)  # (P, m, m)
    info = jax.ops.segment_sum(proj, labels, num_segments=n_lobes)  # (L, m, m)
    cov = jnp.linalg.inv(info)  # an empty lobe gives NaN, reported as such
    g = -dq * inv[..., None]  # (P, C, m)
    var_a = inv + jnp.einsum("pci,pij,pcj->pc", g, cov[labels], g)
    var_a = jnp.where(sq > 0, var_a, jnp.nan)
    return cov, var_a


@functools.partial(jax.jit, static_argnames=("n_lobes",))
def assign_costs(theta, s, geom, f, w, *, n_lobes: int):
    """``(P, L)``: each pixel's χ² under each lobe ``(θ_l, s_l)``, its ρd profiled."""

    st = _stats(geom.q, f, w)

    def one(ts):
        t, s_l = ts
        tp = jnp.broadcast_to(t, (f.shape[0], t.shape[-1]))
        gram = _gram([basis(geom, tp)], st)
        return gram[:, 0, 0] - s_l * (2.0 * gram[:, 1, 0] - s_l * gram[:, 1, 1])

    return jax.lax.map(one, (theta, s)).T
