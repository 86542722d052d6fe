"""ρd's generalised least squares under the texture's whitening: the scanline model's closed-form profile.

With the probe's texture carried (:mod:`wardjax.effects._texture`) the residuals
are whitened along each scanline by a dense lower-triangular ``W = L⁻¹``
``(S, C N, C N)`` (the channels of a scanline together) or ``(S, C, N, N)``
(per channel). ρd per scanline and channel enters the model linearly, so it
is profiled in closed form: ``ρd/π = (AᵀA)⁻¹ Aᵀ b`` with ``A = W D`` the
whitened design (``D``: ``1/σ`` on each channel alone) and ``b`` the whitened
data. On a textured capture ``W`` (tens of MB) is what an evaluation spends
its time on, so each product reads it once for all its columns, and the
profile's derivative is written by hand (:func:`_gls_rho_joint`).
"""

from __future__ import annotations

from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

_TINY = 1e-30


def _whiten(W, z):
    """``L⁻¹ z`` along each scanline: ``z`` ``(S, N, C)``; ``W`` ``(S, C, N, N)`` per channel or ``(S, C N, C N)``
    with the channels of a scanline together (values ordered channel by channel)."""
    if W.ndim == 3:
        s_n, n, c_n = z.shape
        zj = jnp.swapaxes(z, 1, 2).reshape(s_n, c_n * n)
        return jnp.swapaxes(jnp.einsum("sij,sj->si", W, zj).reshape(s_n, c_n, n), 1, 2)
    return jnp.einsum("scij,sjc->sic", W, z)


def _whiten_columns(W, cols):
    """``L⁻¹`` of each of ``K`` vectors at once: ``cols`` ``(S, N, C, K)``, ``W`` ``(S, C N, C N)`` (channels together).

    One matrix product reads ``W`` once for all ``K`` columns; ``K`` products of
    a vector each would read it ``K`` times, and on a textured capture ``W``
    (tens of MB) is what an evaluation of the residuals spends its time on.
    """
    s_n, n, c_n, k = cols.shape
    flat = jnp.swapaxes(cols, 1, 2).reshape(s_n, c_n * n, k)  # values ordered channel by channel, as W's
    return jnp.swapaxes(jnp.einsum("sij,sjk->sik", W, flat).reshape(s_n, c_n, n, k), 1, 2)


def _back_whiten_columns(W, cols):
    """``Wᵀ`` of each of ``K`` vectors at once (whitened residuals back in units of ``1/σ``): ``cols``
    ``(S, N, C, K)``; ``W`` ``(S, C N, C N)`` (channels together, one product for all ``K``) or ``(S, C, N, N)``.
    NumPy arrays in, NumPy out (batched matrix products on the host, no program compiled); otherwise JAX's."""
    xp: Any = np if isinstance(W, np.ndarray) and isinstance(cols, np.ndarray) else jnp
    s_n, n, c_n, k = cols.shape
    if W.ndim == 4:  # per channel: (S, C, N, N)ᵀ @ (S, C, N, K)
        return xp.moveaxis(xp.matmul(xp.swapaxes(W, -1, -2), xp.moveaxis(cols, 2, 1)), 1, 2)
    flat = xp.swapaxes(cols, 1, 2).reshape(s_n, c_n * n, k)  # values ordered channel by channel, as W's
    return xp.swapaxes(xp.matmul(xp.swapaxes(W, -1, -2), flat).reshape(s_n, c_n, n, k), 1, 2)


def _gls_design(W, inv_sp):
    """ρd's whitened design ``(S, N, C, C_cols)``: column ``c`` is ``L⁻¹`` of ``inv_sp`` on channel ``c`` alone."""
    c_n = inv_sp.shape[-1]
    if W.ndim == 3:
        return _whiten_columns(W, inv_sp[..., None] * jnp.eye(c_n, dtype=inv_sp.dtype)[None, None])
    return jnp.stack([_whiten(W, inv_sp)[..., c][..., None] * jnp.eye(c_n)[c] for c in range(c_n)], -2)


def _gls_solve(A, b):
    """``π`` times the least-squares ``ρd/π`` ``(S, 1, C)`` of whitened data ``b`` ``(S, N, C)`` on design ``A``."""
    c_n = A.shape[-1]
    AtA = jnp.einsum("snck,sncl->skl", A, A) + _TINY * jnp.eye(c_n)[None]
    Atb = jnp.einsum("snck,snc->sk", A, b)
    return jnp.pi * jnp.linalg.solve(AtA, Atb[..., None])[..., 0][:, None, :]


def _gls_rho(W, inv_sp, resid):
    """ρd per scanline and channel ``(S, 1, C)`` by generalised least squares under the whitening ``W``.

    ``ρd_c/π`` is a constant added to channel ``c`` of each scanline: its
    whitened design column is ``L⁻¹`` of ``1/σ`` on that channel. Whitened
    per channel the normal equations are one division per channel; with the
    channels together (``W`` ``(S, C N, C N)``) they are a ``C × C`` solve per
    scanline, the ``C`` design columns and the data whitened in one product.
    """
    if W.ndim == 3:
        return _gls_rho_joint(W, inv_sp, resid)
    a = _whiten(W, inv_sp)
    b = _whiten(W, resid)
    return jnp.pi * jnp.sum(a * b, axis=1, keepdims=True) / jnp.maximum(jnp.sum(a * a, axis=1, keepdims=True), _TINY)


def _gls_whitened(W, inv_sp, resid):
    """The whitened design ``A`` ``(S, N, C, C)`` and data ``b`` ``(S, N, C)`` of :func:`_gls_rho`, in one product."""
    c_n = inv_sp.shape[-1]
    out = _whiten_columns(
        W, jnp.concatenate([inv_sp[..., None] * jnp.eye(c_n, dtype=inv_sp.dtype)[None, None], resid[..., None]], -1)
    )
    return out[..., :c_n], out[..., c_n]


@jax.custom_jvp
def _gls_rho_joint(W, inv_sp, resid):
    """:func:`_gls_rho` with the channels whitened together (``W`` ``(S, C N, C N)``), differentiated by hand.

    ``x = H⁻¹ Aᵀ b`` (``H = AᵀA``, ``A = W D``, ``b = W r``, ``D`` the design of
    ``inv_sp``, ``r`` = ``resid``) has the derivative

        dx = H⁻¹ (dDᵀ Wᵀ e + (Wᵀ A)ᵀ (dr − dD x)),      e = b − A x,

    so the ``Wᵀ`` of ``A`` and ``e`` (one product, with the primal) carry every
    tangent: differentiated through the whitening instead, each of a
    Jacobian's columns multiplied ``W`` again on ``C + 1`` vectors. ``W`` is
    data: its tangent is not propagated.
    """
    return _gls_solve(*_gls_whitened(W, inv_sp, resid))


@_gls_rho_joint.defjvp
def _gls_rho_joint_jvp(primals, tangents):
    W, inv_sp, resid = primals
    _, d_inv, d_res = tangents
    c_n = inv_sp.shape[-1]
    A, b = _gls_whitened(W, inv_sp, resid)
    rho = _gls_solve(A, b)
    x = rho[:, 0, :] / jnp.pi  # (S, C)
    e = b - jnp.einsum("snck,sk->snc", A, x)
    back = _back_whiten_columns(W, jnp.concatenate([A, e[..., None]], -1))  # Wᵀ [A, e]
    H = jnp.einsum("snck,sncl->skl", A, A) + _TINY * jnp.eye(c_n)[None]
    q = jnp.sum(d_inv * back[..., c_n], axis=1)  # dDᵀ Wᵀ e, (S, C)
    p = jnp.einsum("snck,snc->sk", back[..., :c_n], d_res - d_inv * x[:, None, :])
    dx = jnp.linalg.solve(H, (q + p)[..., None])[..., 0]
    return rho, jnp.pi * dx[:, None, :]
