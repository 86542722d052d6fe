"""Heteroscedasticity-consistent (sandwich) covariance of a scanline fit, in one pass over its samples."""

from __future__ import annotations

from typing import Any

import jax
import jax.numpy as jnp

# The sandwich's leverage correction divides by 1 − h; a value with h → 1 has a residual → 0.
LEVERAGE_FLOOR = 1e-6
# Up to this many samples (a static shape) the sandwich is HC3; above it HC0: the mean leverage
# P / (3N) is then under 3 %, and the per-value leverage made this pass six times dearer at N = 256.
LEVERAGE_SAMPLES = 64


def sandwich_pass(theta, rho_s, cov, scale, f, x, g, w, mean):
    """Heteroscedasticity-consistent (sandwich, HC3) covariance of ``(ρd RGB, ρs, α…)``.

    ``Σ_HC = B⁻¹ (Σ_i w_i² r_i² / (1 − h_i)² · J_iᵀ J_i) B⁻¹`` (White 1980; the leverage
    correction HC3 of MacKinnon & White 1985) with ``B⁻¹ = cov / (χ²/dof)`` the unscaled
    Gauss–Newton covariance, ``r_i`` the residual, ``J_i`` the gradient of the model at
    observation ``i`` (``∂/∂ρd_c = δ/π``, ``∂/∂ρs = b``, ``∂/∂α_k = ρs b ∂log b/∂log α_k / α_k``)
    and ``h_i = w_i J_i B⁻¹ J_iᵀ`` its leverage. It needs no noise model: it holds when the
    residual variance changes along the scanline (photon noise grows with the signal),
    where ``B⁻¹ χ²/dof`` assumes one variance for all samples. The leverage correction
    matters where there are few observations per parameter (a pixel in 9 photographs:
    27 values for 5 parameters, where the plain sandwich, HC0, is 20–30 % too small); it is
    applied up to :data:`LEVERAGE_SAMPLES` samples, above which HC0 is reported (over a
    scanline of 256 samples the two differ by well under 1 %).

    The lobe's part of ``J_i`` is a fixed linear map ``M`` of the monomials
    ``φ_i = b₀ (1, x_1, …, x_k)`` with ``b₀ = g e``, ``e = exp(−Σ_k x_k/α_k²)`` and ``x = t`` (isotropic)
    or ``(u, v)``:
    ``∂log b/∂log α_k = a_k x_k + c`` (``a = 2/α²``, ``c = −2``; anisotropic ``a_k = 2/α_k²``,
    ``c = −1``). So the meat's sums are ``M Σ r²_c φ`` and ``M (Σ r² φ φᵀ) Mᵀ``: per sample one
    residual and products of ``b₀`` with the geometry, no per-sample Jacobian, and all sums in
    one variadic reduction over the samples.

    One pass over the samples at the optimum ``θ`` (log α, or log αx, log αy) and ``ρs``:
    ``f`` (3, N), ``g`` (N,), ``w`` (C, N) as the kernel's geometry stage leaves them (sample axis
    last, weight 0 where a value is unusable), ``x`` (k, N) the search's geometry (``t``, or ``u, v``),
    and ``mean`` (3,) the weighted mean of ``f − ρs b`` per channel (``ρd/π``) as the search holds it.
    The exponential is formed again inside the pass: in the vectorised reduction one per sample
    cost less than carrying the search's through its steps. Returns ``(terms, finish)``: the
    per-sample terms (equally shaped ``(N,)`` arrays) whose sums over the samples the meat needs,
    and ``finish(sums) -> (P, P)``, the covariance from them.
    """
    k = theta.shape[0]
    n = g.shape[0]
    alpha = jnp.exp(theta)
    inv2 = jnp.exp(-2.0 * theta)  # (k,) 1/α_k²
    xs = [x[i] for i in range(k)]
    e = jnp.exp(sum(xs[i] * -inv2[i] for i in range(k)))
    if k == 1:
        q = inv2[0]  # b = q b₀
        slope, const = 2.0 * inv2, -2.0
    else:
        q = jnp.exp(-theta[0] - theta[1])
        slope, const = 2.0 * inv2, -1.0
    b0 = g * e
    # Per channel, (N,) each: broadcast over the channels, the exponential would be formed once per
    # channel, and XLA materialises it before the reduction instead (~0.3 ms per 1,024 scanlines).
    wc = [w[min(c, w.shape[0] - 1)] for c in range(3)]
    lobe = (rho_s * q) * b0
    r2c = [(wc[c] * (f[c] - lobe - mean[c])) ** 2 for c in range(3)]
    # J's lobe part per observation: jl = M φ, φ = b₀ (1, x_1, …, x_k).
    scl = rho_s / alpha  # (k,) ∂f/∂α_k = (ρs/α_k) b ∂log b/∂log α_k
    # M by its entries, None where structurally 0: row 0 maps φ to ∂f/∂ρs, row 1+i to ∂f/∂α_i.
    lin = [[q] + [None] * k]
    for i in range(k):
        lin.append([q * scl[i] * const] + [q * scl[i] * slope[i] if j == i else None for j in range(k)])
    if n <= LEVERAGE_SAMPLES:
        phi = [b0] + [b0 * x for x in xs]
        jl = [_dot(row, phi) for row in lin]  # 1+k of (N,)
        bread = cov / jnp.where(scale > 0, scale, 1.0)
        # Leverage h = w J B⁻¹ Jᵀ per observation, from the ρd (one-hot/π) and lobe (jl) parts of J.
        quad = sum(bread[3 + i, 3 + j] * jl[i] * jl[j] for i in range(1 + k) for j in range(1 + k))  # (N,)
        for c in range(3):
            cross = sum(bread[c, 3 + i] * jl[i] for i in range(1 + k))
            lev = wc[c] * (bread[c, c] / jnp.pi**2 + (2.0 / jnp.pi) * cross + quad)
            # A value with leverage 1 has residual 0: the floor only keeps 0/0 away.
            r2c[c] = r2c[c] / jnp.maximum(1.0 - lev, LEVERAGE_FLOOR) ** 2
    r2b = [x * b0 for x in r2c]
    tot = (r2c[0] + r2c[1] + r2c[2]) * b0 * b0
    pairs = [(i, j) for i in range(k) for j in range(i, k)]
    terms = r2c + r2b + [y * x for y in r2b for x in xs] + [tot] + [tot * x for x in xs]
    terms += [tot * xs[i] * xs[j] for i, j in pairs]
    return terms, lambda sums: _covariance(sums, lin, cov, scale, k, pairs)


def _covariance(sums, lin, cov, scale, k, pairs):
    """``B⁻¹ meat B⁻¹`` from :func:`sandwich_pass`'s sums and the map ``M`` (``lin``, nested lists) of the
    monomials to ``J``.

    Every product by its scalar entries (:func:`_product`): under ``vmap`` one elementwise loop over the
    batch, where the (P, P) matrix products became library calls per member (~1 ms of XLA:CPU time per
    1,024 scanlines, a fifth of what the sandwich added to the search).
    """
    p = 4 + k
    ip = 1.0 / jnp.pi
    phi_c = [[sums[3 + c]] + [sums[6 + c * k + i] for i in range(k)] for c in range(3)]  # Σ r²_c φ
    rest = sums[6 + 3 * k :]
    mom = {(0, 0): rest[0]}
    mom.update({(0, 1 + i): rest[1 + i] for i in range(k)})
    mom.update({(1 + i, 1 + j): rest[1 + k + m] for m, (i, j) in enumerate(pairs)})
    phi2 = [[mom[min(i, j), max(i, j)] for j in range(1 + k)] for i in range(1 + k)]  # Σ r² φ φᵀ
    lin_t = [list(col) for col in zip(*lin)]
    dl = _product(phi_c, lin_t)  # (3, 1+k): π Σ r²_c jl
    ll = _product(_product(lin, phi2), lin_t)  # (1+k, 1+k): Σ r² jl jlᵀ
    meat = [[sums[c] * ip * ip if c == d else None for d in range(3)] + [x * ip for x in dl[c]] for c in range(3)]
    meat += [[dl[c][i] * ip for c in range(3)] + ll[i] for i in range(1 + k)]
    inv_scale = 1.0 / jnp.where(scale > 0, scale, 1.0)
    bread = [[cov[i, j] * inv_scale for j in range(p)] for i in range(p)]
    out = _product(_product(bread, meat), bread)
    # Materialised entry by entry before they are stacked: fused into the stack, each entry re-derived
    # the products it shares with the others (a single loop five times dearer than the matmuls).
    out = jax.lax.optimization_barrier(out)
    return jnp.stack([jnp.stack(row) for row in out])


def _dot(x, y) -> Any:
    """``Σ x_i y_i`` over the entries that are not ``None`` (a structural 0); ``None`` where none is
    (never for the products :func:`_covariance` forms: every row of ``M`` has its first entry)."""
    terms = [a * b for a, b in zip(x, y) if a is not None and b is not None]
    return sum(terms[1:], terms[0]) if terms else None


def _product(a, b) -> list[list[Any]]:
    """``a @ b`` of small matrices held as nested lists of scalars (``None``: a structural 0)."""
    cols = [[row[j] for row in b] for j in range(len(b[0]))]
    return [[_dot(row, col) for col in cols] for row in a]


__all__ = ["LEVERAGE_FLOOR", "LEVERAGE_SAMPLES", "sandwich_pass"]
