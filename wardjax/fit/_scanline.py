"""Batched Levenberg–Marquardt fits of the Ward model to scanlines of BRDF samples.

Two solvers, one problem (weighted least squares of ``f_r`` against the Ward
model, section 3 of the image-based paper):

``solver="fast"`` (default)
    A fixed-iteration LM on the variable-projection reduction written in JAX
    (:mod:`wardjax.fit._varpro`): ρd and ρs are solved in closed form, only the
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

Uncertainties with weights are ``√diag((JᵀWJ)⁻¹ · χ²/dof)``: the Gauss–Newton
covariance at the solution scaled by the residual variance (with ``weights = 1/σ²``
from a correct noise model χ²/dof ≈ 1 and the scaling is harmless). Without
weights the noise may grow with the signal, and the default reports the sandwich
covariance ``(JᵀJ)⁻¹ (Σ r² JᵢᵀJᵢ) (JᵀJ)⁻¹`` instead (White 1980; with few samples per fit,
MacKinnon & White's 1985 leverage correction HC3, ``r²/(1−h)²``). Where χ² is not
quadratic over one standard error, profile-likelihood errors replace either.

Fits run in float64 inside a scoped ``jax.enable_x64(True)``: importing or
calling wardjax never changes the caller's global JAX settings.
"""

from __future__ import annotations

import dataclasses
import functools
from typing import Any, Literal, cast

import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx

from .. import _shapes
from .._status import Status
from ..ward import NORMALIZATIONS, WardParams, ward_geometry
from . import _feed, _profile, _varpro
from ._data import (
    SMALL_SAMPLES,
    buckets,
    check_choice,
    check_sign,
    clean,
    kernel,
    moments_chunk,
    negative_flag,
    pad_rows,
    pad_samples,
    validate,
)
from ._joint import CombinedFit, combined

__all__ = ["ScanlineFit", "fit_scanlines"]

Model = Literal["isotropic", "anisotropic"]

# Rows per compiled chunk on a CPU where the sample count is not given (the float64 refits, the profiles' pass).
_CHUNK = {np.dtype(np.float64): 1024, np.dtype(np.float32): 1024}
# Samples per chunk on a CPU: the search's streams of a chunk then stay in the cores' caches through its
# steps. Two cores, 8,192 scanlines of 256 samples, fits/s with the defaults (Gauss–Newton): 256 rows
# 73k (84k), 1,024 rows 56k (65k); weighted 54k (55k) against 52k (45k); float32 131k (139k) against
# 80k (104k). Few samples per row take more rows, at most 4,096: each call costs the host a fixed
# ~0.4 ms (dispatch, fetch) that 1,024 rows of 9 samples hardly outweigh; at least 64.
_CHUNK_SAMPLES = 65_536
_ACCELERATOR_CHUNK = 131_072  # per device, on a GPU with ≥ 32 GB (see _default_chunk)
# Small problems (a pixel seen in a few photographs): compiled for their exact sample count.
TINY = 16


# --------------------------------------------------------------------------- results


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
    errors
        ``(S,)`` which standard errors each fit reports: ``"gauss_newton"`` (the
        scaled inverse curvature), ``"sandwich"`` (heteroscedasticity-consistent, for
        fits without weights) or ``"profile"`` (half-widths of the 68 %
        profile-likelihood intervals of ρs and α, where the curvature check failed;
        for unweighted fits rescaled by the sandwich's ratio to Gauss–Newton;
        ``covariance`` is rescaled to match, correlations kept).
    """

    params: WardParams
    stderr: WardParams
    covariance: np.ndarray
    chi2: np.ndarray
    dof: np.ndarray
    status: np.ndarray
    model: Model
    normalization: str
    solver: str
    _data: tuple = dataclasses.field(repr=False)
    errors: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros(0, "<U12"))

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
        model: str | None = None,
        *,
        errors: str = "robust",
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
            simulated marble); :func:`wardjax.fit.texture_field_covariance`
            accounts for it, and :func:`wardjax.fit_capture` reports that.
            ``"model"``: the Gauss–Newton covariance scaled by χ²/dof.
        """
        model = model or self.model
        check_choice("model", model, ("isotropic", "anisotropic"))
        check_choice("errors", errors, ("robust", "model"))
        with jax.enable_x64(True):
            return combined(
                self._data, self.status, self.normalization, model, errors=errors, max_steps=max_steps, rtol=rtol
            )


@functools.partial(jax.jit, static_argnames=("normalization", "dtype"))
def _geometry_chunk(f, wi, wo, mask, weights, *, normalization, dtype):
    f, wi, wo, w = clean(f, wi, wo, mask, weights, dtype)
    geom = ward_geometry(wi, wo, normalization)
    w = jnp.where(geom.valid[..., None], w, 0.0)
    # Sample axis last for the kernel: the transposes fuse into this pass.
    return jnp.swapaxes(f, -1, -2), geom.u, geom.v, geom.g, jnp.swapaxes(w, -1, -2)


@kernel(static_argnames=("iso", "rtol", "check", "steps", "lanes"))
def _search_chunk(prepared, raw=None, *, iso, rtol, check, steps=None, lanes=0):
    """The search of each prepared scanline; with ``raw`` (the geometry stage's arrays) the sandwich
    covariance too, in the same program (a separate pass cost a third more CPU than the fold); with
    ``lanes`` the profile errors of up to that many rows that fail the curvature check, in the same program too
    (:func:`~wardjax.fit._profile.profile_flagged`)."""
    fit = lambda p, r: _varpro.solve_scanline(p, iso=iso, rtol=rtol, check=check, steps=steps, raw=r)
    sol = jax.vmap(fit)(prepared, raw)
    return _profile.profile_flagged(prepared, sol, lanes) if lanes else sol


def _profile_lanes(rows: int, n_pad: int) -> int:
    """Rows of a chunk of ``rows`` its search program profiles: 1/16 (1/8 for small problems, where more
    fits fail the curvature check: about 9 % at 9 samples, 1–3 % at 256)."""
    return max(rows // (8 if n_pad <= TINY else 16), 1)


def _fast_chunk(
    f, wi, wo, mask, weights, n, *, iso, rtol, normalization, dtype, check, sandwich, steps=None, lanes=0, small=False
):
    """One chunk through the three compiled stages; ``small``: the programs for few samples on a CPU
    (:func:`_small_programs`)."""
    # Geometry and moments as separate programs too: ~25 % less CPU than one.
    parts = _geometry_chunk(f, wi, wo, mask, weights, normalization=normalization, dtype=dtype)
    prepared = moments_chunk.pick(small)(*parts, n, iso=iso)
    raw = parts if sandwich else None
    return _search_chunk.pick(small)(prepared, raw, iso=iso, rtol=rtol, check=check, steps=steps, lanes=lanes)


def _small_programs(n_pad: int, devices) -> bool:
    """Whether problems of ``n_pad`` (padded) samples take the programs compiled for few samples: on a
    CPU, up to :data:`~wardjax.fit._data.SMALL_SAMPLES` (see :class:`~wardjax.fit._data.Kernel`)."""
    return n_pad <= SMALL_SAMPLES and devices[0].platform == "cpu"


def _steps(max_steps) -> int | None:
    """``max_steps`` checked at the boundary: ``None`` (the kernel's default) or a positive integer."""
    if max_steps is not None and not (isinstance(max_steps, int | np.integer) and max_steps >= 1):
        raise ValueError(f"max_steps must be a positive integer, got {max_steps!r}")
    return None if max_steps is None else int(max_steps)


def fit_scanlines(
    f_r,
    wi,
    wo,
    model: str = "isotropic",
    *,
    mask=None,
    weights=None,
    normalization: str = "ward1992",
    solver: str = "fast",
    dtype=np.float64,
    chunk_size: int | None = None,
    devices=None,
    errors: str = "auto",
    max_steps: int | None = None,
) -> ScanlineFit:
    """Fit the Ward model to each scanline of a batch, independently.

    Parameters
    ----------
    f_r
        ``(S, N, 3)`` measured BRDF values (sr⁻¹), RGB. NaN or inf samples are
        ignored. Every array may be NumPy or a :class:`jax.Array`; a
        ``jax.Array`` is fitted on its device without a copy through the host
        (on one H200, 10⁶ scanlines already on the GPU fit at 1.9–2.7 M/s in
        float32; from host memory the copy bounds the rate: see the benchmarks page).
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
        float32 fit is not certified (any status but ``converged``) are
        fitted again in float64, so float32 loses no accuracy.
    chunk_size
        Scanlines per compiled call and device; default on a CPU about 65,536 samples' worth (256
        scanlines of 256 samples; 4,096 of up to 16 samples), 131,072 on an accelerator with ≥ 32 GB
        of memory (32,768 on a smaller one).
    devices
        JAX devices to spread each call's scanlines over (``NamedSharding``
        over a 1-D mesh, scanline axis); default ``jax.devices()``. Scanlines
        are independent, so the results do not depend on the devices.
    errors
        Standard errors (fast solver): ``"auto"`` (default) reports Gauss–Newton ones with weights and the sandwich
        (heteroscedasticity-consistent) ones without, and for isotropic fits the profile-likelihood ones of ρs and α
        where the curvature check fails (χ² one standard error away off a quadratic's rise by over 20 %);
        ``"gauss_newton"``: Gauss–Newton only (the fastest); ``"profile"``: every converged isotropic fit profiled.
        :attr:`ScanlineFit.errors` says which each fit reports.
    max_steps
        LM steps after the grid start (fast solver; default 4, anisotropic 8 more). A scanline still moving at the
        limit gets status ``max_steps``: its parameters are the best point found, not certified a minimum.

    Notes
    -----
    Precision rule: on a GPU, ``dtype=float32`` is the fast path where the
    tests show it accurate enough (it is: every float32 fit that is not
    certified is redone in float64, and the results then equal float64's to
    1e-12 in the tests); certification is always float64's. The default stays
    float64.

    Returns
    -------
    ScanlineFit
        Per-scanline parameters, standard errors, χ², dof and status. One bad
        scanline never sinks the batch: it gets its status code.
    """
    check_choice("model", model, ("isotropic", "anisotropic"))
    check_choice("normalization", normalization, NORMALIZATIONS)
    check_choice("solver", solver, ("fast", "optimistix"))
    check_choice("errors", errors, ("auto", "gauss_newton", "profile"))
    dtype = np.dtype(dtype)
    if dtype not in _CHUNK:
        raise ValueError(f"dtype must be float64 or float32, got {dtype}")
    if solver == "optimistix" and model != "isotropic":
        raise ValueError("solver='optimistix' fits the isotropic model; use res.combined() for anisotropy")
    devices = _check_devices(devices)
    # Host memory feeding an accelerator: the chunks cross in worker threads, and the weights' sign is
    # checked on the device, chunk by chunk (decided once, here, for every pass below).
    host_fed = _feed.host_fed((f_r, wi, wo, mask, weights), devices)
    f, wi, wo, mask, weights = validate(f_r, wi, wo, mask, weights, sign_later=host_fed)
    iso = model == "isotropic"
    n_pad = _sample_bucket(f.shape[1]) if solver == "fast" else None
    chunk = int(chunk_size or _default_chunk(dtype, devices, n_pad))
    data = (f, wi, wo, mask, weights)
    kw: dict[str, Any] = dict(
        iso=iso,
        normalization=normalization,
        solver=solver,
        devices=devices,
        every_gn=errors == "profile",
        host_fed=host_fed,
    )
    check = errors == "auto"
    # Without weights the residual variance is unknown and may follow the signal: the sandwich.
    sandwich = weights is None and errors != "gauss_newton" and solver == "fast"
    kw.update(check=check, sandwich=sandwich, steps=_steps(max_steps))
    sol = _solve(data, dtype=dtype, chunk=chunk, **kw)
    if dtype == np.float32 and solver == "fast":
        sol = _refit_uncertified(sol, data, **kw)  # the same step cap: float64's result, not a longer fit
    if solver == "fast" and iso and errors != "gauss_newton":
        if errors == "profile":
            sol.nonlinear[sol.status == Status.CONVERGED] = _profile.PENDING
        _profile_where_nonlinear(sol, data, normalization=normalization, devices=devices)
    else:
        sol.nonlinear[:] = 0
    return _assemble(sol, data, model, normalization, solver, sandwich)


# What a padded sample of each input of ``data = (f, wi, wo, mask, weights)`` holds: unusable, weight 0.


def _refit_uncertified(sol: _varpro.ScanlineSolution, data, *, devices, **kw) -> _varpro.ScanlineSolution:
    """``sol`` with the float32 fits that are not certified fitted again in float64 (in place).

    Rounding can cancel the algebraic centring into a spurious optimum (~3 in 10⁴ scanlines with
    broad lobes), which float32 does not certify but may report as any other outcome (``max_steps``,
    ``nonfinite``, and ``insufficient_data`` where its sums are reassociated or fused otherwise): every
    row whose status is not ``converged`` takes float64's results, profiled or pending alike.
    """
    redo = np.flatnonzero(sol.status != Status.CONVERGED)
    if redo.size:
        if not np.asarray(sol.cov_gn).flags.writeable:  # no row was pending (see _to_host): now some may be
            sol = sol._replace(cov_gn=np.array(sol.cov_gn))
        sub = tuple(None if a is None else a[redo] for a in data)
        f64 = np.dtype(np.float64)
        again = _solve(sub, dtype=f64, chunk=_default_chunk(f64, devices), devices=devices, **kw)
        for full, part in zip(sol, again):
            full[redo] = part
    return sol


def _check_devices(devices) -> list:
    devices = list(jax.devices() if devices is None else devices)
    if not devices or not all(isinstance(d, jax.Device) for d in devices):
        raise ValueError(f"devices={devices!r}, expected a non-empty sequence of jax.Device")
    return devices


def _default_chunk(dtype, devices, n_pad: int | None = None) -> int:
    """Rows per call and device: on a CPU :data:`_CHUNK_SAMPLES` samples' worth of rows of ``n_pad``
    (padded) samples, between 64 and 4,096 (256 rows of 256 samples, 4,096 rows up to 16 samples;
    1,024 where ``n_pad`` is not given); on an accelerator 131,072 where it has
    ≥ 32 GB (one call then holds ~5 GB in float64), else 32,768. Measured on an H200 with 10⁶ scanlines on
    the device: 131,072 rows gave 2.58 M fits/s in float64 against 1.96 M at 32,768 (3.75 vs 2.92 M in
    float32). On two CPU cores, 10⁵ problems of 9 samples (``errors="auto"``): 1,024 rows 2.49 µs
    per fit (wall), 2,048 rows 1.80, 4,096 rows 1.56, 8,192 rows 1.54; the host thread's CPU 1.18 →
    0.42 µs per fit from 1,024 to 4,096 rows.
    """
    device = devices[0]
    if device.platform == "cpu":
        if not n_pad:
            return _CHUNK[np.dtype(dtype)]
        return min(4096, max(64, _CHUNK_SAMPLES // n_pad))
    limit = (device.memory_stats() or {}).get("bytes_limit", 0)
    return _ACCELERATOR_CHUNK if limit >= 32 << 30 else _ACCELERATOR_CHUNK // 4


def _placement(devices, direct: bool = True):
    """How a chunk's rows are put on the devices: split along the scanline axis over a 1-D mesh.

    Returns a function of one array. On the default device alone it returns NumPy arrays as they
    are: the compiled call copies them itself, where ``device_put`` with a sharding costs about
    3 ms of host time per array (the whole cost of a chunk of small problems). ``direct=False``:
    always ``device_put`` (the profiles' few chunks, whose host-side inputs then stay visible).
    """
    if direct and len(devices) == 1 and devices[0] == jax.devices()[0]:
        return lambda a: a
    mesh = jax.sharding.Mesh(np.asarray(devices), ("scanline",))
    sharding = jax.sharding.NamedSharding(mesh, jax.sharding.PartitionSpec("scanline"))
    return lambda a: jax.device_put(a, sharding)


def _sample_bucket(n: int) -> int:
    """Samples the fast kernel is compiled for: :func:`~wardjax._shapes.bucket` of ``n``, or ``n`` itself
    up to :data:`TINY` samples, where padding would double the work (9 → 16) and each count compiles
    once (a program per count from 1 to 16 at most)."""
    return n if n <= TINY else _shapes.bucket(n)


def _solve(
    data,
    *,
    iso,
    normalization,
    solver,
    dtype,
    chunk,
    devices=None,
    check=True,
    sandwich=False,
    steps=None,
    every_gn=False,
    host_fed=False,
) -> _varpro.ScanlineSolution:
    """Run the kernel over ``data = (f, wi, wo, mask, weights)`` in chunks; float64 NumPy results.

    The fast kernel sees the samples padded to :func:`~wardjax._shapes.bucket`
    of their number (zero weight, the true count passed as data), so batches
    whose scanlines differ a little in length share one compiled program.
    Each call holds ``chunk`` rows per device, split over ``devices``
    (default ``jax.devices()``) along the scanline axis. ``every_gn``: Gauss–Newton's
    covariance of every row is wanted on the host (see :func:`_to_host`). ``host_fed``
    (:func:`~wardjax.fit._feed.host_fed` of the caller's data): the chunks cross from host memory
    in worker threads and NumPy weights' sign is checked on the device.
    """
    devices = _check_devices(devices)
    put = _placement(devices, direct=not host_fed)
    chunk *= len(devices)
    rtol = 0.0 if dtype == np.float64 else 64 * float(np.finfo(dtype).eps)
    n_rows, n_true = data[0].shape[0], data[0].shape[1]
    n_pad = _sample_bucket(n_true) if solver == "fast" else n_true
    if solver == "fast":
        data = pad_samples(data, n_pad)  # the sample axis only
    with jax.enable_x64(True):
        # Padded: the true count as data (one program per bucket). Not padded: None, the static
        # grid slice, which is tighter than the padded gather (64 grid samples, not 128, at N = 256:
        # ~30 % faster in float32).
        n = None if n_pad == n_true else jnp.asarray(n_true, jnp.int32)
        # The profiles in the search program: float64 only (a float32 profile's χ² rises round too coarsely).
        profile_here = check and iso and solver == "fast" and dtype == np.float64
        pieces = []
        # Whole rows on every device.
        spans = [(a, b, -(-rows // len(devices)) * len(devices)) for a, b, rows in buckets(n_rows, chunk)]
        small = solver == "fast" and _small_programs(n_pad, devices)
        signs = []
        streams = _feed.streams(devices)  # on a CPU, chunks on all cores at once
        chunks = _feed.chunks(data, spans, put, threaded=host_fed)
        for i, ((start, stop, rows), args) in enumerate(zip(spans, chunks)):
            if host_fed and args[4] is not None:
                signs.append(negative_flag(args[4]))  # validate left host weights' sign to the device
            with _feed.stream(i, streams):
                if solver == "fast":
                    out = _fast_chunk(
                        *args,
                        n=n,
                        iso=iso,
                        rtol=rtol,
                        normalization=normalization,
                        dtype=dtype,
                        check=check,
                        sandwich=sandwich,
                        steps=steps,
                        lanes=_profile_lanes(rows, n_pad) if profile_here else 0,
                        small=small,
                    )
                else:
                    out = _optimistix_chunk(*clean(*args, dtype=dtype), normalization=normalization)
            pieces.append((out, start, stop))  # dispatched asynchronously
        check_sign(signs)
        local = devices[0].platform == "cpu" and not host_fed  # results in host memory already
        return _to_host(pieces, n_rows, sandwich=sandwich and solver == "fast", every_gn=every_gn, local=local)


def _to_host(
    pieces, n_rows: int, *, sandwich: bool, every_gn: bool = False, local: bool = False
) -> _varpro.ScanlineSolution:
    """The chunks' results as float64 NumPy arrays of ``n_rows`` rows, each value copied once into place.

    Without the sandwich ``cov_gn`` is ``cov`` (the same array). With it, Gauss–Newton's covariance
    crosses to the host only for the rows the profile pass reads (curvature check failed; every row
    with ``every_gn``), NaN elsewhere: on an accelerator the results' copy, not the fit, bounds small
    problems. ``local``: the results are in host memory already (a CPU device); NumPy reads them in
    place, without :func:`jax.device_get`'s per-array machinery (a third of the host's share of a chunk).
    Where no row is pending (the search program profiled every row that failed the check), ``cov_gn``
    is a read-only NaN broadcast: filling 200 bytes a row of fresh memory cost the host a third of its
    CPU time at 10⁶ rows.
    """
    first = pieces[0][0]
    skip = () if sandwich and every_gn else ("cov_gn",)
    host = {k: np.empty((n_rows, *np.shape(v)[1:]), np.float64) for k, v in first._asdict().items() if k not in skip}
    fetch = (lambda tree: {k: np.asarray(v) for k, v in tree.items()}) if local else jax.device_get
    for out, start, stop in pieces:
        got = fetch({k: v for k, v in out._asdict().items() if k not in skip})
        for k, v in got.items():
            host[k][start:stop] = v[: stop - start]
    made = cast(Any, _varpro.ScanlineSolution)  # NumPy arrays in the kernel's NamedTuple
    if "cov_gn" in host:
        return made(**host)
    if not sandwich:
        return made(**host, cov_gn=host["cov"])
    pending = host["nonlinear"] == _profile.PENDING
    if not pending.any():
        return made(**host, cov_gn=np.broadcast_to(np.float64(np.nan), host["cov"].shape))
    cov_gn = np.full_like(host["cov"], np.nan)
    for out, start, stop in pieces:
        at = np.flatnonzero(pending[start:stop])
        if at.size:
            cov_gn[start + at] = np.asarray(out.cov_gn)[at] if local else np.asarray(out.cov_gn[jnp.asarray(at)])
    return made(**host, cov_gn=cov_gn)


def _profile_where_nonlinear(sol: _varpro.ScanlineSolution, data, *, normalization, devices=None) -> None:
    """Profile-likelihood errors of ρs and α, in float64, for the rows still pending a profile.

    The search program profiles the rows that fail its curvature check itself, up to a share of each
    chunk (:func:`_profile_lanes`); this pass takes the rest (a chunk with more failures, float32 fits,
    ``errors="profile"``). Rescales those rows of ``sol.cov`` (in place) so that its diagonal holds the
    profile variances; the correlations stay the Gauss–Newton ones. ``sol.nonlinear``
    keeps which rows changed. Only these rows pay for the profiles (12 evaluations each),
    split over ``devices`` along the scanline axis as :func:`_solve` splits the fits.
    """
    devices = _check_devices(devices)
    put = _placement(devices, direct=False)
    rows = np.flatnonzero((sol.nonlinear == _profile.PENDING) & (sol.status == Status.CONVERGED))
    if not rows.size:
        return
    sub = tuple(None if a is None else a[rows] for a in data)
    n_true = data[0].shape[1]
    n_pad = _sample_bucket(n_true)
    sub = pad_samples(sub, n_pad)
    # 12 profile evaluations per row: at most a quarter of the fit's rows per call on an accelerator.
    chunk = min(_default_chunk(np.float64, devices), _ACCELERATOR_CHUNK // 4) * len(devices)
    scale = np.asarray(sol.chi2, np.float64)[rows] / np.maximum(np.asarray(sol.dof)[rows], 1)
    fit = [np.asarray(a, np.float64)[rows] for a in (sol.alpha[:, 0], sol.rho_s, sol.chi2, sol.cov_gn)]
    small = _small_programs(n_pad, devices)
    with jax.enable_x64(True):
        n = None if n_pad == n_true else jnp.asarray(n_true, jnp.int32)
        out = []
        for start, stop, size in buckets(rows.size, chunk):
            size = -(-size // len(devices)) * len(devices)  # whole rows on every device
            args = [None if a is None else put(pad_rows(a[start:stop], size)) for a in sub]
            parts = _geometry_chunk(*args, normalization=normalization, dtype=np.dtype(np.float64))
            prepared = moments_chunk.pick(small)(*parts, n, iso=True)
            pick = [put(pad_rows(a[start:stop], size)) for a in (*fit, scale)]
            sig = _profile.profile_chunk.pick(small)(prepared, *pick)
            out.append(np.stack([np.asarray(v)[: stop - start] for v in sig], -1))
        sig = np.concatenate(out)
        # The sandwich for unweighted fits: scaled by the profile's ratio to Gauss–Newton.
        cov, good = _profile.rescale_rows(sol.cov[rows], sol.cov_gn[rows], sig)
        sol.cov[rows] = np.asarray(cov)
    sol.nonlinear[rows] = np.where(np.asarray(good), _profile.PROFILED, 0)


def _assemble(sol, data, model, normalization, solver, sandwich=False) -> ScanlineFit:
    alpha = sol.alpha
    ax = alpha[:, 0]
    ay = alpha[:, -1]
    var = np.ascontiguousarray(np.diagonal(sol.cov, axis1=-2, axis2=-1))
    with np.errstate(invalid="ignore"):
        se = np.sqrt(var)  # NaN where a variance is negative, in one pass
    params = WardParams.from_estimate(rho_d=sol.rho_d, rho_s=sol.rho_s, alpha_x=ax, alpha_y=ay)
    stderr = WardParams.from_estimate(rho_d=se[:, :3], rho_s=se[:, 3], alpha_x=se[:, 4], alpha_y=se[:, -1])
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
        errors=np.where(sol.nonlinear == _profile.PROFILED, "profile", "sandwich" if sandwich else "gauss_newton"),
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
    cov = jnp.linalg.inv(jac_nat.T @ jac_nat) * chi2 / jnp.maximum(dof, 1).astype(chi2.dtype)
    ok = sol.result == optx.RESULTS.successful
    n_samples = jnp.sum(jnp.sum(w, axis=-1) > 0)
    finite = jnp.all(jnp.isfinite(y)) & jnp.isfinite(chi2)
    status = jnp.where(
        (n_samples < 4) | (dof < 1),
        Status.INSUFFICIENT_DATA,
        jnp.where(~finite, Status.NONFINITE, jnp.where(ok, Status.CONVERGED, Status.MAX_STEPS)),
    ).astype(jnp.int32)
    no_check = jnp.zeros((), jnp.int32)  # the reference path reports Gauss–Newton errors
    return _varpro.ScanlineSolution(y[:3], jnp.exp(y[3]), jnp.exp(y[4:5]), cov, chi2, dof, status, no_check, cov)


@functools.partial(jax.jit, static_argnames="normalization")
def _optimistix_chunk(f, wi, wo, w, *, normalization):
    return jax.vmap(lambda *a: _optimistix_scanline(*a, normalization=normalization))(f, wi, wo, w)
