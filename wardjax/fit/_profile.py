"""Profile-likelihood standard errors of ρs and α where the Gauss–Newton curvature fails.

The Gauss–Newton covariance of a scanline fit is the inverse curvature of χ² at the
optimum; it is honest while χ² is quadratic over about one standard error. Where the
curvature check of :func:`wardjax.fit._varpro.curvature_check` says it is not (a lobe
spanning few samples, a weakly detected lobe: χ² skewed in α), the 68 % profile-likelihood
interval replaces it (Venzon & Moolgavkar 1988; the likelihood-ratio interval of
Wilks' theorem):

* α: ``χ²_p(θ) = min_{ρd, ρs} χ²`` is exact by variable projection
  (``K₀ − ⟨b̃, f̃⟩² / ⟨b̃, b̃⟩``, :func:`~wardjax.fit._varpro.stats`), evaluated on a
  grid of ``θ = log α`` of ``±PROFILE_HALF`` Gauss–Newton standard errors;
* ρs: ``χ²_p(s) = min_θ (K₀ − 2 s ⟨b̃, f̃⟩(θ) + s² ⟨b̃, b̃⟩(θ))``, traced along its
  path: at each grid θ the ``s`` for which that θ is the minimiser,
  ``s*(θ) = ⟨b̃', f̃⟩ / ⟨b̃', b̃⟩`` (``∂χ²/∂θ = 0``), with ``χ²_p(s*(θ))`` exact, on a θ
  grid narrowed by the ρs–α correlation ``|r|`` (the path reaches ``ŝ ± σ_s`` near
  ``θ̂ ± |r| σ_θ``);

and the interval's ends are where ``χ²_p`` rises by one residual variance ``χ²/dof``
above its minimum (linear interpolation between grid points). The standard error
reported is its half-width. Isotropic fits only; anisotropic scanline fits keep the
Gauss–Newton errors.
"""

from __future__ import annotations

import functools
import math

import jax
import jax.numpy as jnp

from . import _varpro

__all__ = ["PROFILE_HALF", "PROFILE_POINTS", "profile_chunk", "profile_errors"]

PROFILE_HALF = 6.0  # grid half-width, in Gauss–Newton standard errors of log α
PROFILE_POINTS = 33


def _crossings(c, delta):
    """Where ``delta`` (M,) first reaches 1 on each side of its minimum.

    Interpolated linearly in ``√delta``, which is exactly linear in ``c`` where χ² is quadratic.
    """
    i0 = jnp.argmin(delta)
    idx = jnp.arange(c.shape[0])
    above = delta >= 1.0
    right = jnp.where(above & (idx > i0), idx, c.shape[0] - 1).min()
    left = jnp.where(above & (idx < i0), idx, 0).max()

    root = jnp.sqrt(jnp.maximum(delta, 0.0))  # linear in the parameter where χ² is quadratic

    def interp(j, k):  # between j (below) and k (above, or the grid end)
        dj, dk = root[j], root[k]
        t = jnp.clip((1.0 - dj) / jnp.where(dk > dj, dk - dj, 1.0), 0.0, 1.0)
        return c[j] + t * (c[k] - c[j])

    hi = interp(jnp.maximum(right - 1, 0), right)
    lo = interp(jnp.minimum(left + 1, c.shape[0] - 1), left)
    return lo, hi


def profile_errors(p: _varpro.Prepared, alpha, rho_s, chi2, cov, scale):
    """``(σ_ρs, σ_α)``: half-widths of the 68 % profile-likelihood intervals of one isotropic scanline.

    ``alpha``, ``rho_s``, ``chi2`` are the fit's optimum, ``cov`` its Gauss–Newton
    covariance (natural parameters, scaled), ``scale = χ²/dof``.
    """
    theta0 = jnp.log(alpha)
    scale = jnp.where(scale > 0, scale, 1.0)
    sd_t = jnp.sqrt(jnp.abs(cov[4, 4])) / alpha
    c = jnp.linspace(-PROFILE_HALF, PROFILE_HALF, PROFILE_POINTS, dtype=alpha.dtype)
    lo_b, hi_b = math.log(_varpro.ALPHA_MIN), math.log(_varpro.ALPHA_MAX)
    thetas = jnp.clip(theta0 + sd_t * c, lo_b, hi_b)
    sts = jax.vmap(lambda t: _varpro.stats(t[None], p, True, with_jac=False))(thetas)
    chi_min = jnp.minimum(chi2, jnp.min(sts.chi2))
    d_alpha = (sts.chi2 - chi_min) / scale
    lo, hi = _crossings(thetas, d_alpha)
    sigma_alpha = 0.5 * (jnp.exp(hi) - jnp.exp(lo))
    # ρs: the path of its profile, s*(θ) = ⟨b̃', f̃⟩ / ⟨b̃', b̃⟩ = s − Jᵀr / (s ⟨b̃', b̃⟩), on a θ grid
    # narrowed by the correlation (the path reaches ŝ ± σ_s at θ̂ ± |r| σ_θ).
    corr = jnp.abs(cov[3, 4]) / jnp.sqrt(jnp.abs(cov[3, 3] * cov[4, 4]))
    narrow = jnp.clip(1.5 * jnp.where(jnp.isfinite(corr), corr, 1.0), 0.05, 1.0)
    path = jax.vmap(lambda t: _varpro.stats(t[None], p, True))(jnp.clip(theta0 + narrow * sd_t * c, lo_b, hi_b))
    s_t, spb, jtr = path.s, path.spb[:, 0], path.jtr[:, 0]
    den = s_t * spb
    s_star = jnp.maximum(jnp.where(den != 0, s_t - jtr / jnp.where(den != 0, den, 1.0), s_t), 0.0)
    prof_s = p.k0 - 2.0 * s_star * path.sbf + s_star * s_star * path.sbb
    d_s = (prof_s - jnp.minimum(chi_min, jnp.min(prof_s))) / scale
    lo_s, hi_s = _crossings(s_star, d_s)
    return 0.5 * jnp.abs(hi_s - lo_s), sigma_alpha


@functools.partial(jax.jit)
def profile_chunk(prepared, alpha, rho_s, chi2, cov, scale):
    """:func:`profile_errors` of each scanline of a prepared chunk (vmapped)."""
    return jax.vmap(profile_errors)(prepared, alpha, rho_s, chi2, cov, scale)
