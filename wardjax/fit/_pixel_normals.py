"""A normal per pixel: two slopes fitted to the pixel's ``K`` views, its ρd profiled, its lobe given.

The normal is ``n = (−g_x, −g_y, 1)/‖·‖`` (the slopes ``g = ∇h`` of a height
field). For fixed ``g`` the pixel's model (:mod:`._pixel_model`)
``f ≈ q(g) a + s B(g)`` is linear in ``a = ρd/π``, so Levenberg–Marquardt runs
on the two slopes alone with ``a`` in closed form (variable projection), the
same fixed number of steps for every pixel (no data-dependent loop under
``vmap``), started from the best of a grid of slopes; a step is kept only
where it lowers the pixel's χ².

Covariance: the Gauss–Newton inverse of ``JᵀJ`` over ``(a, g)`` of the pixel's
weighted residuals, with the lobe held fixed.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np

from ._pixel_model import basis, geometry

__all__ = ["MAX_SLOPE", "fit_normals", "normal_from_slopes", "normal_jacobian"]

MAX_SLOPE = 1.0  # 45°: beyond this a bump is a facet the flat-sample geometry no longer describes
_STEPS = 24
_RESTARTS = 4  # LM runs from the best four grid points; the lowest χ² wins
# Starting slopes: a 13 × 13 grid over ±0.3 (±17°, 0.05 apart), the best of which starts LM — a highlight seen in
# a few views makes the χ² of a tilt multimodal, and LM from the flat normal can stop in the wrong mode.
_STARTS = tuple((a, b) for a in np.linspace(-0.3, 0.3, 13) for b in np.linspace(-0.3, 0.3, 13))


def normal_from_slopes(g: jax.Array) -> jax.Array:
    """``(…, 2)`` slopes → ``(…, 3)`` unit normals ``(−gx, −gy, 1)/‖·‖``."""
    n = jnp.concatenate([-g, jnp.ones_like(g[..., :1])], -1)
    return n / jnp.linalg.norm(n, axis=-1, keepdims=True)


def normal_jacobian(g: jax.Array) -> jax.Array:
    """``(…, 3, 2)``: ∂n/∂g, for propagating the slopes' covariance to the normal."""
    flat = g.reshape(-1, 2)
    return jax.vmap(jax.jacfwd(normal_from_slopes))(flat).reshape(g.shape[:-1] + (3, 2))


def _model(a, g, f, wi, wo, theta, s, tangent, normalization):
    geom = geometry(wi[None], wo[None], normal_from_slopes(g)[None], tangent, normalization)
    b = basis(geom, theta[None])[0]
    return geom.q[0][:, None] * a[None, :] + s * b[:, None], geom.q[0], b


def _profiled_residual(g, f, w, wi, wo, theta, s, tangent, normalization):
    _, q, b = _model(jnp.zeros(f.shape[-1], f.dtype), g, f, wi, wo, theta, s, tangent, normalization)
    qw = w * q[:, None]
    sq = jnp.sum(qw * q[:, None], 0)
    a = jnp.sum(qw * (f - s * b[:, None]), 0) / jnp.where(sq > 0, sq, 1.0)
    r = jnp.sqrt(w) * (f - q[:, None] * a[None, :] - s * b[:, None])
    return r.reshape(-1), a


def _one_pixel(f, w, wi, wo, theta, s, tangent, *, normalization):
    def res(g):
        return _profiled_residual(g, f, w, wi, wo, theta, s, tangent, normalization)[0]

    def cost(g):
        r = res(g)
        return jnp.sum(r * r)

    c_flat = cost(jnp.zeros(2, f.dtype))
    starts = jnp.asarray(_STARTS, f.dtype)
    c_starts = jax.vmap(cost)(starts)
    best = jnp.argsort(c_starts)[:_RESTARTS]

    def step(_, state):
        g, c, lam = state
        r = res(g)
        j = jax.jacfwd(res)(g)
        a = j.T @ j
        rhs = j.T @ r
        damped = a + lam * jnp.diag(jnp.diag(a)) + 1e-12 * jnp.eye(2, dtype=a.dtype)
        trial = jnp.clip(g - jnp.linalg.solve(damped, rhs), -MAX_SLOPE, MAX_SLOPE)
        c_new = cost(trial)
        ok = jnp.isfinite(c_new) & (c_new < c)
        return jnp.where(ok, trial, g), jnp.where(ok, c_new, c), jnp.where(ok, 0.3 * lam, 10.0 * lam)

    def run(g0, c0):
        return jax.lax.fori_loop(0, _STEPS, step, (g0, c0, jnp.asarray(1e-3, f.dtype)))[:2]

    gs, cs = jax.vmap(run)(starts[best], c_starts[best])
    g, c = gs[jnp.argmin(cs)], jnp.min(cs)
    _, a = _profiled_residual(g, f, w, wi, wo, theta, s, tangent, normalization)

    def full(p):
        m, _, _ = _model(p[: f.shape[-1]], p[f.shape[-1] :], f, wi, wo, theta, s, tangent, normalization)
        return (jnp.sqrt(w) * (f - m)).reshape(-1)

    j = jax.jacfwd(full)(jnp.concatenate([a, g]))
    cov = jnp.linalg.pinv(j.T @ j)
    return g, a, c_flat, c, cov


@functools.partial(jax.jit, static_argnames=("normalization",))
def _chunk(f, w, wi, wo, theta, s, tangent, *, normalization):
    fn = functools.partial(_one_pixel, normalization=normalization)
    return jax.vmap(fn, in_axes=(0, 0, 0, 0, 0, 0, None))(f, w, wi, wo, theta, s, tangent)


def fit_normals(f, w, wi, wo, theta_p, s_p, tangent, normalization: str, chunk: int = 32768):
    """Fit every pixel's slopes; arrays ``(P, …)``, processed in chunks of one compiled shape.

    Returns ``g (P, 2)``, ``a (P, C)``, ``χ²`` flat and fitted ``(P,)`` each, and the
    covariance ``(P, C+2, C+2)`` of ``(a, g)``.
    """
    n = f.shape[0]
    chunk = min(chunk, n)
    outs = []
    for start in range(0, n, chunk):
        sl = slice(start, min(start + chunk, n))
        parts = [x[sl] for x in (f, w, wi, wo, theta_p, s_p)]
        pad = chunk - parts[0].shape[0]
        if pad:
            parts = [jnp.concatenate([x, jnp.repeat(x[-1:], pad, 0)], 0) for x in parts]
        out = _chunk(*parts, tangent, normalization=normalization)
        outs.append([o[: chunk - pad] for o in out])
    return tuple(jnp.concatenate([o[i] for o in outs], 0) for i in range(5))
