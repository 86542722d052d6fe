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

from . import _shapes, _varpro
from ._status import Status
from .ward import NORMALIZATIONS, Normalization, WardParams, ward_geometry

__all__ = ["CombinedFit", "ScanlineFit", "fit_scanlines"]

Model = Literal["isotropic", "anisotropic"]
Solver = Literal["fast", "optimistix"]

# Rows per compiled chunk: about 3–6 MB per input array. One huge batch is
# slower; measured here, 1,024 rows beat 4,096 in float32 too (14.3k vs 9.7k
# fits per CPU-second).
_CHUNK = {np.dtype(np.float64): 1024, np.dtype(np.float32): 1024}


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
        self,
        model: Model | None = None,
        *,
        errors: Literal["robust", "model"] = "robust",
        max_steps: int = 256,
        rtol: float = 1e-10,
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
        errors
            ``"robust"`` (default): the sandwich covariance clustered by
            scanline, ``A⁻¹ (Σ_s g_s g_sᵀ · S/(S−1)) A⁻¹`` with ``A = JᵀJ`` and
            ``g_s = J_sᵀ r_s`` the score of scanline ``s``. It stays honest when
            the residuals are correlated along a scanline — an unmodelled ρd
            texture, a slightly wrong lobe shape — where the model-based
            ``A⁻¹ χ²/dof`` assumes independent noise and can be many times too
            small. With fewer than 10 scanlines it falls back to ``"model"``.
            It still assumes scanlines independent: a texture correlated
            *across* neighbouring scanlines (a camera image's columns) that the
            fit partly absorbs into (ρs, α) leaves no trace in the residuals,
            and both covariances then understate the error (5–7× on the
            simulated marble); :func:`wardjax.pipeline.texture_field_covariance`
            accounts for it, and :func:`wardjax.fit_capture` reports that.
            ``"model"``: the Gauss–Newton covariance scaled by χ²/dof.
        """
        model = model or self.model
        _check_choice("model", model, ("isotropic", "anisotropic"))
        _check_choice("errors", errors, ("robust", "model"))
        with jax.enable_x64(True):
            return _combined(self, model, errors=errors, max_steps=max_steps, rtol=rtol)


# --------------------------------------------------------------------------- boundary


def _check_choice(name, value, allowed):
    if value not in allowed:
        raise ValueError(f"{name}={value!r} is not one of {', '.join(map(repr, allowed))}")


def _as_batch(name: str, x, shape: tuple[int, ...] | None = None) -> np.ndarray:
    arr = np.asarray(x)
    if arr.dtype == object or not (np.issubdtype(arr.dtype, np.number) or arr.dtype == bool):
        raise TypeError(f"{name} must be a numeric array, got dtype {arr.dtype}")
    if shape is not None and arr.shape != shape:
        raise ValueError(f"{name} has shape {arr.shape}, expected {shape}")
    return arr


def _validate(f_r, wi, wo, mask, weights):
    """Check shapes and types at the boundary (cheap); cleaning happens inside the kernel."""
    f = np.asarray(f_r)
    if f.ndim != 3 or f.shape[-1] != 3:
        raise ValueError(f"f_r must have shape (S, N, 3) (scanlines, samples, RGB), got {f.shape}")
    shape = f.shape
    f = _as_batch("f_r", f)
    wi = _as_batch("wi", wi, shape)
    wo = _as_batch("wo", wo, shape)
    s, n, _ = shape
    if weights is not None:
        wt = _as_batch("weights", weights)
        if wt.shape == (s, n):
            wt = wt[..., None]
        if wt.shape not in ((s, n, 1), (s, n, 3)):
            raise ValueError(
                f"weights must have shape (S, N) or (S, N, 3) = {(s, n)} or {shape}, got {np.shape(weights)}"
            )
        if np.any(wt < 0):
            raise ValueError("weights must be non-negative (they are 1/σ² per sample)")
        weights = wt
    if mask is not None:
        m = np.asarray(mask)
        if m.shape == (s, n):
            m = m[..., None]
        if m.shape not in ((s, n, 1), (s, n, 3)):
            raise ValueError(f"mask must have shape (S, N) or (S, N, 3), got {np.shape(mask)}")
        mask = m.astype(bool, copy=False)
    return f, wi, wo, mask, weights


def _clean(f, wi, wo, mask, weights, dtype):
    """Inside the jit: cast, zero the weight of unusable samples, make their values finite.

    A sample (or, with per-channel weights or mask, a value) is unusable when
    it is masked, non-finite, or has a non-finite direction. Returns
    ``(f, wi, wo, w)`` with ``w`` of shape ``(S, N, C)``.
    """
    f, wi, wo = (jnp.asarray(a, dtype) for a in (f, wi, wo))
    c = max(1 if weights is None else weights.shape[-1], 1 if mask is None else mask.shape[-1])
    w = jnp.ones(f.shape[:2] + (c,), dtype)
    if weights is not None:
        w = w * jnp.asarray(weights, dtype)
    if mask is not None:
        w = jnp.where(mask, w, 0.0)
    finite = jnp.isfinite(f)
    fin = jnp.all(finite, axis=-1, keepdims=True) if c == 1 else finite
    dirs_ok = jnp.all(jnp.isfinite(wi) & jnp.isfinite(wo), axis=-1, keepdims=True)
    w = jnp.where(fin & dirs_ok & jnp.isfinite(w), w, 0.0)
    up = jnp.asarray([0.0, 0.0, 1.0], dtype)[None, None, :]
    return jnp.where(finite, f, 0.0), jnp.where(dirs_ok, wi, up), jnp.where(dirs_ok, wo, up), w


# The fast path is compiled as separate stages. Stage A cleans the inputs and
# builds each scanline's geometry, then its moment matrices; stage B runs the
# search on them. Compiled as one program, XLA:CPU lays out and fuses the moments so
# that every evaluation of the search costs ~5× more (measured: 1.5 vs 6–10 ms
# CPU per evaluation of 1,024 scanlines); materialising them between two
# programs keeps each evaluation a plain exp plus two small mat-vecs.


@functools.partial(jax.jit, static_argnames=("normalization", "dtype"))
def _geometry_chunk(f, wi, wo, mask, weights, *, normalization, dtype):
    f, wi, wo, w = _clean(f, wi, wo, mask, weights, dtype)
    geom = ward_geometry(wi, wo, normalization)
    w = jnp.where(geom.valid[..., None], w, 0.0)
    # Sample axis last for the kernel: the transposes fuse into this pass.
    return jnp.swapaxes(f, -1, -2), geom.u, geom.v, geom.g, jnp.swapaxes(w, -1, -2)


@functools.partial(jax.jit, static_argnames=("iso",))
def _moments_chunk(f, u, v, g, w, n, *, iso):
    """:func:`~wardjax._varpro.prepare` of each scanline; ``n`` (traced) samples are data, the rest padding."""
    return jax.vmap(lambda *a: _varpro.prepare(*a, iso, n))(f, u, v, g, w)


@functools.partial(jax.jit, static_argnames=("iso", "rtol"))
def _search_chunk(prepared, *, iso, rtol):
    return jax.vmap(lambda p: _varpro.solve_scanline(p, iso=iso, rtol=rtol))(prepared)


def _fast_chunk(f, wi, wo, mask, weights, n, *, iso, rtol, normalization, dtype):
    # Geometry and moments as separate programs too: ~25 % less CPU than one.
    parts = _geometry_chunk(f, wi, wo, mask, weights, normalization=normalization, dtype=dtype)
    return _search_chunk(_moments_chunk(*parts, n, iso=iso), iso=iso, rtol=rtol)


@functools.partial(jax.jit, static_argnames=("dtype",))
def _clean_jit(f, wi, wo, mask, weights, *, dtype):
    return _clean(f, wi, wo, mask, weights, dtype)


def _bucket_rows(s: int, chunk: int) -> int:
    """Rows a batch of ``s`` is padded to: 64, 256, 1024, … (×4), at most ``chunk``.

    Coarse buckets keep the number of compiled shapes small (each costs
    seconds); the padded rows have zero weight and cost little.
    """
    rows = 64
    while rows < s and rows < chunk:
        rows *= 4
    return min(rows, chunk)


def _buckets(s: int, chunk: int) -> list[tuple[int, int, int]]:
    """Split ``s`` rows into chunks of ``chunk`` rows; a short batch is padded to a bucket size."""
    if s >= chunk:
        return [(i, min(i + chunk, s), chunk) for i in range(0, s, chunk)]
    return [(0, s, _bucket_rows(s, chunk))]


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
        ``float64`` (default) or ``float32`` for speed (about twice the
        rate on float32 inputs). Results are float64; scanlines whose
        float32 fit is not certified (``max_steps``, ``nonfinite``) are
        fitted again in float64, so float32 loses no accuracy.
    chunk_size
        Scanlines per compiled call; default 1024.

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
    f, wi, wo, mask, weights = _validate(f_r, wi, wo, mask, weights)
    iso = model == "isotropic"
    chunk = int(chunk_size or _CHUNK[dtype])
    data = (f, wi, wo, mask, weights)
    sol = _solve(data, iso=iso, normalization=normalization, solver=solver, dtype=dtype, chunk=chunk)
    if dtype == np.float32 and solver == "fast":
        # A float32 fit that is not certified (rounding can cancel the
        # algebraic centring into a spurious optimum: ~3 in 10⁴ scanlines with
        # broad lobes) is fitted again in float64.
        redo = np.flatnonzero(np.isin(sol.status, (Status.MAX_STEPS, Status.NONFINITE)))
        if redo.size:
            sub = tuple(None if a is None else a[redo] for a in data)
            again = _solve(sub, iso=iso, normalization=normalization, solver=solver, dtype=np.dtype(np.float64),
                           chunk=_CHUNK[np.dtype(np.float64)])
            for full, part in zip(sol, again):
                full[redo] = part
    return _assemble(sol, data, model, normalization, solver)


# What a padded sample of each input of ``data = (f, wi, wo, mask, weights)`` holds: unusable, weight 0.
_SAMPLE_FILL = (np.nan, np.nan, np.nan, False, 0.0)


def _pad_samples(data, n: int):
    """``data`` with the sample axis padded to ``n`` by unusable samples (zero weight after :func:`_clean`)."""
    return tuple(None if a is None else _shapes.pad_to_shape(a, a.shape[:1] + (n,), fill)
                 for a, fill in zip(data, _SAMPLE_FILL))


def _solve(data, *, iso, normalization, solver, dtype, chunk) -> _varpro.ScanlineSolution:
    """Run the kernel over ``data = (f, wi, wo, mask, weights)`` in chunks; float64 NumPy results.

    The fast kernel sees the samples padded to :func:`~wardjax._shapes.bucket`
    of their number (zero weight, the true count passed as data), so batches
    whose scanlines differ a little in length share one compiled program.
    """
    rtol = 0.0 if dtype == np.float64 else 64 * float(np.finfo(dtype).eps)
    n_true = data[0].shape[1]
    if solver == "fast":
        data = _pad_samples(data, _shapes.bucket(n_true))
    with jax.enable_x64(True):
        # Padded: the true count as data (one program per bucket). Not padded: None, the static
        # grid slice, which is tighter than the padded gather (64 grid samples, not 128, at N = 256:
        # ~30 % faster in float32).
        n = None if data[0].shape[1] == n_true else jnp.asarray(n_true, jnp.int32)
        pieces = []
        for start, stop, rows in _buckets(data[0].shape[0], chunk):
            args = [None if a is None else jax.device_put(_pad(a[start:stop], rows)) for a in data]
            if solver == "fast":
                out = _fast_chunk(*args, n, iso=iso, rtol=rtol, normalization=normalization, dtype=dtype)
            else:
                out = _optimistix_chunk(*_clean(*args, dtype), normalization=normalization)
            pieces.append((out, stop - start))  # dispatched asynchronously
        sol = [jax.tree_util.tree_map(lambda a, n=n: np.asarray(a)[:n], o) for o, n in pieces]
        return jax.tree_util.tree_map(lambda *a: np.concatenate(a).astype(np.float64), *sol)


def _pad(a: np.ndarray, rows: int) -> np.ndarray:
    if a.shape[0] == rows:
        return a
    pad = [(0, rows - a.shape[0])] + [(0, 0)] * (a.ndim - 1)
    return np.pad(a, pad)


def _assemble(sol, data, model, normalization, solver) -> ScanlineFit:
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
        _data=data,
    )


# --------------------------------------------------------------------------- optimistix paths


def _iso_model(y, u, v, g):
    """Model of the full isotropic problem in scaled coordinates y = (ρd RGB, log ρs, log α)."""
    rho_d, log_rs, log_a = y[:3], y[3], y[4]
    b = _varpro.basis(log_a[None], u, v, g, True)
    f_model = rho_d[None, :] / jnp.pi + jnp.exp(log_rs) * b[:, None]
    return f_model


def _optimistix_scanline(f, wi, wo, w, normalization):
    """Reference fit of one scanline with optimistix's LM (same start as the fast path)."""
    geom = ward_geometry(wi, wo, normalization)
    w = jnp.where(geom.valid[:, None], w, 0.0)
    p = _varpro.prepare(f.T, geom.u, geom.v, geom.g, w.T)
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
    :func:`_moments_chunk` of the same data, sample axis last, for the
    normalisation ``NORMALIZATIONS[norm_index]`` (traced: a capture's fit and
    its export refit in another normalisation share the program). One
    program: run eagerly, these few dozen small operations would each compile
    once per shape bucket.
    """
    geoms = [ward_geometry(wi, wo, n) for n in NORMALIZATIONS]  # u, v, valid are common; only g differs
    g = jnp.select([norm_index == i for i in range(len(geoms))], [geom.g for geom in geoms])
    geom = geoms[0]
    args = _JointArgs(f, geom.u, geom.v, g, jnp.where(geom.valid[..., None], w, 0.0))
    # Start: the best of a log-α grid of the joint profiled χ² (for fixed α the
    # joint model is linear in every ρd and the shared ρs), not the per-scanline
    # fits, which a strong texture can spoil.
    prepared = _moments_chunk(jnp.swapaxes(args.f, -1, -2), args.u, args.v, args.g, jnp.swapaxes(args.w, -1, -2),
                              n_samples, iso=True)
    return args, prepared


def _joint_residual(y, a: _JointArgs, iso: bool):
    log_rs, theta = y[0], y[1:]
    a_lin, b = _joint_rho_d(log_rs, theta, a, iso)
    r = a.f - a_lin[:, None, :] - jnp.exp(log_rs) * b[..., None]
    return jnp.sqrt(jnp.broadcast_to(a.w, a.f.shape)) * r


def _combined(res: ScanlineFit, model: str, *, errors: str, max_steps: int, rtol: float) -> CombinedFit:
    iso = model == "isotropic"
    k = 1 if iso else 2
    # Cleaned with both axes padded to bucket sizes (padded samples unusable), so that batches of
    # slightly different shapes share every compiled program below.
    s_true, n_true = res._data[0].shape[:2]
    data = [None if a is None else _shapes.pad_to_shape(a, (_shapes.bucket(s_true),), fill)
            for a, fill in zip(_pad_samples(res._data, _shapes.bucket(n_true)), _SAMPLE_FILL)]
    f_c, wi_c, wo_c, w_c = (np.asarray(a)[:s_true] for a in _clean_jit(
        *(None if a is None else jnp.asarray(a) for a in data), dtype=np.dtype(np.float64)))
    # Every scanline with usable data takes part, including those whose own fit
    # saw no lobe: a scanline beside the highlight says where the lobe is *not*,
    # which is exactly what constrains αx.
    wfull = np.broadcast_to(w_c, f_c.shape)
    use = np.all(np.sum(wfull > 0, axis=1) >= 3, axis=-1) & (res.status != Status.NONFINITE)
    n_use = int(np.sum(use))
    if n_use == 0:
        nan = WardParams(rho_d=np.full(3, np.nan), rho_s=np.nan, alpha_x=np.nan, alpha_y=np.nan)
        return CombinedFit(
            nan, nan, np.full((len(res), 3), np.nan), np.full((k + 1, k + 1), np.nan),
            float("nan"), 0, Status.INSUFFICIENT_DATA, 0, model, res.normalization,
        )
    # Pad the scanline axis to a bucket size with zero-weight rows: one compile per bucket.
    rows = _bucket_rows(n_use, 1 << 30)
    sel = [np.asarray(a)[use] for a in (f_c, wi_c, wo_c, w_c)]
    f_p, wi_p, wo_p, w_p = (_pad(a, rows) for a in sel)
    wi_p[n_use:, :, 2] = wo_p[n_use:, :, 2] = 1.0  # padded rows: straight up, weight 0
    args, prepared = _joint_prepare(f_p, wi_p, wo_p, w_p, np.int32(n_true),
                                    np.int32(NORMALIZATIONS.index(res.normalization)))
    log_a, rs0 = (float(v) for v in _joint_grid_start(prepared))
    y = jnp.asarray([math.log(max(rs0, 1e-6))] + [log_a] * k, jnp.float64)
    n_obs = int(np.sum(np.broadcast_to(np.asarray(args.w), args.f.shape) > 0))
    dof = n_obs - (3 * n_use + 1 + k)
    # optimistix's LM stops on small steps, which a large damping can also
    # produce: certify the optimum with the Gauss–Newton step and restart
    # (resetting the damping) until it is below 1e-3 σ.
    certified = False
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
    wsum = np.sum(np.broadcast_to(np.asarray(args.w), args.f.shape), axis=1)[:n_use]  # (S, 3)
    noise_var = (np.pi / n_use) ** 2 * np.sum(scale / np.where(wsum > 0, wsum, np.inf), axis=0)
    grad = np.asarray(_joint_rho_d_mean_grad(jnp.asarray(y), args, iso, jnp.asarray(n_use))) / nat[None, :]
    rho_d_var = noise_var + np.einsum("ip,pq,iq->i", grad, cov, grad)

    rho_d_full = np.full((len(res), 3), np.nan)
    rho_d_full[use] = rho_d_s
    ax, ay = (nat[1], nat[1]) if iso else (nat[1], nat[2])
    sx, sy = (se[1], se[1]) if iso else (se[1], se[2])
    finite = np.all(np.isfinite(y)) and np.isfinite(chi2) and np.all(np.isfinite(se))
    status = Status.NONFINITE if not finite else (Status.CONVERGED if certified else Status.MAX_STEPS)
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
        covariance_model=cov_model,
        covariance_robust=cov_robust,
        errors=used,
    )


_JOINT_GRID = np.linspace(math.log(2e-3), math.log(1.0), 24)


@jax.jit
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
