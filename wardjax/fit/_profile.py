"""Profile-likelihood standard errors of ρs and α where the Gauss–Newton curvature fails.

The Gauss–Newton covariance of a scanline fit is the inverse curvature of χ² at the
optimum; it is honest while χ² is quadratic over about one standard error. Where the
curvature check of :func:`wardjax.fit._varpro.curvature_pass` says it is not (a lobe
spanning few samples, a weakly detected lobe: χ² skewed in α), the 68 % profile-likelihood
interval replaces it (Venzon & Moolgavkar 1988; the likelihood-ratio interval of
Wilks' theorem):

* α: ``χ²_p(θ) = min_{ρd, ρs} χ²`` is exact by variable projection
  (``K₀ − ⟨b̃, f̃⟩² / ⟨b̃, b̃⟩``, :func:`~wardjax.fit._varpro.stats`), evaluated on a
  at the ``θ = log α`` where it crosses, found from ``θ̂ ± σ_θ`` by false position in
  ``√Δχ²`` (linear in θ where χ² is quadratic) within ``±PROFILE_HALF`` standard errors;
* ρs: ``χ²_p(s) = min_θ (K₀ − 2 s ⟨b̃, f̃⟩(θ) + s² ⟨b̃, b̃⟩(θ))``, traced along its
  path: at each θ the ``s`` for which that θ is the minimiser,
  ``s*(θ) = ⟨b̃', f̃⟩ / ⟨b̃', b̃⟩`` (``∂χ²/∂θ = 0``), with ``χ²_p(s*(θ))`` exact, the
  crossing sought the same way from ``θ̂ ± |r| σ_θ`` (the path reaches ``ŝ ± σ_s``
  near there, ``r`` the ρs–α correlation);

and the interval's ends are where ``χ²_p`` rises by one residual variance ``χ²/dof``
above the fit's minimum. The standard error
reported is its half-width. Isotropic fits only; anisotropic scanline fits keep the
Gauss–Newton errors.
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp

from . import _varpro
from ._data import kernel

__all__ = [
    "PENDING",
    "PROFILED",
    "PROFILE_HALF",
    "PROFILE_ITERATIONS",
    "profile_chunk",
    "profile_errors",
    "profile_flagged",
    "rescale",
    "rescale_rows",
    "round_lanes",
]

PROFILE_HALF = 6.0  # farthest a crossing is sought, in Gauss–Newton standard errors of log α
# Evaluations per side and parameter: a probe, then false-position steps. A fourth moved no σ by more than
# 1.3 % (99 % of them by under 1.4·10⁻⁴) over 16,000 scanlines of the speed benchmark's four regimes.
PROFILE_ITERATIONS = 3
# ``ScanlineSolution.nonlinear`` codes: 0 the curvature check passed (or was not run); PROFILED the
# profile's σ replaced Gauss–Newton's; PENDING the check failed and the profile is still to be formed.
PROFILED = 1
PENDING = 2


def _crossing(delta_fn, x0, v0, step, direction):
    """Where ``√Δ`` reaches 1 going from the optimum ``x0`` in ``direction`` (±1): ``(t, v)``.

    ``delta_fn(x) -> (Δ, v)`` is the profile's rise (in residual variances) at ``x`` and the
    value reported there, ``v0`` that value at the optimum. ``√Δ`` is linear in ``x`` where χ²
    is quadratic, so the first probe at ``x0 ± step`` and the false-position steps after it
    (secant extrapolation until the crossing is bracketed) converge in a few evaluations.
    Returns the crossing's distance ``t`` and ``v`` interpolated there.
    """
    t_max = PROFILE_HALF * step
    lo = (jnp.zeros_like(step), jnp.zeros_like(step), v0)  # (t, √Δ, v) below the crossing
    hi = (t_max, jnp.full_like(step, jnp.inf), v0)  # above it, once found
    has_hi = jnp.zeros((), bool)
    t = step
    for _ in range(PROFILE_ITERATIONS):
        d, v = delta_fn(x0 + direction * t)
        root = jnp.sqrt(jnp.maximum(jnp.where(jnp.isfinite(d), d, jnp.inf), 0.0))
        above = root >= 1.0
        lo = jax.tree_util.tree_map(lambda new, old: jnp.where(above, old, new), (t, root, v), lo)
        hi = jax.tree_util.tree_map(lambda new, old: jnp.where(above, new, old), (t, root, v), hi)
        has_hi = has_hi | above
        t_lo, r_lo, _ = lo
        t_hi, r_hi, _ = hi
        bracket = t_lo + (1.0 - r_lo) * (t_hi - t_lo) / jnp.where(jnp.isfinite(r_hi), r_hi - r_lo, 1.0)
        extrap = jnp.where(r_lo > 0, t_lo / jnp.where(r_lo > 0, r_lo, 1.0), 2.0 * t_lo)
        t = jnp.where(has_hi & jnp.isfinite(r_hi), bracket, jnp.minimum(extrap, 4.0 * t_lo))
        t = jnp.clip(t, 0.0, t_max)
    t_lo, r_lo, v_lo = lo
    t_hi, r_hi, v_hi = hi
    ok = has_hi & jnp.isfinite(r_hi) & (r_hi > r_lo)
    frac = jnp.where(ok, (1.0 - r_lo) / jnp.where(ok, r_hi - r_lo, 1.0), 1.0)
    return jnp.where(ok, t_lo + frac * (t_hi - t_lo), t_max), jnp.where(ok, v_lo + frac * (v_hi - v_lo), v_lo)


def profile_errors(p: _varpro.Prepared, alpha, rho_s, chi2, cov, scale):
    """``(σ_ρs, σ_α)``: half-widths of the 68 % profile-likelihood intervals of one isotropic scanline.

    ``alpha``, ``rho_s``, ``chi2`` are the fit's optimum, ``cov`` its Gauss–Newton
    covariance (natural parameters, scaled), ``scale = χ²/dof``. Each of the four interval
    ends costs :data:`PROFILE_ITERATIONS` evaluations of the sums.
    """
    theta0 = jnp.log(alpha)
    scale = jnp.where(scale > 0, scale, 1.0)
    sd_t = jnp.sqrt(jnp.abs(cov[4, 4])) / alpha
    lo_b, hi_b = math.log(_varpro.ALPHA_MIN), math.log(_varpro.ALPHA_MAX)

    def rise_alpha(theta):
        theta = jnp.clip(theta, lo_b, hi_b)
        st = _varpro.stats(theta[None], p, True, with_jac=False)
        return (st.chi2 - chi2) / scale, jnp.exp(theta)

    def rise_rho_s(theta):  # along the ρs profile's path: s*(θ) = s − Jᵀr / (s ⟨b̃', b̃⟩)
        theta = jnp.clip(theta, lo_b, hi_b)
        st = _varpro.stats(theta[None], p, True)
        den = st.s * st.spb[0]
        s_star = jnp.maximum(jnp.where(den != 0, st.s - st.jtr[0] / jnp.where(den != 0, den, 1.0), st.s), 0.0)
        prof = p.k0 - 2.0 * s_star * st.sbf + s_star * s_star * st.sbb
        return (prof - chi2) / scale, s_star

    ends_a = [_crossing(rise_alpha, theta0, alpha, sd_t, d)[1] for d in (1.0, -1.0)]
    # The ρs path reaches ŝ ± σ_s near θ̂ ± |r| σ_θ.
    corr = jnp.abs(cov[3, 4]) / jnp.sqrt(jnp.abs(cov[3, 3] * cov[4, 4]))
    narrow = jnp.clip(jnp.where(jnp.isfinite(corr), corr, 1.0), 0.05, 1.0)
    ends_s = [_crossing(rise_rho_s, theta0, rho_s, narrow * sd_t, d)[1] for d in (1.0, -1.0)]
    return 0.5 * jnp.abs(ends_s[0] - ends_s[1]), 0.5 * jnp.abs(ends_a[0] - ends_a[1])


def rescale(cov, cov_gn, sig):
    """``cov`` (P, P) with the ρs and α rows and columns scaled by the profile's ``sig = (σ_ρs, σ_α)``
    over Gauss–Newton's (from ``cov_gn``): the diagonal then holds the profile variances (for an
    unweighted fit, the sandwich's scaled by the same ratio), the correlations are kept. Returns
    ``(cov, good)``; where the profile or Gauss–Newton's σ is not a positive number ``cov`` is unchanged.
    """
    gn = jnp.sqrt(jnp.clip(jnp.diagonal(cov_gn)[3:5], 0.0, None))
    good = jnp.all(jnp.isfinite(sig) & (sig > 0)) & jnp.all(gn > 0)
    ratio = jnp.ones(cov.shape[-1], cov.dtype).at[3:5].set(jnp.where(good, sig / jnp.where(good, gn, 1.0), 1.0))
    return cov * ratio[:, None] * ratio[None, :], good


rescale_rows = jax.jit(jax.vmap(rescale))  # (R, P, P), (R, P, P), (R, 2) → (R, P, P), (R,)


def profile_flagged(prepared: _varpro.Prepared, sol: _varpro.ScanlineSolution, lanes: int):
    """``sol`` of a chunk with the profile errors of its :data:`PENDING` rows, in the same program.

    Up to ``lanes`` pending rows (a static count) are profiled, in rounds of :func:`round_lanes`
    lanes: each round compacts the next pending rows into its lanes (``jnp.nonzero`` with a static
    size), profiles them and scatters them back (``sol.cov`` rescaled by :func:`rescale`,
    ``nonlinear`` set to :data:`PROFILED`, or 0 where the profile gave no usable σ). A
    ``lax.while_loop`` runs only as many rounds as there are pending rows to fill: the cost follows
    the failures (none in a chunk without one), not the largest share a chunk may hold. Rows past
    ``lanes`` stay :data:`PENDING` for the caller to profile apart.
    """
    width = round_lanes(lanes)
    rounds = -(-lanes // width)

    def more(carry):
        i, s = carry
        return (i < rounds) & jnp.any(s.nonlinear == PENDING)

    def step(carry):
        i, s = carry
        return i + 1, _profile_lanes(prepared, s, lanes=width)

    return jax.lax.while_loop(more, step, (jnp.zeros((), jnp.int32), sol))[1]


def round_lanes(lanes: int) -> int:
    """Lanes of one round of :func:`profile_flagged`: a quarter of ``lanes`` (at least 1), so that a
    chunk with few failures pays for a quarter of its share, and one with many for four rounds."""
    return max(lanes // 4, 1)


def _profile_lanes(prepared, sol, *, lanes: int):
    pending = sol.nonlinear == PENDING
    rows = pending.shape[0]
    idx = jnp.nonzero(pending, size=lanes, fill_value=rows)[0]  # (lanes,), `rows` past the last
    at = jnp.minimum(idx, rows - 1)
    sub = jax.tree_util.tree_map(lambda a: a[at], prepared)
    scale = sol.chi2 / jnp.maximum(sol.dof, 1).astype(sol.chi2.dtype)
    sig = jax.vmap(profile_errors)(sub, sol.alpha[at, 0], sol.rho_s[at], sol.chi2[at], sol.cov_gn[at], scale[at])
    cov, good = jax.vmap(rescale)(sol.cov[at], sol.cov_gn[at], jnp.stack(sig, -1))
    code = jnp.where(good, PROFILED, 0).astype(sol.nonlinear.dtype)
    # Lanes past the pending rows hold index `rows`: the scatter drops them.
    return sol._replace(
        cov=sol.cov.at[idx].set(cov, mode="drop"), nonlinear=sol.nonlinear.at[idx].set(code, mode="drop")
    )


@kernel()
def profile_chunk(prepared, alpha, rho_s, chi2, cov, scale):
    """:func:`profile_errors` of each scanline of a prepared chunk (vmapped)."""
    return jax.vmap(profile_errors)(prepared, alpha, rho_s, chi2, cov, scale)
