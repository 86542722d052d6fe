"""The joint refit over all scanlines of a capture: shared ρs, αx, αy, a ρd per scanline.

Image-based paper, section 4.1: one scanline alone barely constrains αx in
the papers' rig (lamp and camera in the plane x = 0, scanlines along y); the
joint fit over scanlines at different x offsets is where anisotropy is
identified. ρd per scanline is profiled out (variable projection); the
shared parameters are fitted in log coordinates with optimistix's
Levenberg–Marquardt.
"""

from __future__ import annotations

import dataclasses
import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx

from .. import _shapes
from .._status import Status
from ..ward import NORMALIZATIONS, WardParams, ward_geometry
from . import _varpro
from ._data import SAMPLE_FILL, bucket_rows, clean_jit, kernel, moments_chunk, pad_rows, pad_samples

__all__ = ["CombinedFit", "combined"]


@dataclasses.dataclass(frozen=True, eq=False)
class CombinedFit:
    """One joint fit over all usable scanlines of a batch.

    Attributes
    ----------
    params
        :class:`WardParams` (unbatched): shared ρs, αx, αy; ρd is the mean of
        the per-scanline nuisance ρd.
    stderr
        1-σ standard errors, same structure. For ρs and α they are the
        profiled (Schur-complement) errors with every ρd free.
    rho_d_scanlines
        ``(S, 3)`` the per-scanline ρd at the joint optimum (NaN for scanlines
        left out).
    covariance
        Covariance of the shared parameters ``(ρs, α)`` or ``(ρs, αx, αy)``
        that ``stderr`` reports (see ``errors``).
    covariance_model, covariance_robust
        The Gauss–Newton covariance scaled by χ²/dof (residuals independent),
        and the sandwich covariance clustered by scanline (residuals may be
        correlated along a scanline, as ρd texture makes them).
    errors
        ``"robust"`` or ``"model"``: which covariance ``stderr`` reports.
    chi2, dof, status
        Fit quality and :class:`Status`; ``n_scanlines`` were used.
    """

    params: WardParams
    stderr: WardParams
    rho_d_scanlines: np.ndarray
    covariance: np.ndarray
    chi2: float
    dof: int
    status: Status
    n_scanlines: int
    model: str
    normalization: str
    covariance_model: np.ndarray | None = None
    covariance_robust: np.ndarray | None = None
    errors: str = "model"

    @property
    def reduced_chi2(self) -> float:
        return self.chi2 / max(self.dof, 1)


class _JointArgs(eqx.Module):
    f: jax.Array  # (S, N, 3)
    u: jax.Array
    v: jax.Array
    g: jax.Array
    w: jax.Array  # (S, N, C)


def _joint_rho_d(log_rs, theta, a: _JointArgs, iso: bool):
    """Per-scanline profiled ρd (S, 3) and the spec basis (S, N) at given ρs, α."""
    b = jax.vmap(lambda u, v, g: _varpro.basis(theta, u, v, g, iso))(a.u, a.v, a.g)  # (S, N)
    rs = jnp.exp(log_rs)
    wsum = jnp.sum(a.w, axis=1)  # (S, C)
    safe = jnp.where(wsum > 0, wsum, 1.0)
    resid_lin = a.f - rs * b[..., None]
    a_lin = jnp.sum(a.w * resid_lin, axis=1) / safe  # (S, 3)
    return a_lin, b


_joint_rho_d_jit = jax.jit(_joint_rho_d, static_argnames="iso")


@jax.jit
def _joint_prepare(f, wi, wo, w, n_samples, norm_index):
    """Geometry of the joint fit's padded data, and the moments of its log-α grid start.

    Returns the :class:`_JointArgs` (invalid geometry weighted 0) and
    :func:`~._data.moments_chunk` of the same data, sample axis last, for the
    normalisation ``NORMALIZATIONS[norm_index]`` (traced: a capture's fit and
    its export refit in another normalisation share the program). One
    program: run eagerly, these few dozen small operations would each compile
    once per shape bucket.
    """
    geom = ward_geometry(wi, wo, norm_index)
    args = _JointArgs(f, geom.u, geom.v, geom.g, jnp.where(geom.valid[..., None], w, 0.0))
    # Start: the best of a log-α grid of the joint profiled χ² (for fixed α the
    # joint model is linear in every ρd and the shared ρs), not the per-scanline
    # fits, which a strong texture can spoil.
    prepared = moments_chunk(
        jnp.swapaxes(args.f, -1, -2), args.u, args.v, args.g, jnp.swapaxes(args.w, -1, -2), n_samples, iso=True
    )
    return args, prepared


def _joint_residual(y, a: _JointArgs, iso: bool):
    log_rs, theta = y[0], y[1:]
    a_lin, b = _joint_rho_d(log_rs, theta, a, iso)
    r = a.f - a_lin[:, None, :] - jnp.exp(log_rs) * b[..., None]
    return jnp.sqrt(jnp.broadcast_to(a.w, a.f.shape)) * r


def _no_data(n_scan: int, k: int, model: str, normalization: str) -> CombinedFit:
    """The joint fit of scanlines none of which has usable data: NaN, status ``INSUFFICIENT_DATA``."""
    nan = WardParams.from_estimate(rho_d=np.full(3, np.nan), rho_s=np.nan, alpha_x=np.nan, alpha_y=np.nan)
    return CombinedFit(
        nan,
        nan,
        np.full((n_scan, 3), np.nan),
        np.full((k + 1, k + 1), np.nan),
        float("nan"),
        0,
        Status.INSUFFICIENT_DATA,
        0,
        model,
        normalization,
    )


def combined(
    data: tuple, scan_status: np.ndarray, normalization: str, model: str, *, errors: str, max_steps: int, rtol: float
) -> CombinedFit:
    """The joint refit of the scanlines ``data = (f, wi, wo, mask, weights)`` (as validated by
    :func:`~wardjax.fit._data.validate`), whose per-scanline fits ended with ``scan_status`` ``(S,)``.
    """
    iso = model == "isotropic"
    k = 1 if iso else 2
    # Cleaned with both axes padded to bucket sizes (padded samples unusable), so that batches of
    # slightly different shapes share every compiled program below.
    s_true, n_true = data[0].shape[:2]
    padded = [
        None if a is None else _shapes.pad_to_shape(a, (_shapes.bucket(s_true),), fill)
        for a, fill in zip(pad_samples(data, _shapes.bucket(n_true)), SAMPLE_FILL)
    ]
    f_c, wi_c, wo_c, w_c = (
        np.asarray(a)[:s_true]
        for a in clean_jit(*(None if a is None else jnp.asarray(a) for a in padded), dtype=np.dtype(np.float64))
    )
    # Every scanline with usable data takes part, including those whose own fit
    # saw no lobe: a scanline beside the highlight says where the lobe is *not*,
    # which is exactly what constrains αx.
    wfull = np.broadcast_to(w_c, f_c.shape)
    use = np.all(np.sum(wfull > 0, axis=1) >= 3, axis=-1) & (scan_status != Status.NONFINITE)
    n_use = int(np.sum(use))
    if n_use == 0:
        return _no_data(len(scan_status), k, model, normalization)
    # Pad the scanline axis to a bucket size with zero-weight rows: one compile per bucket.
    rows = bucket_rows(n_use, 1 << 30)
    sel = [np.asarray(a)[use] for a in (f_c, wi_c, wo_c, w_c)]
    f_p, wi_p, wo_p, w_p = (pad_rows(a, rows) for a in sel)
    wi_p[n_use:, :, 2] = wo_p[n_use:, :, 2] = 1.0  # padded rows: straight up, weight 0
    args, prepared = _joint_prepare(
        f_p, wi_p, wo_p, w_p, np.int32(n_true), np.int32(NORMALIZATIONS.index(normalization))
    )
    log_a, rs0 = (float(v) for v in _joint_grid_start(prepared))
    y = jnp.asarray([math.log(max(rs0, 1e-6))] + [log_a] * k, jnp.float64)
    n_obs = int(np.sum(np.broadcast_to(np.asarray(args.w), args.f.shape) > 0))
    dof = n_obs - (3 * n_use + 1 + k)
    # optimistix's LM stops on small steps, which a large damping can also
    # produce: certify the optimum with the Gauss–Newton step and restart
    # (resetting the damping) until it is below 1e-3 σ.
    certified = False
    jac = r = np.empty(0)  # set by the loop's first pass, which always runs
    for _ in range(4):
        y, _ = _solve_joint(y, args, iso, max_steps, rtol)
        jac, r = _joint_jacobian(y, args, iso)
        jac = np.asarray(jac).reshape(-1, 1 + k)
        r = np.asarray(r).ravel()
        jtj = jac.T @ jac
        try:
            step = np.linalg.solve(jtj, -jac.T @ r)
            sigma = np.sqrt(np.diag(np.linalg.inv(jtj)) * float(r @ r) / max(dof, 1))
        except np.linalg.LinAlgError:  # degenerate optimum (e.g. ρs → 0): reported as nonfinite below
            break
        if np.all(np.abs(step) <= 1e-3 * sigma + 1e-12):
            certified = True
            break
        y = y + jnp.asarray(step)  # a Gauss–Newton step is the best next start
    y = np.asarray(y)
    chi2 = float(r @ r)
    scale = chi2 / max(dof, 1)

    # Profiled covariance of the shared natural parameters (ρs, α…): the
    # residual already has every ρd projected out, so JᵀJ is the Schur complement.
    nat = np.exp(y)
    jac_nat = jac / nat[None, :]
    info = jac_nat.T @ jac_nat
    a_inv = np.linalg.pinv(info) if np.all(np.isfinite(info)) else np.full_like(info, np.nan)
    cov_model = a_inv * scale
    # Sandwich clustered by scanline: each scanline's score g_s = J_sᵀ r_s.
    scores = np.einsum("snp,sn->sp", jac_nat.reshape(rows, -1, 1 + k), r.reshape(rows, -1))[:n_use]
    meat = scores.T @ scores * n_use / max(n_use - 1, 1)
    cov_robust = a_inv @ meat @ a_inv
    used = "robust" if errors == "robust" and n_use >= 10 else "model"
    cov = cov_robust if used == "robust" else cov_model
    se = np.sqrt(np.clip(np.diag(cov), 0, None))

    a_lin, _ = _joint_rho_d_jit(jnp.asarray(y[0]), jnp.asarray(y[1:]), args, iso)
    rho_d_s = np.pi * np.asarray(a_lin)[:n_use]
    rho_d = rho_d_s.mean(axis=0)
    # σ of the mean ρd: noise in each scanline's mean, plus (ρs, α) uncertainty
    # through ∂ρd/∂(ρs, α); the two are uncorrelated (projected residual ⟂ means).
    # Each channel's own residual variance: pooled over R, G, B (with the lobe grey) every channel's σ was the same.
    wfull_p = np.broadcast_to(np.asarray(args.w), args.f.shape)
    wsum = np.sum(wfull_p, axis=1)[:n_use]  # (S, 3)
    dof_c = np.maximum(np.sum(wfull_p > 0, axis=(0, 1)) - n_use - (1 + k) / 3, 1)  # (3,): ρd per channel, θ shared
    scale_c = np.sum(r.reshape(args.f.shape) ** 2, axis=(0, 1)) / dof_c
    noise_var = (np.pi / n_use) ** 2 * np.sum(scale_c / np.where(wsum > 0, wsum, np.inf), axis=0)
    grad = np.asarray(_joint_rho_d_mean_grad(jnp.asarray(y), args, iso, jnp.asarray(n_use))) / nat[None, :]
    rho_d_var = noise_var + np.einsum("ip,pq,iq->i", grad, cov, grad)

    rho_d_full = np.full((len(scan_status), 3), np.nan)
    rho_d_full[use] = rho_d_s
    ax, ay = (nat[1], nat[1]) if iso else (nat[1], nat[2])
    sx, sy = (se[1], se[1]) if iso else (se[1], se[2])
    finite = np.all(np.isfinite(y)) and np.isfinite(chi2) and np.all(np.isfinite(se))
    status = Status.NONFINITE if not finite else (Status.CONVERGED if certified else Status.MAX_STEPS)
    return CombinedFit(
        params=WardParams.from_estimate(rho_d=rho_d, rho_s=nat[0], alpha_x=ax, alpha_y=ay),
        stderr=WardParams.from_estimate(rho_d=np.sqrt(rho_d_var), rho_s=se[0], alpha_x=sx, alpha_y=sy),
        rho_d_scanlines=rho_d_full,
        covariance=cov,
        chi2=chi2,
        dof=int(dof),
        status=status,
        n_scanlines=n_use,
        model=model,
        normalization=normalization,
        covariance_model=cov_model,
        covariance_robust=cov_robust,
        errors=used,
    )


_JOINT_GRID = np.linspace(math.log(2e-3), math.log(1.0), 24)


@kernel()  # the scanline kernels' compiler options: its sums are theirs (_varpro.stats)
def _joint_grid_start(prepared):
    """``(log α, ρs)`` minimising the joint profiled χ² on a log-α grid, refined by a parabola."""
    thetas = jnp.asarray(_JOINT_GRID)

    def per_scanline(p):
        st = jax.vmap(lambda th: _varpro.stats(th[None], p, True, with_jac=False))(thetas)
        return st.sbf, st.sbb

    sbf, sbb = jax.vmap(per_scanline)(prepared)  # (S, G); padded rows contribute 0
    sf, sb = jnp.sum(sbf, axis=0), jnp.sum(sbb, axis=0)
    gain = jnp.where((sf > 0) & (sb > 0), sf * sf / jnp.where(sb > 0, sb, 1.0), 0.0)  # χ² = K₀ − gain
    i = jnp.clip(jnp.argmax(gain), 1, thetas.shape[0] - 2)
    gm, g0, gp = gain[i - 1], gain[i], gain[i + 1]
    h = thetas[1] - thetas[0]
    curv = gm - 2 * g0 + gp
    shift = jnp.where(curv < 0, 0.5 * h * (gm - gp) / jnp.where(curv < 0, curv, -1.0), 0.0)
    theta = thetas[i] + jnp.clip(shift, -h, h)
    rs = jnp.where(sb[i] > 0, jnp.maximum(sf[i], 0.0) / jnp.where(sb[i] > 0, sb[i], 1.0), 0.0)
    return theta, rs


@eqx.filter_jit
def _joint_rho_d_mean_grad(y, args: _JointArgs, iso: bool, n_use):
    """``∂ρ̄d/∂y`` of the mean ρd over the first ``n_use`` (traced) rows; the rest are padding."""
    real = (jnp.arange(args.f.shape[0]) < n_use)[:, None]

    def fn(yy):
        rho_d = _joint_rho_d(yy[0], yy[1:], args, iso)[0]
        return jnp.pi * jnp.sum(jnp.where(real, rho_d, 0.0), axis=0) / n_use

    return jax.jacfwd(fn)(y)


@eqx.filter_jit
def _solve_joint(y0, args: _JointArgs, iso: bool, max_steps: int, rtol: float):
    solver = optx.LevenbergMarquardt(rtol=rtol, atol=rtol * 1e-2)
    sol = optx.least_squares(
        lambda y, a: _joint_residual(y, a, iso), solver, y0, args=args, max_steps=max_steps, throw=False
    )
    return sol.value, sol.result == optx.RESULTS.successful


@eqx.filter_jit
def _joint_jacobian(y, args: _JointArgs, iso: bool):
    """Jacobian (in ``y``) and value of the profiled joint residual."""
    return jax.jacfwd(lambda yy: _joint_residual(yy, args, iso))(y), _joint_residual(y, args, iso)
