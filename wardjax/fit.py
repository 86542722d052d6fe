"""Batched Levenberg–Marquardt fits of the Ward model to scanlines of BRDF samples.

Two solvers, one problem (weighted least squares of ``f_r`` against the Ward
model, section 3 of the image-based paper):

``solver="fast"`` (default)
    A fixed-iteration LM on the variable-projection reduction written in JAX
    (:mod:`wardjax._varpro`): ρd and ρs are solved in closed form, only the
    roughness is iterated, every scanline does the same work under ``vmap``.
``solver="optimistix"``
    :class:`optimistix.LevenbergMarquardt` on the full problem in well-scaled
    coordinates (ρd, log ρs, log α), vmapped. The reference path: slower, and
    the tests check that both reach the same optimum.

:meth:`ScanlineFit.combined` refits all scanlines of a batch jointly with
optimistix: shared ρs, αx, αy and a ρd per scanline profiled out. In the
papers' rig (lamp and camera in the plane x = 0, scanlines along y) a single
scanline barely constrains αx; the joint fit over scanlines at different x
offsets is where anisotropy is identified.

Uncertainties are ``√diag((JᵀWJ)⁻¹ · χ²/dof)``: the Gauss–Newton covariance
at the solution scaled by the residual variance. With ``weights = 1/σ²`` from
a correct noise model χ²/dof ≈ 1 and the scaling is harmless; with unit
weights it supplies the noise level.

Fits run in float64 inside a scoped ``jax.enable_x64(True)``: importing or
calling wardjax never changes the caller's global JAX settings.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from typing import Literal

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx

from . import _varpro
from ._status import Status
from .ward import NORMALIZATIONS, Normalization, WardParams, ward_geometry

__all__ = ["CombinedFit", "ScanlineFit", "fit_scanlines"]

Model = Literal["isotropic", "anisotropic"]
Solver = Literal["fast", "optimistix"]

# Rows per compiled chunk: about 1–4 MB per input array (issue: one huge batch
# was 2–7× slower than chunks of this size).
_CHUNK = {np.dtype(np.float64): 1024, np.dtype(np.float32): 4096}


# --------------------------------------------------------------------------- results


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
        Covariance of the shared parameters ``(ρs, α)`` or ``(ρs, αx, αy)``.
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

    @property
    def reduced_chi2(self) -> float:
        return self.chi2 / max(self.dof, 1)


@dataclasses.dataclass(frozen=True, eq=False)
class ScanlineFit:
    """Per-scanline fits of a batch of ``S`` scanlines.

    Attributes
    ----------
    params, stderr
        :class:`WardParams` batched over ``S`` (NumPy leaves): ``rho_d (S, 3)``,
        ``rho_s (S,)``, ``alpha_x (S,)``, ``alpha_y (S,)``.
    covariance
        ``(S, P, P)`` in natural parameters ``(ρd R, G, B, ρs, α)`` or
        ``(…, ρs, αx, αy)``.
    chi2, dof
        ``(S,)`` weighted residual sum of squares and degrees of freedom.
    status
        ``(S,)`` :class:`Status` codes; :attr:`status_names` reads them.
    """

    params: WardParams
    stderr: WardParams
    covariance: np.ndarray
    chi2: np.ndarray
    dof: np.ndarray
    status: np.ndarray
    model: str
    normalization: str
    solver: str
    _data: tuple = dataclasses.field(repr=False)

    @property
    def status_names(self) -> np.ndarray:
        """``(S,)`` status names: ``"converged"``, ``"max_steps"``, …"""
        return Status.names(self.status)

    @property
    def ok(self) -> np.ndarray:
        """``(S,)`` True where the fit converged."""
        return self.status == Status.CONVERGED

    @property
    def reduced_chi2(self) -> np.ndarray:
        return self.chi2 / np.maximum(self.dof, 1)

    def __len__(self) -> int:
        return int(self.status.shape[0])

    def combined(
        self, model: Model | None = None, *, max_steps: int = 256, rtol: float = 1e-10
    ) -> CombinedFit:
        """Joint refit over all scanlines: shared ρs, αx, αy; ρd per scanline.

        Uses :class:`optimistix.LevenbergMarquardt` on ``(log ρs, log αx,
        log αy)`` with each scanline's ρd solved in closed form inside the
        residual (variable projection), started from the medians of the
        converged per-scanline fits. Every scanline with at least 3 valid
        samples in each channel takes part (a scanline that misses the
        highlight still says where the lobe is not); mask a scanline to
        leave it out.

        Parameters
        ----------
        model
            ``"isotropic"`` (one shared α) or ``"anisotropic"``; defaults to
            the model of the per-scanline fits.
        """
        model = model or self.model
        _check_choice("model", model, ("isotropic", "anisotropic"))
        with jax.enable_x64(True):
            return _combined(self, model, max_steps=max_steps, rtol=rtol)


# --------------------------------------------------------------------------- boundary


def _check_choice(name, value, allowed):
    if value not in allowed:
        raise ValueError(f"{name}={value!r} is not one of {', '.join(map(repr, allowed))}")


def _as_batch(name: str, x, dtype, shape: tuple[int, ...] | None = None) -> np.ndarray:
    arr = np.asarray(x)
    if arr.dtype == object or not (np.issubdtype(arr.dtype, np.number) or arr.dtype == bool):
        raise TypeError(f"{name} must be a numeric array, got dtype {arr.dtype}")
    if shape is not None and arr.shape != shape:
        raise ValueError(f"{name} has shape {arr.shape}, expected {shape}")
    return arr.astype(dtype, copy=False)


def _validate(f_r, wi, wo, mask, weights, dtype):
    f = np.asarray(f_r)
    if f.ndim != 3 or f.shape[-1] != 3:
        raise ValueError(f"f_r must have shape (S, N, 3) (scanlines, samples, RGB), got {f.shape}")
    shape = f.shape
    f = _as_batch("f_r", f, dtype)
    wi = _as_batch("wi", wi, dtype, shape)
    wo = _as_batch("wo", wo, dtype, shape)
    s, n, _ = shape
    w = np.ones((s, n, 1), dtype)
    if weights is not None:
        wt = np.asarray(weights)
        if wt.shape == (s, n):
            wt = wt[..., None]
        if wt.shape not in ((s, n, 1), (s, n, 3)):
            raise ValueError(f"weights must have shape (S, N) or (S, N, 3) = {(s, n)} or {shape}, got {np.shape(weights)}")
        wt = wt.astype(dtype)
        if np.any(wt < 0):
            raise ValueError("weights must be non-negative (they are 1/σ² per sample)")
        w = w * wt
    if mask is not None:
        m = np.asarray(mask)
        if m.shape == (s, n):
            m = m[..., None]
        if m.shape not in ((s, n, 1), (s, n, 3)):
            raise ValueError(f"mask must have shape (S, N) or (S, N, 3), got {np.shape(mask)}")
        w = w * m.astype(dtype)
    finite = np.isfinite(f)
    if w.shape[-1] == 1:
        w = np.where(np.all(finite, axis=-1, keepdims=True), w, 0.0)
    else:
        w = np.where(finite, w, 0.0)
    w = np.where(np.isfinite(w), w, 0.0).astype(dtype)
    f = np.where(finite, f, 0.0)
    directions_ok = np.all(np.isfinite(wi) & np.isfinite(wo), axis=-1, keepdims=True)
    wi = np.where(directions_ok, wi, np.array([0.0, 0.0, 1.0], dtype))
    wo = np.where(directions_ok, wo, np.array([0.0, 0.0, 1.0], dtype))
    w = np.where(directions_ok, w, 0.0)
    return f, wi, wo, w


def _buckets(s: int, chunk: int) -> list[tuple[int, int, int]]:
    """Split ``s`` rows into chunks of ``chunk`` rows; a short batch is padded to a power of two."""
    if s >= chunk:
        return [(i, min(i + chunk, s), chunk) for i in range(0, s, chunk)]
    return [(0, s, max(8, 1 << math.ceil(math.log2(max(s, 1)))))]


def fit_scanlines(
    f_r,
    wi,
    wo,
    model: Model = "isotropic",
    *,
    mask=None,
    weights=None,
    normalization: Normalization = "ward1992",
    solver: Solver = "fast",
    dtype=np.float64,
    chunk_size: int | None = None,
) -> ScanlineFit:
    """Fit the Ward model to each scanline of a batch, independently.

    Parameters
    ----------
    f_r
        ``(S, N, 3)`` measured BRDF values (sr⁻¹), RGB. NaN or inf samples are
        ignored.
    wi, wo
        ``(S, N, 3)`` unit directions to the light and to the camera, away
        from the surface, in the sample frame (z = normal, x = tangent).
    model
        ``"isotropic"`` (ρd RGB, ρs, α) or ``"anisotropic"`` (ρd RGB, ρs, αx, αy).
    mask
        ``(S, N)`` or ``(S, N, 3)`` booleans, True where a sample is usable.
    weights
        ``(S, N)`` or ``(S, N, 3)`` non-negative weights, ideally ``1/σ²``.
    normalization
        Ward normalisation fitted (see :mod:`wardjax.ward`).
    solver
        ``"fast"`` (default) or ``"optimistix"`` (reference; isotropic only).
    dtype
        ``float64`` (default) or ``float32`` for speed. Results are float64.
    chunk_size
        Scanlines per compiled call; default 1024 (float64) or 4096 (float32).

    Returns
    -------
    ScanlineFit
        Per-scanline parameters, standard errors, χ², dof and status. One bad
        scanline never sinks the batch: it gets its status code.
    """
    _check_choice("model", model, ("isotropic", "anisotropic"))
    _check_choice("normalization", normalization, NORMALIZATIONS)
    _check_choice("solver", solver, ("fast", "optimistix"))
    dtype = np.dtype(dtype)
    if dtype not in _CHUNK:
        raise ValueError(f"dtype must be float64 or float32, got {dtype}")
    if solver == "optimistix" and model != "isotropic":
        raise ValueError("solver='optimistix' fits the isotropic model; use res.combined() for anisotropy")
    f, wi, wo, w = _validate(f_r, wi, wo, mask, weights, dtype)
    iso = model == "isotropic"
    chunk = int(chunk_size or _CHUNK[dtype])
    s = f.shape[0]
    with jax.enable_x64(True):
        pieces = []
        for start, stop, rows in _buckets(s, chunk):
            args = [jnp.asarray(_pad(a[start:stop], rows)) for a in (f, wi, wo, w)]
            if solver == "fast":
                rtol = 0.0 if dtype == np.float64 else 64 * float(np.finfo(dtype).eps)
                out = _varpro.fit_chunk_jit(*args, iso=iso, rtol=rtol, normalization=normalization)
            else:
                out = _optimistix_chunk(*args, normalization=normalization)
            pieces.append((out, stop - start))  # dispatched asynchronously
        sol = [jax.tree_util.tree_map(lambda a, n=n: np.asarray(a)[:n], o) for o, n in pieces]
        sol = jax.tree_util.tree_map(lambda *a: np.concatenate(a).astype(np.float64), *sol)
    return _assemble(sol, f, wi, wo, w, model, normalization, solver)


def _pad(a: np.ndarray, rows: int) -> np.ndarray:
    if a.shape[0] == rows:
        return a
    pad = [(0, rows - a.shape[0])] + [(0, 0)] * (a.ndim - 1)
    return np.pad(a, pad)


def _assemble(sol, f, wi, wo, w, model, normalization, solver) -> ScanlineFit:
    alpha = sol.alpha
    ax = alpha[:, 0]
    ay = alpha[:, -1]
    var = np.diagonal(sol.cov, axis1=-2, axis2=-1)
    se = np.sqrt(np.where(var >= 0, var, np.nan))
    params = WardParams(rho_d=sol.rho_d, rho_s=sol.rho_s, alpha_x=ax, alpha_y=ay)
    stderr = WardParams(rho_d=se[:, :3], rho_s=se[:, 3], alpha_x=se[:, 4], alpha_y=se[:, -1])
    return ScanlineFit(
        params=params,
        stderr=stderr,
        covariance=sol.cov,
        chi2=sol.chi2,
        dof=sol.dof.astype(np.int64),
        status=sol.status.astype(np.int8),
        model=model,
        normalization=normalization,
        solver=solver,
        _data=(f, wi, wo, w),
    )


# --------------------------------------------------------------------------- optimistix paths


def _iso_model(y, u, v, g):
    """Model of the full isotropic problem in scaled coordinates y = (ρd RGB, log ρs, log α)."""
    rho_d, log_rs, log_a = y[:3], y[3], y[4]
    b, _ = _varpro.basis(log_a[None], u, v, g, True)
    f_model = rho_d[None, :] / jnp.pi + jnp.exp(log_rs) * b[:, None]
    return f_model


def _optimistix_scanline(f, wi, wo, w, normalization):
    """Reference fit of one scanline with optimistix's LM (same start as the fast path)."""
    geom = ward_geometry(wi, wo, normalization)
    w = jnp.where(geom.valid[:, None], w, 0.0)
    p = _varpro.prepare(f, geom.u, geom.v, geom.g, w)
    theta0 = _varpro.grid_start(p)
    st = _varpro.stats(theta0, p, True, with_jac=False)
    rho_d0 = jnp.pi * (p.fbar - st.s * jnp.broadcast_to(st.bbar, (3,)))
    y0 = jnp.concatenate([rho_d0, jnp.log(jnp.maximum(st.s, 1e-6))[None], theta0])
    sw = jnp.sqrt(jnp.broadcast_to(w, f.shape))

    def residual(y, _):
        return sw * (f - _iso_model(y, geom.u, geom.v, geom.g))

    solver = optx.LevenbergMarquardt(rtol=1e-10, atol=1e-12)
    sol = optx.least_squares(residual, solver, y0, max_steps=256, throw=False)
    y = sol.value
    r = residual(y, None)
    chi2 = jnp.sum(r * r)
    # Covariance in natural parameters (ρd, ρs, α) by the chain rule from y.
    jac = jax.jacfwd(lambda yy: residual(yy, None).reshape(-1))(y)
    scale_vec = jnp.concatenate([jnp.ones(3), jnp.exp(y[3:])])
    jac_nat = jac / scale_vec[None, :]  # ∂r/∂ρs = ∂r/∂log ρs / ρs, likewise α
    n_obs = jnp.sum(sw > 0)
    dof = n_obs - 5
    cov = jnp.linalg.inv(jac_nat.T @ jac_nat) * chi2 / jnp.maximum(dof, 1)
    ok = sol.result == optx.RESULTS.successful
    n_samples = jnp.sum(jnp.sum(w, axis=-1) > 0)
    finite = jnp.all(jnp.isfinite(y)) & jnp.isfinite(chi2)
    status = jnp.where(
        (n_samples < 4) | (dof < 1),
        Status.INSUFFICIENT_DATA,
        jnp.where(~finite, Status.NONFINITE, jnp.where(ok, Status.CONVERGED, Status.MAX_STEPS)),
    ).astype(jnp.int32)
    return _varpro.ScanlineSolution(
        y[:3], jnp.exp(y[3]), jnp.exp(y[4:5]), cov, chi2, dof, status
    )


@functools.partial(jax.jit, static_argnames="normalization")
def _optimistix_chunk(f, wi, wo, w, *, normalization):
    return jax.vmap(lambda *a: _optimistix_scanline(*a, normalization))(f, wi, wo, w)


class _JointArgs(eqx.Module):
    f: jax.Array  # (S, N, 3)
    u: jax.Array
    v: jax.Array
    g: jax.Array
    w: jax.Array  # (S, N, C)


def _joint_rho_d(log_rs, theta, a: _JointArgs, iso: bool):
    """Per-scanline profiled ρd (S, 3) and the spec basis (S, N) at given ρs, α."""
    b = jax.vmap(lambda u, v, g: _varpro.basis(theta, u, v, g, iso)[0])(a.u, a.v, a.g)  # (S, N)
    rs = jnp.exp(log_rs)
    wsum = jnp.sum(a.w, axis=1)  # (S, C)
    safe = jnp.where(wsum > 0, wsum, 1.0)
    resid_lin = a.f - rs * b[..., None]
    a_lin = jnp.sum(a.w * resid_lin, axis=1) / safe  # (S, 3)
    return a_lin, b


def _joint_residual(y, a: _JointArgs, iso: bool):
    log_rs, theta = y[0], y[1:]
    a_lin, b = _joint_rho_d(log_rs, theta, a, iso)
    r = a.f - a_lin[:, None, :] - jnp.exp(log_rs) * b[..., None]
    return jnp.sqrt(jnp.broadcast_to(a.w, a.f.shape)) * r


def _combined(res: ScanlineFit, model: str, *, max_steps: int, rtol: float) -> CombinedFit:
    iso = model == "isotropic"
    f, wi, wo, w = res._data
    # Every scanline with usable data takes part, including those whose own fit
    # saw no lobe: a scanline beside the highlight says where the lobe is *not*,
    # which is exactly what constrains αx.
    wfull = np.broadcast_to(w, f.shape)
    use = np.all(np.sum(wfull > 0, axis=1) >= 3, axis=-1) & (res.status != Status.NONFINITE)
    n_use = int(np.sum(use))
    k = 1 if iso else 2
    if n_use == 0:
        nan = WardParams(rho_d=np.full(3, np.nan), rho_s=np.nan, alpha_x=np.nan, alpha_y=np.nan)
        return CombinedFit(
            nan, nan, np.full((len(res), 3), np.nan), np.full((k + 1, k + 1), np.nan),
            float("nan"), 0, Status.INSUFFICIENT_DATA, 0, model, res.normalization,
        )
    geom = ward_geometry(wi[use], wo[use], res.normalization)
    args = _JointArgs(
        jnp.asarray(f[use], jnp.float64), geom.u, geom.v, geom.g,
        jnp.where(geom.valid[..., None], jnp.asarray(w[use], jnp.float64), 0.0),
    )
    good = res.status == Status.CONVERGED
    pick = good if np.any(good) else use
    rs0 = float(np.median(res.params.rho_s[pick]))
    a0 = float(np.median(np.sqrt(res.params.alpha_x[pick] * res.params.alpha_y[pick])))
    y0 = jnp.asarray([math.log(max(rs0, 1e-6))] + [math.log(a0)] * k, jnp.float64)
    sol = _solve_joint(y0, args, iso, max_steps, rtol)
    y = np.asarray(sol[0])
    ok = bool(sol[1])
    r = np.asarray(_joint_residual(jnp.asarray(y), args, iso))
    chi2 = float(np.sum(r * r))
    n_obs = int(np.sum(np.broadcast_to(np.asarray(args.w), args.f.shape) > 0))
    dof = n_obs - (3 * n_use + 1 + k)
    scale = chi2 / max(dof, 1)

    # Profiled covariance of the shared natural parameters (ρs, α…): the
    # residual already has every ρd projected out, so JᵀJ is the Schur complement.
    nat = np.exp(y)
    jac = np.asarray(_joint_jacobian(jnp.asarray(y), args, iso)).reshape(-1, 1 + k) / nat
    info = jac.T @ jac
    cov = np.linalg.inv(info) * scale
    se = np.sqrt(np.clip(np.diag(cov), 0, None))

    a_lin, _ = _joint_rho_d(jnp.asarray(y[0]), jnp.asarray(y[1:]), args, iso)
    rho_d_s = np.pi * np.asarray(a_lin)
    rho_d = rho_d_s.mean(axis=0)
    # σ of the mean ρd: noise in each scanline's mean, plus (ρs, α) uncertainty
    # through ∂ρd/∂(ρs, α); the two are uncorrelated (projected residual ⟂ means).
    wsum = np.sum(np.broadcast_to(np.asarray(args.w), args.f.shape), axis=1)  # (S, 3)
    noise_var = (np.pi / n_use) ** 2 * np.sum(scale / np.where(wsum > 0, wsum, np.inf), axis=0)
    grad = np.asarray(
        jax.jacfwd(lambda yy: jnp.pi * _joint_rho_d(yy[0], yy[1:], args, iso)[0].mean(0))(jnp.asarray(y))
    ) / nat  # (3, 1 + k) in natural units
    rho_d_var = noise_var + np.einsum("ip,pq,iq->i", grad, cov, grad)

    rho_d_full = np.full((len(res), 3), np.nan)
    rho_d_full[use] = rho_d_s
    ax, ay = (nat[1], nat[1]) if iso else (nat[1], nat[2])
    sx, sy = (se[1], se[1]) if iso else (se[1], se[2])
    finite = np.all(np.isfinite(y)) and np.isfinite(chi2) and np.all(np.isfinite(se))
    status = Status.CONVERGED if ok and finite else (Status.NONFINITE if not finite else Status.MAX_STEPS)
    return CombinedFit(
        params=WardParams(rho_d=rho_d, rho_s=nat[0], alpha_x=ax, alpha_y=ay),
        stderr=WardParams(rho_d=np.sqrt(rho_d_var), rho_s=se[0], alpha_x=sx, alpha_y=sy),
        rho_d_scanlines=rho_d_full,
        covariance=cov,
        chi2=chi2,
        dof=int(dof),
        status=status,
        n_scanlines=n_use,
        model=model,
        normalization=res.normalization,
    )


@eqx.filter_jit
def _solve_joint(y0, args: _JointArgs, iso: bool, max_steps: int, rtol: float):
    solver = optx.LevenbergMarquardt(rtol=rtol, atol=rtol * 1e-2)
    sol = optx.least_squares(
        lambda y, a: _joint_residual(y, a, iso), solver, y0, args=args, max_steps=max_steps, throw=False
    )
    return sol.value, sol.result == optx.RESULTS.successful


@eqx.filter_jit
def _joint_jacobian(y, args: _JointArgs, iso: bool):
    return jax.jacfwd(lambda yy: _joint_residual(yy, args, iso))(y)
