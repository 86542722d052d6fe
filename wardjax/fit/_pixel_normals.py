"""A normal per pixel: two slopes fitted to the pixel's ``K`` views, its ρd profiled, its lobe given.

The normal is ``n = (−g_x, −g_y, 1)/‖·‖`` (the slopes ``g = ∇h`` of a height
field). For fixed ``g`` the pixel's model (:mod:`._pixel_model`)
``f ≈ q(g) a + s B(g)`` is linear in ``a = ρd/π``, so Levenberg–Marquardt runs
on the two slopes alone with ``a`` in closed form (variable projection), the
same fixed number of steps for every pixel (no data-dependent loop under
``vmap``), started from the best of a grid of slopes (and from given slopes:
a warm start); a step is kept only where it lowers the pixel's χ².

The grid must resolve the lobe. A normal tilted by ``δ`` moves the half-vector
by ``δ`` in the lobe's ``tan θh``, so χ² near the true slopes is a valley about
``α`` wide; between valleys lies a plateau, the normals that hide the highlight
from every photo, where the diffuse term alone fits. On a grid coarser than the
valley the plateau wins and LM, whose gradient vanishes there, cannot leave it.

Covariance: the Gauss–Newton inverse of ``JᵀJ`` over ``(a, g)`` of the pixel's
weighted residuals, with the lobe held fixed.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np

from ._pixel_model import basis, geometry

__all__ = ["MAX_SLOPE", "fit_normals", "normal_from_slopes", "normal_jacobian", "slope_systems"]

MAX_SLOPE = 1.0  # 45°: beyond this a bump is a facet the flat-sample geometry no longer describes
_STEPS = 16
_RESTARTS = 2  # LM runs from the best two grid points; the lowest χ² wins
# Starting slopes: a 31 × 31 grid over ±0.3 (±17°, 0.02 apart, a quarter of the narrowest lobe of the renders,
# α 0.08), the best of which start LM — a highlight seen in a few views makes the χ² of a tilt multimodal, and LM
# from the flat normal, or from a grid point outside the valley, stops on the plateau (module docstring).
_STARTS = tuple((a, b) for a in np.linspace(-0.3, 0.3, 31) for b in np.linspace(-0.3, 0.3, 31))


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


def _one_pixel(f, w, wi, wo, theta, s, tangent, g0, *, normalization, warm, grid):
    def res(g):
        return _profiled_residual(g, f, w, wi, wo, theta, s, tangent, normalization)[0]

    def cost(g):
        r = res(g)
        return jnp.sum(r * r)

    c_flat = cost(jnp.zeros(2, f.dtype))
    starts, c_best = g0[None], cost(g0)[None]
    if grid:
        pts = jnp.asarray(_STARTS, f.dtype)
        c_grid = jax.vmap(cost)(pts)
        best = jnp.argsort(c_grid)[:_RESTARTS]
        starts, c_best = pts[best], c_grid[best]
        if warm:  # the given slopes join the grid's best
            starts = jnp.concatenate([g0[None], starts], 0)
            c_best = jnp.concatenate([cost(g0)[None], c_best], 0)

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

    def run(start, c0):
        return jax.lax.fori_loop(0, _STEPS, step, (start, c0, jnp.asarray(1e-3, f.dtype)))[:2]

    gs, cs = jax.vmap(run)(starts, c_best)
    g, c = gs[jnp.argmin(cs)], jnp.min(cs)
    _, a = _profiled_residual(g, f, w, wi, wo, theta, s, tangent, normalization)

    def full(p):
        m, _, _ = _model(p[: f.shape[-1]], p[f.shape[-1] :], f, wi, wo, theta, s, tangent, normalization)
        return (jnp.sqrt(w) * (f - m)).reshape(-1)

    j = jax.jacfwd(full)(jnp.concatenate([a, g]))
    cov = jnp.linalg.pinv(j.T @ j)
    return g, a, c_flat, c, cov


@functools.partial(jax.jit, static_argnames=("normalization", "warm", "grid"))
def _chunk(f, w, wi, wo, theta, s, g0, tangent, *, normalization, warm, grid):
    fn = functools.partial(_one_pixel, normalization=normalization, warm=warm, grid=grid)
    return jax.vmap(fn, in_axes=(0, 0, 0, 0, 0, 0, None, 0))(f, w, wi, wo, theta, s, tangent, g0)


def fit_normals(
    f, w, wi, wo, theta_p, s_p, tangent, normalization: str, g0=None, *, grid: bool = True, chunk: int = 32768
):
    """Fit every pixel's slopes; arrays ``(P, …)``, processed in chunks of one compiled shape.

    ``g0 (P, 2)``: slopes to start from as well as the grid's best (a warm start); with ``grid=False``
    from them alone.

    Returns ``g (P, 2)``, ``a (P, C)``, ``χ²`` flat and fitted ``(P,)`` each, and the
    covariance ``(P, C+2, C+2)`` of ``(a, g)``.
    """
    n = f.shape[0]
    chunk = min(chunk, n)
    start_g = jnp.zeros((n, 2), f.dtype) if g0 is None else jnp.asarray(g0, f.dtype)
    outs = []
    for start in range(0, n, chunk):
        sl = slice(start, min(start + chunk, n))
        parts = [x[sl] for x in (f, w, wi, wo, theta_p, s_p, start_g)]
        pad = chunk - parts[0].shape[0]
        if pad:
            parts = [jnp.concatenate([x, jnp.repeat(x[-1:], pad, 0)], 0) for x in parts]
        out = _chunk(*parts, tangent, normalization=normalization, warm=g0 is not None, grid=grid or g0 is None)
        outs.append([o[: chunk - pad] for o in out])
    return tuple(jnp.concatenate([o[i] for o in outs], 0) for i in range(5))


@functools.partial(jax.jit, static_argnames=("normalization",))
def slope_systems(g, f, w, wi, wo, theta_p, s_p, tangent, *, normalization: str):
    """Every pixel's χ² at its slopes ``g (P, 2)`` (ρd profiled, the lobe given) and its Gauss–Newton model there:
    ``JᵀJ (P, 2, 2)``, ``Jᵀr (P, 2)`` and ``rᵀr (P,)``, ``J = ∂r/∂g`` of the profiled residuals (variable
    projection), so that ``χ²(g + δ) ≈ rᵀr + 2 δᵀJᵀr + δᵀJᵀJ δ``."""

    def one(g, f, w, wi, wo, theta, s):
        def res(g):
            return _profiled_residual(g, f, w, wi, wo, theta, s, tangent, normalization)[0]

        r, j = res(g), jax.jacfwd(res)(g)
        return j.T @ j, j.T @ r, r @ r

    return jax.vmap(one)(g, f, w, wi, wo, theta_p, s_p)
