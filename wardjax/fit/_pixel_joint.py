"""Lobes and normals refined together: Gauss–Newton on the lobes with every pixel's ``(ρd, slopes)`` eliminated.

Fitting the normals with the lobes fixed, then the lobes with the normals
fixed, creeps along the valley where a tilt and a lobe width trade off (a
slightly wider lobe is matched by normals pointing slightly away from the
photos), and stops short of the optimum. Here each step for a lobe
``φ = (ρs, θ)`` takes into account how its pixels' ``x_p = (a_p, g_p)``
would follow: with the weighted residuals ``r_p(x_p, φ)`` (:mod:`._pixel_normals`),
``J_p = ∂r_p/∂x_p`` and ``K_p = ∂r_p/∂φ``, the reduced (Schur complement)
system is

.. math::

    \\Big(\\sum_{p∈l} K_p^T (I − J_p (J_p^TJ_p)^{-1} J_p^T) K_p\\Big)\\,Δφ
    = −\\sum_{p∈l} K_p^T (I − J_p (J_p^TJ_p)^{-1} J_p^T)\\, r_p

(the same elimination as variable projection, Golub & Pereyra 1973, and as
bundle adjustment's reduced camera system). After the step every pixel's slopes
are refitted from where they were and the step is kept per lobe where it
lowers that lobe's χ². The reduced matrix is also the lobe's information with
the normals' uncertainty included.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp

from ._pixel_normals import _model

__all__ = ["reduced_system"]


def _pixel_system(f, w, wi, wo, a, g, phi, tangent, normalization):
    """One pixel's ``(m, m)`` reduced information and ``(m,)`` reduced gradient in ``φ`` (``m = 1 + d``)."""
    c = f.shape[-1]

    def res(x, ph):
        m, _, _ = _model(x[:c], x[c:], f, wi, wo, ph[1:], ph[0], tangent, normalization)
        return (jnp.sqrt(w) * (f - m)).reshape(-1)

    x = jnp.concatenate([a, g])
    r = res(x, phi)
    jx = jax.jacfwd(res, 0)(x, phi)
    kp = jax.jacfwd(res, 1)(x, phi)
    a_mat = jx.T @ jx
    eye = jnp.eye(a_mat.shape[0], dtype=a_mat.dtype)
    sol = jnp.linalg.solve(a_mat + 1e-12 * jnp.trace(a_mat) * eye, jnp.concatenate([jx.T @ kp, (jx.T @ r)[:, None]], 1))
    info = kp.T @ kp - (jx.T @ kp).T @ sol[:, :-1]
    grad = kp.T @ r - (jx.T @ kp).T @ sol[:, -1]
    ok = jnp.all(jnp.isfinite(info)) & jnp.all(jnp.isfinite(grad))
    return jnp.where(ok, info, 0.0), jnp.where(ok, grad, 0.0)


@functools.partial(jax.jit, static_argnames=("normalization", "n_lobes"))
def reduced_system(f, w, wi, wo, a, g, theta, s, labels, tangent, *, normalization: str, n_lobes: int):
    """Per lobe ``(L, m, m)`` reduced information and ``(L, m)`` gradient of ``½χ²`` in ``φ = (ρs, θ)``.

    ``a (P, C)`` and ``g (P, 2)`` each pixel's ``ρd/π`` and slopes; ``theta (L, d)``, ``s (L,)`` the lobes.
    """
    phi = jnp.concatenate([s[:, None], theta], 1)[labels]
    fn = functools.partial(_pixel_system, tangent=tangent, normalization=normalization)
    info, grad = jax.vmap(fn)(f, w, wi, wo, a, g, phi)
    return (
        jax.ops.segment_sum(info, labels, num_segments=n_lobes),
        jax.ops.segment_sum(grad, labels, num_segments=n_lobes),
    )
