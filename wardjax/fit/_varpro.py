"""Fast path: fixed-iteration Levenberg–Marquardt on the variable-projection reduction.

One scanline holds ``N`` samples of RGB BRDF values ``f[n, c]`` with weights
``w[n, c]`` (``c`` runs over 1 weight column shared by the channels, or 3).
The Ward model is

    f[n, c] ≈ a[c] + s · b[n](θ),    a = ρd / π,  s = ρs,
    b[n](θ) = N[n] · exp(−u[n]/αx² − v[n]/αy²) / (αx αy),

with the geometry ``(u, v, N)`` fixed (:func:`wardjax.ward.ward_geometry`).
For fixed roughness ``θ = log α`` (or ``(log αx, log αy)``) the model is
linear in ``(a, s)``: variable projection (Golub & Pereyra 1973) solves those
in closed form and leaves a 1- or 2-parameter nonlinear problem.

With ``x̃ = x − Σw x / Σw`` (weighted centring per channel) and ``m = 3 / C``
the multiplicity of a shared weight column:

* ``s(θ) = max(⟨b̃, f̃⟩, 0) / ⟨b̃, b̃⟩``, ``a[c] = f̄[c] − s b̄[c]``
* ``χ²(θ) = K₀ − s (2⟨b̃, f̃⟩ − s ⟨b̃, b̃⟩)``, ``K₀ = Σ w f̃²``
* Kaufman's Jacobian of the projected residual, ``J = −s P⊥ ∂b/∂θ``, gives
  ``JᵀJ = s² (⟨b̃', b̃'⟩ − ⟨b̃', b̃⟩⟨b̃, b̃'⟩ / ⟨b̃, b̃⟩)`` and the exact gradient
  ``Jᵀr = −s (⟨b', f̃⟩ − s ⟨b', b̃⟩)``,

where ``⟨x, y⟩`` sums ``w x y`` over samples and channels. Every quantity is
a weighted sum over the samples of one exponential, so an RGB fit costs what a
grey one does.

The search: a data-driven guess of ``α`` (half-maximum width of the peak
above the floor), an 8-point grid in ``log α`` around it, the vertex of the
parabola through the best three grid points, then a fixed number of LM steps
(no data-dependent loop under ``vmap``: every member does the same work).
Anisotropic fits continue from the isotropic optimum with 2-D LM steps.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import jax
import jax.numpy as jnp
from jaxtyping import Array, Float, Int

from .._status import Status
from ._sandwich import sandwich_pass

# Search range of α. Below 1e-4 no camera resolves a lobe; above 2 the lobe is
# flat over the hemisphere and α no longer has a meaning.
ALPHA_MIN = 1e-4
ALPHA_MAX = 2.0
GRID_POINTS = 8
GRID_STEP = 0.5  # in log α: the grid spans a factor e^3.5 ≈ 33
ISO_STEPS = 4
ANISO_STEPS = 8
# Converged when the remaining Gauss–Newton step is below this fraction of the
# parameter's standard error (or below an absolute floor in log α).
STEP_TOL_SIGMA = 1e-3
STEP_TOL_SIGMA_F32 = 3e-2
STEP_TOL_ABS = 1e-9
# A lobe counts as detected when it lowers χ² by 25 residual variances (5σ).
DETECT_CHI2 = 25.0
# α counts as resolved when its relative standard error is at most 1.
MAX_REL_SIGMA = 1.0
# The Gauss–Newton covariance is trusted where the profiled χ² one standard error
# from the optimum rises by 1 ± CURVATURE_TOL residual variances, as a quadratic would.
CURVATURE_TOL = 0.2


class Stats(NamedTuple):
    """Weighted sums of one scanline at one roughness."""

    chi2: Array  # ()
    s: Array  # () profiled ρs (≥ 0)
    sbf: Array  # () ⟨b̃, f̃⟩
    sbb: Array  # () ⟨b̃, b̃⟩
    jtj: Array  # (k, k) ⟨b̃', b̃'⟩-based Kaufman normal matrix (× s²)
    jtr: Array  # (k,)
    spb: Array  # (k,) ⟨b̃', b̃⟩
    spp: Array  # (k, k) ⟨b̃', b̃'⟩
    bbar: Array  # (C,) weighted mean of b per weight column
    bpbar: Array  # (C, k) weighted mean of ∂b/∂θ


class Prepared(NamedTuple):
    """Per-scanline constants, computed once before the search.

    The sample axis is last (minor) so that XLA vectorises along it. Every
    weighted sum the search needs is a product of one of a few per-sample
    streams with ``e = exp(−u/αx² − v/αy²)`` or ``e²`` times a low power of
    the geometry ``x`` (``t = u + v``, or ``u`` and ``v``), formed on the fly:

    * ``gw[c] = g w_c`` per weight column (for ``Σwb`` and its derivatives,
      needed per column because of the centring),
    * ``gwf = g Σ_c w_c f̃_c`` and ``g2w = m g² Σ_c w_c`` summed over the
      channels (``⟨b, f̃⟩`` and ``⟨b, b⟩`` only ever appear summed).

    Six streams (isotropic RGB) instead of a 21-row moment matrix: the search
    is bound by memory traffic, not by arithmetic.
    """

    x: Array  # (K, N) t = u + v (isotropic, K = 1) or (u, v) (K = 2)
    gw: Array  # (C, N) g w per weight column, 0 where invalid
    gwf: Array  # (N,) g Σ_c w_c f̃_c
    g2w: Array  # (N,) m g² Σ_c w_c
    wsum: Array  # (C,) Σ w (1 where there is none, to keep divisions finite)
    fbar: Array  # (3,) per-channel weighted mean of f
    k0: Array  # () Σ w f̃² over channels
    channels_ok: Array  # () every weight column has some weight
    has: Array  # (C,) this weight column has some weight
    n_obs: Array  # () values with weight > 0 (over channels)
    n_samples: Array  # () samples with weight > 0 in some channel
    theta_guess: Array  # () log of the data-driven α guess (:func:`initial_alpha`)
    grid_gw: Array  # (C, Ng) gw on a subsample, for the grid
    grid_gwf: Array  # (Ng,)
    grid_g2w: Array  # (Ng,)
    grid_x: Array  # (Ng,) t on the subsample
    grid_wsum: Array  # (C,)
    grid_fsum: Array  # (C,) Σ w f̃ on the subsample (not 0: centred on all samples)

    @property
    def mult(self) -> float:
        """``m = 3 / C``: how many channels share one weight column."""
        return 3.0 / self.gw.shape[-2]


GRID_MIN_SAMPLES = 64


def _grid_subsample(n_pad: int, n):
    """Indices and 0/1 weights of the grid subsample: every ``max(1, ⌊n/64⌋)``-th of the first ``n`` samples.

    ``n`` is ``None`` (all ``n_pad`` samples are data: a static slice) or a
    traced count of data samples, the rest padding (see
    :mod:`wardjax._shapes`); then the same samples are gathered into
    ``min(n_pad, 128)`` slots (``⌈n / max(1, ⌊n/64⌋)⌉ ≤ 127``), the slots past
    them weighted 0, so the grid sees exactly what it would unpadded.
    """
    if n is None:
        return slice(0, None, max(1, n_pad // GRID_MIN_SAMPLES)), None
    stride = jnp.maximum(n // GRID_MIN_SAMPLES, 1)
    idx = jnp.arange(min(n_pad, 2 * GRID_MIN_SAMPLES), dtype=stride.dtype) * stride
    keep = idx < n
    return jnp.where(keep, idx, 0), keep


def prepare(f, u, v, g, w, iso: bool = True, n=None) -> Prepared:
    """Centre the data and build the per-sample streams of one scanline.

    ``f`` (3, N), ``u, v, g`` (N,), ``w`` (C, N) (sample axis last) with
    invalid samples already at weight 0 and ``f`` finite there. ``n``
    (traced int, optional): only the first ``n`` samples are data, the rest
    zero-weight padding; it fixes the grid subsample, so that padding does
    not change the fit.
    """
    c, n_pad = w.shape
    m = 3.0 / c
    wsum = jnp.sum(w, axis=-1)
    has = wsum > 0
    channels_ok = jnp.all(has)
    wsum = jnp.where(has, wsum, 1.0)
    fbar = jnp.sum(w * f, axis=-1) / wsum  # (3,); w and wsum broadcast when C == 1
    fc = f - fbar[:, None]
    k0 = jnp.sum(w * fc * fc)
    ft = jnp.sum(fc, axis=0, keepdims=True) if c == 1 else fc  # (C, N)
    gw = g[None, :] * w  # (C, N)
    gwf = g * jnp.sum(w * fc, axis=0)
    g2w = (m * g * g) * jnp.sum(w, axis=0)
    t = u + v
    x = t[None, :] if iso else jnp.stack([u, v])
    valid = jnp.sum(w, axis=0) > 0
    # Counted in floating point: an int64 count is a slow path in XLA:CPU.
    n_obs = (m * jnp.sum((w > 0).astype(w.dtype))).astype(jnp.int32)
    n_samples = jnp.sum(valid.astype(w.dtype)).astype(jnp.int32)
    theta_guess = jnp.log(initial_alpha(jnp.sum(ft, axis=0), t, valid))
    sub, keep = _grid_subsample(n_pad, n)

    def pick(a):  # (..., N) → (..., G): the subsample, slots past the data weighted 0
        if keep is None:  # n is None: a static slice of data samples
            return a[..., sub]
        return jnp.where(jnp.reshape(keep, (1,) * (a.ndim - 1) + keep.shape), a[..., sub], 0.0)

    grid_wsum = jnp.sum(pick(w), axis=-1)
    grid_wsum = jnp.where(grid_wsum > 0, grid_wsum, 1.0)
    grid_fsum = jnp.sum(pick(w * ft), axis=-1)
    return Prepared(
        x,
        gw,
        gwf,
        g2w,
        wsum,
        fbar,
        k0,
        channels_ok,
        has,
        n_obs,
        n_samples,
        theta_guess,
        pick(gw),
        pick(gwf),
        pick(g2w),
        t[sub],
        grid_wsum,
        grid_fsum,
    )


def basis(theta, u, v, g, iso: bool):
    """``b`` (N,) at ``θ`` (log α or (log αx, log αy)): the specular basis, ``ρs b`` the lobe."""
    if iso:
        inv = jnp.exp(-2.0 * theta[0])
        return g * jnp.exp(-(u + v) * inv) * inv
    ix = jnp.exp(-2.0 * theta[0])
    iy = jnp.exp(-2.0 * theta[1])
    return g * jnp.exp(-(u * ix + v * iy) - theta[0] - theta[1])


def _profile(bsum, qsum, psum, wsum, fsum, m, k0):
    """Profiled ``s``, χ² and the centred sums.

    ``bsum`` (C,) is ``Σwb`` per weight column, ``qsum`` () the channel total
    ``m Σ_c Σ w_c b²``, ``psum`` () the channel total ``Σ_c Σ w_c f̃_c b`` and
    ``fsum`` (C,) ``Σ w f̃`` per column (0 over all samples, where the data are
    centred): ``⟨b̃, b̃⟩ = qsum − m Σ_c (Σwb)²/Σw`` and
    ``⟨b̃, f̃⟩ = psum − Σ_c Σwf̃ Σwb / Σw``.
    """
    sbb = qsum - m * jnp.sum(bsum * bsum / wsum)
    sbf = psum - jnp.sum(fsum * bsum / wsum)
    ok = sbb > 0
    s = jnp.where(ok, jnp.maximum(sbf, 0.0) / jnp.where(ok, sbb, 1.0), 0.0)
    chi2 = k0 - s * (2.0 * sbf - s * sbb)
    return s, chi2, sbf, sbb, ok


def sum_samples(terms):
    """``[Σ_n x[n] for x in terms]`` of equally shaped ``(N,)`` arrays as one variadic reduction: one loop
    over the samples, which XLA:CPU vectorises where the program may reassociate its sums (the kernels'
    compiler options, :data:`~wardjax.fit._data._REASSOCIATE_OPTIONS`)."""
    zeros = tuple(jnp.zeros((), x.dtype) for x in terms)
    return jax.lax.reduce(tuple(terms), zeros, lambda a, b: tuple(x + y for x, y in zip(a, b)), (0,))


def _lobe_terms(gw, gwf, g2w, e) -> list:
    """The per-sample terms of the profiled χ²'s sums at one ``θ``: ``gw_c e`` per weight column, ``gwf e``
    and ``g2w e²`` (C + 2 of them, for :func:`sum_samples`). Per column, not broadcast over the columns,
    and ``g2w e e``, not ``g2w (e e)``: otherwise XLA materialises the exponential (or its square) rather
    than form it inside the reduction (the search of 1,024 scanlines of 256 samples 6.3 against 4.4 ms)."""
    return [*(gw[c] * e for c in range(gw.shape[0])), gwf * e, g2w * e * e]


def _lobe_sums(sums, q):
    """``(Σwb (C,), Σw f̃ b, m Σwb²)`` from the C + 2 sums of :func:`_lobe_terms`, with ``b = q g e``."""
    c_ = len(sums) - 2
    return q * jnp.stack(sums[:c_]), q * sums[c_], q * q * sums[c_ + 1]


def grid_chi2(theta, p: Prepared):
    """Profiled χ² (up to a constant) of the isotropic model on the grid subsample.

    The sums in one variadic reduction over the subsample, the exponential formed inside it
    (vectorised, see :func:`stats`). A reduction per grid point: one for all eight points was as
    fast at 256 samples and 0.4 ms slower per 1,024 problems of 9.
    """
    inv = jnp.exp(-2.0 * theta)
    e = jnp.exp(p.grid_x * -inv)
    bsum, psum, qsum = _lobe_sums(sum_samples(_lobe_terms(p.grid_gw, p.grid_gwf, p.grid_g2w, e)), inv)
    return _profile(bsum, qsum, psum, p.grid_wsum, p.grid_fsum, p.mult, 0.0)[1]


def lobe_exp(theta, p: Prepared, iso: bool):
    """``(e, q)`` at ``θ``: ``e = exp(−t/α²)`` (N,) (or ``exp(−u/αx² − v/αy²)``), ``q = 1/(αx αy)``; ``b = g e q``."""
    if iso:
        inv = jnp.exp(-2.0 * theta[0])
        return jnp.exp(p.x[0] * -inv), inv
    ix = jnp.exp(-2.0 * theta[0])
    iy = jnp.exp(-2.0 * theta[1])
    return jnp.exp(p.x[0] * -ix + p.x[1] * -iy), jnp.exp(-theta[0] - theta[1])


def stats(theta, p: Prepared, iso: bool, with_jac: bool = True) -> Stats:
    """Profiled χ², ``s`` and the Kaufman normal equations at ``θ``.

    One exponential per sample, then weighted sums of the streams of
    :class:`Prepared` against ``e`` and ``e²`` times powers of the geometry:
    ``Σwb = q Σ gw e``, ``m Σwb² = q² Σ g2w e²``, ``Σw f̃ b = q Σ gwf e``
    with ``q = 1/(αx αy)``, and their ``∂/∂θ`` companions through
    ``∂b/∂θ = b c`` with ``c`` linear in the geometry (``c = 2t/α² − 2``, or
    ``c_x = 2u/αx² − 1``, ``c_y = 2v/αy² − 1``). Centring is algebraic (see
    :func:`_profile`).
    """
    k = 1 if iso else 2
    inv = ix = jnp.exp(-2.0 * theta[0])
    iy = inv if iso else jnp.exp(-2.0 * theta[1])
    e, q = lobe_exp(theta, p, iso)
    xs = [p.x[i] for i in range(k)]
    pairs = [(i, j) for i in range(k) for j in range(i, k)]
    # Every sum in one variadic reduction over the samples, the exponential formed inside it: with the
    # kernels' reassociating compiler options XLA:CPU vectorises the loop, which reads each stream once.
    # As dot products (a YNNPACK call per sum, each re-reading e and its stream) the search of 1,024
    # scanlines of 256 samples cost 10.6 ms, against 4.4 ms so (one core, medians over interleaved runs).
    c_ = p.gw.shape[0]
    terms = _lobe_terms(p.gw, p.gwf, p.g2w, e)
    if with_jac:
        gwe, gfe, gqe = terms[:c_], terms[c_], terms[c_ + 1]
        for x in xs:
            terms += [*(a * x for a in gwe), gfe * x, gqe * x]
        terms += [gqe * xs[i] * xs[j] for i, j in pairs]
    sums = sum_samples(terms)
    bsum, psum, qsum = _lobe_sums(sums[: c_ + 2], q)  # (C,), (), ()
    s, chi2, sbf, sbb, ok = _profile(bsum, qsum, psum, p.wsum, jnp.zeros_like(bsum), p.mult, p.k0)
    bbar = bsum / p.wsum
    if not with_jac:
        z = jnp.zeros((k,), chi2.dtype)
        zz = jnp.zeros((k, k), chi2.dtype)
        return Stats(chi2, s, sbf, sbb, zz, z, z, zz, bbar, jnp.zeros((c_, k), chi2.dtype))
    # Σ gw e x, Σ gwf e x, Σ g2w e² x per geometry stream x, and Σ g2w e² x_i x_j.
    per = [sums[(c_ + 2) * (1 + i) : (c_ + 2) * (2 + i)] for i in range(k)]
    bs = [jnp.stack(a[:c_]) for a in per]
    ps = [a[c_] for a in per]
    qs = [a[c_ + 1] for a in per]
    qq = dict(zip(pairs, sums[(c_ + 2) * (1 + k) :]))
    b0, p0, q0 = bsum / q, psum / q, qsum / (q * q)
    if iso:
        bp = q * (2 * inv * bs[0] - 2 * b0)[:, None]  # (C, 1)
        pp = q * (2 * inv * ps[0] - 2 * p0)[None]  # (1,)
        qp = q * q * (2 * inv * qs[0] - 2 * q0)[None]
        rp = (q * q * (4 * inv * inv * qq[0, 0] - 8 * inv * qs[0] + 4 * q0))[None, None]
    else:
        bp = q * jnp.stack([2 * ix * bs[0] - b0, 2 * iy * bs[1] - b0], -1)  # (C, 2)
        pp = q * jnp.stack([2 * ix * ps[0] - p0, 2 * iy * ps[1] - p0])
        qp = q * q * jnp.stack([2 * ix * qs[0] - q0, 2 * iy * qs[1] - q0])
        rxx = 4 * ix * ix * qq[0, 0] - 4 * ix * qs[0] + q0
        ryy = 4 * iy * iy * qq[1, 1] - 4 * iy * qs[1] + q0
        rxy = 4 * ix * iy * qq[0, 1] - 2 * ix * qs[0] - 2 * iy * qs[1] + q0
        rp = q * q * jnp.stack([jnp.stack([rxx, rxy]), jnp.stack([rxy, ryy])])  # (2, 2)
    m, wsum = p.mult, p.wsum
    spb = qp - m * jnp.sum(bsum[:, None] * bp / wsum[:, None], axis=0)
    spp = rp - m * jnp.sum(bp[:, :, None] * bp[:, None, :] / wsum[:, None, None], axis=0)
    jtj = s * s * (spp - jnp.outer(spb, spb) / jnp.where(ok, sbb, 1.0))
    jtr = -s * (pp - s * spb)
    return Stats(chi2, s, sbf, sbb, jtj, jtr, spb, spp, bbar, bp / wsum[:, None])


def _solve_small(a, b):
    """Solve a 1×1 or 2×2 system in closed form (vmap-friendly, no LAPACK call)."""
    if a.shape[-1] == 1:
        den = a[0, 0]
        return jnp.where(den > 0, b / jnp.where(den > 0, den, 1.0), 0.0)
    det = a[0, 0] * a[1, 1] - a[0, 1] * a[1, 0]
    ok = jnp.abs(det) > 0
    det = jnp.where(ok, det, 1.0)
    x0 = (a[1, 1] * b[0] - a[0, 1] * b[1]) / det
    x1 = (a[0, 0] * b[1] - a[1, 0] * b[0]) / det
    return jnp.where(ok, jnp.stack([x0, x1]), 0.0)


def initial_alpha(y, t, valid) -> Array:
    """Data-driven guess of ``α``: the half-maximum width of the peak above the floor.

    ``y`` (N,) is the channel-summed centred data, ``t = tan²δ`` (N,),
    ``valid`` (N,) where a sample has weight. For a lobe ``exp(−t/α²)`` the
    excess over the floor halves where ``t − t_peak = α² ln 2``. The floor is
    the smallest valid value. Returns a value inside the search range.
    """
    big = jnp.asarray(jnp.finfo(y.dtype).max, y.dtype)
    floor = jnp.min(jnp.where(valid, y, big))
    excess = jnp.where(valid, y - floor, 0.0)
    peak = jnp.argmax(excess)
    half = excess >= 0.5 * excess[peak]
    spread = jnp.max(jnp.where(half & valid, t, -big)) - t[peak]
    alpha = jnp.sqrt(jnp.maximum(spread, 0.0) / jnp.log(2.0))
    alpha = jnp.where(jnp.isfinite(alpha) & (alpha > 0), alpha, 0.1)
    return jnp.clip(alpha, 2 * ALPHA_MIN, ALPHA_MAX / 2).astype(y.dtype)


def grid_start(p: Prepared) -> Array:
    """Best of an 8-point ``log α`` grid around the guess, refined by a parabola.

    The vertex of the parabola through the best point and its two neighbours
    is taken unconditionally when the curvature is positive (it is the
    minimum of the local quadratic model), clipped to one grid step.
    """
    centre = p.theta_guess
    offsets = (jnp.arange(GRID_POINTS, dtype=centre.dtype) - (GRID_POINTS - 1) / 2) * GRID_STEP
    lo, hi = math.log(ALPHA_MIN), math.log(ALPHA_MAX)
    thetas = jnp.clip(centre + offsets, lo, hi)
    chi = jnp.stack([grid_chi2(thetas[i], p) for i in range(GRID_POINTS)])
    chi = jnp.where(jnp.isfinite(chi), chi, jnp.finfo(chi.dtype).max)
    i = jnp.clip(jnp.argmin(chi), 1, GRID_POINTS - 2)
    cm, c0, cp = chi[i - 1], chi[i], chi[i + 1]
    curv = cm - 2.0 * c0 + cp
    shift = jnp.where(curv > 0, 0.5 * GRID_STEP * (cm - cp) / jnp.where(curv > 0, curv, 1.0), 0.0)
    shift = jnp.clip(shift, -GRID_STEP, GRID_STEP)
    best = jnp.where(chi[jnp.argmin(chi)] < c0, thetas[jnp.argmin(chi)], thetas[i] + shift)
    return jnp.clip(best, lo, hi)[None]


def lm(theta0, p: Prepared, iso: bool, steps: int, rtol: float):
    """``steps`` Levenberg–Marquardt iterations on the reduced problem: ``(θ, Stats)`` at the last
    accepted point.

    Marquardt's scaling (``λ diag(JᵀJ)``), ``λ`` divided by 3 on success and
    multiplied by 10 on failure. A step is accepted when it lowers χ² by more
    than the rounding allowance ``rtol · K₀`` (0 in float64 is too strict for
    float32 sums, which round at that level).
    """
    lo, hi = math.log(ALPHA_MIN), math.log(ALPHA_MAX)
    tiny = jnp.finfo(theta0.dtype).tiny

    def body(_, carry):
        theta, st, lam = carry
        h = st.jtj + lam * jnp.diag(jnp.diag(st.jtj)) + tiny * jnp.eye(theta.shape[0], dtype=theta.dtype)
        step = -_solve_small(h, st.jtr)
        trial = jnp.clip(theta + step, lo, hi)
        st_new = stats(trial, p, iso)
        ok = jnp.isfinite(st_new.chi2) & (st_new.chi2 < st.chi2 + rtol * p.k0)
        ok = ok & jnp.any(trial != theta)
        theta = jnp.where(ok, trial, theta)
        st = jax.tree_util.tree_map(lambda a, b: jnp.where(ok, a, b), st_new, st)
        lam = jnp.where(ok, jnp.maximum(lam / 3.0, 1e-12), jnp.minimum(lam * 10.0, 1e12))
        return theta, st, lam

    carry = (theta0, stats(theta0, p, iso), jnp.asarray(1e-3, theta0.dtype))
    # A fixed number of steps in a loop, not unrolled: unrolled, XLA:CPU fused
    # the chain of accept/reject selects into every later step and re-evaluated
    # the whole history each time (anisotropic search 2-3.5x slower, iso equal).
    theta, st, _ = jax.lax.fori_loop(0, steps, body, carry)
    return theta, st


class ScanlineSolution(NamedTuple):
    """What the kernel returns for one scanline (all arrays)."""

    rho_d: Float[Array, " 3"]
    rho_s: Float[Array, ""]
    alpha: Float[Array, " k"]
    cov: Float[Array, "p p"]  # natural parameters (ρd RGB, ρs, α or αx, αy), scaled
    chi2: Float[Array, ""]
    dof: Int[Array, ""]
    status: Int[Array, ""]
    nonlinear: Int[Array, ""]  # 2 where the curvature check fails, 1 once profiled (:mod:`._profile` codes)
    cov_gn: Float[Array, "p p"]  # the Gauss–Newton covariance (``cov`` unless it is the sandwich)


def _inv_small(a):
    """Inverse of a symmetric 1×1, 2×2 or 3×3 matrix by the adjugate (NaN where singular)."""
    n = a.shape[-1]
    if n == 1:
        return 1.0 / a
    if n == 2:
        det = a[0, 0] * a[1, 1] - a[0, 1] * a[1, 0]
        return jnp.array([[a[1, 1], -a[0, 1]], [-a[1, 0], a[0, 0]]]) / det
    c00 = a[1, 1] * a[2, 2] - a[1, 2] * a[2, 1]
    c01 = a[1, 2] * a[2, 0] - a[1, 0] * a[2, 2]
    c02 = a[1, 0] * a[2, 1] - a[1, 1] * a[2, 0]
    c11 = a[0, 0] * a[2, 2] - a[0, 2] * a[2, 0]
    c12 = a[0, 1] * a[2, 0] - a[0, 0] * a[2, 1]
    c22 = a[0, 0] * a[1, 1] - a[0, 1] * a[1, 0]
    det = a[0, 0] * c00 + a[0, 1] * c01 + a[0, 2] * c02
    adj = jnp.array([[c00, c01, c02], [c01, c11, c12], [c02, c12, c22]])
    return adj / det


def covariance(theta, st: Stats, p: Prepared, scale):
    """Covariance of ``(ρd R, G, B, ρs, α…)`` by blocks, from the sums of :func:`stats`.

    The information matrix ``JᵀWJ`` in natural parameters has a diagonal ρd
    block ``A = diag(Σw)/π²``. Eliminating it (Schur complement) leaves, for
    ``(ρs, α…)``, ``S = D [[⟨b̃,b̃⟩, ⟨b̃,b̃'⟩], [⟨b̃',b̃⟩, ⟨b̃',b̃'⟩]] D`` with
    ``D = diag(1, s/α…)`` (since ``∂f/∂α = s b c / α``): the sums the search
    already forms. Then ``Σ_θθ = S⁻¹``, ``Σ_dθ = −M S⁻¹`` and
    ``Σ_dd = A⁻¹ + M S⁻¹ Mᵀ`` with ``M = A⁻¹B = π (b̄, s b̄'/α)`` per channel.
    Everything is multiplied by the residual variance ``scale = χ²/dof``.
    """
    k = theta.shape[0]
    alpha = jnp.exp(theta)
    s = st.s
    sv = jnp.concatenate([jnp.ones((1,), theta.dtype), s / alpha])
    top = jnp.concatenate([st.sbb[None], st.spb])[None, :]
    bottom = jnp.concatenate([st.spb[:, None], st.spp], axis=1)
    info = jnp.concatenate([top, bottom], axis=0) * jnp.outer(sv, sv)
    sinv = _inv_small(info)  # (k+1, k+1)
    mrow = jnp.pi * jnp.concatenate([st.bbar[:, None], st.bpbar * (s / alpha)[None, :]], axis=1)  # (C, k+1)
    mrow = jnp.broadcast_to(mrow, (3, k + 1))
    wsum = jnp.broadcast_to(p.wsum, (3,))
    c_dt = -mrow @ sinv
    c_dd = jnp.diag(jnp.pi**2 / wsum) + mrow @ sinv @ mrow.T
    cov = jnp.block([[c_dd, c_dt], [c_dt.T, sinv]])
    return cov * scale


def curvature_pass(theta, chi2, s_hat, p: Prepared, cov, scale):
    """The curvature check's per-sample terms and its verdict on their sums: ``(terms, verdict)``.

    The profiled χ² (the sums of :func:`stats` without derivatives) at two points about one standard
    error either side of the optimum, both from one pass over the samples. At a fixed roughness the
    model is linear in ρd and ρs, so each gives the exact χ² there for *every* ``ρs``
    (``χ²(θ, s) = K₀ − 2 s ⟨b̃, f̃⟩ + s² ⟨b̃, b̃⟩``, ρd profiled out). The
    Gauss–Newton covariance predicts, in units of the residual variance ``χ²/dof`` and in
    standardised coordinates ``(z_s, z_θ)`` with correlation ``r``,
    ``Δχ²(z_s, z_θ) = (z_s² − 2 r z_s z_θ + z_θ²) / (1 − r²)``. Checked at each point ``z_θ``:

    * α: the profile over ρs (``min_s``, exact by variable projection) rises by ``z_θ²``;
    * ρs: at the corner ``z_s = sign(r) z_θ``, nearest the ρs profile's path (which passes
      ``(±1, ±r)``), χ² rises by ``2 z_θ² / (1 + |r|)``.

    The points are symmetric in ``1/α²``: ``1/α'² = (1 ± κ)/α̂²`` with ``κ = tanh 2σ_θ``, i.e.
    ``θ' = θ̂ ± σ_θ + ½ log cosh 2σ_θ`` (``θ̂ ± σ_θ`` to second order in ``σ_θ``), where the lobe's
    exponentials are ``exp(−(1 ± κ) t/α̂²)``: two per sample.

    The check fails when any of the four rises differs from its prediction by more than
    ``CURVATURE_TOL`` times the prediction (widened by the rounding allowance
    ``64 ε K₀ / (χ²/dof)``, which matters in float32 only): the likelihood is not quadratic
    over one standard error (a lobe spanning few samples, a weakly detected lobe), and
    :func:`wardjax.fit._profile.profile_errors` replaces the standard errors of ρs and α by
    profile-likelihood ones. ``verdict(sums)`` returns ``1`` where the check fails (the sums of
    ``terms`` over the samples, e.g. by :func:`sum_samples`).
    """
    alpha = jnp.exp(theta[0])
    var_s, var_a, cov_sa = cov[3, 3], cov[4, 4], cov[3, 4]
    scale = jnp.where(scale > 0, scale, 1.0)
    sd_t = jnp.sqrt(jnp.abs(var_a)) / alpha
    sd_s = jnp.sqrt(jnp.abs(var_s))
    den = jnp.sqrt(jnp.abs(var_s * var_a))
    r = jnp.clip(jnp.where(den > 0, cov_sa / jnp.where(den > 0, den, 1.0), 0.0), -0.999, 0.999)
    corner = 2.0 / (1.0 + jnp.abs(r))
    sign_r = jnp.where(r < 0, -1.0, 1.0)
    kappa = jnp.tanh(2.0 * sd_t)
    inv = jnp.exp(-2.0 * theta[0])
    ends = ((1.0, -0.5 * jnp.log1p(-kappa), jnp.exp(-(1.0 - kappa) * inv * p.x[0])),)
    ends += ((-1.0, 0.5 * jnp.log1p(kappa), jnp.exp(-(1.0 + kappa) * inv * p.x[0])),)
    # Both points' sums (``Σ gw e'`` per column, ``Σ gwf e'``, ``Σ g2w e'²``) in one variadic reduction:
    # one loop that reads the streams once, where a mat-vec per sum re-read them (XLA's cost analysis:
    # 18 MB of memory traffic for the check of 1,024 scanlines of 256 samples, not 50 MB). The
    # exponentials are formed inside it: with the sums reassociated (the kernels' compiler options) the
    # loop is vectorised, and materialising them first cost 0.1–0.2 ms more per 1,024 scanlines.
    terms = [x for _, _, e_t in ends for x in _lobe_terms(p.gw, p.gwf, p.g2w, e_t)]
    return terms, lambda sums: _verdict(sums, theta, chi2, s_hat, p, scale, ends, sd_t, sd_s, sign_r, corner)


def _verdict(sums, theta, chi2, s_hat, p: Prepared, scale, ends, sd_t, sd_s, sign_r, corner):
    """:func:`curvature_pass`'s verdict from its sums: ``1`` where a rise is off its prediction."""
    per = len(sums) // 2  # each point's C + 2 sums of _lobe_terms
    rises, predicted = [], []
    for j, (sign, delta, _) in enumerate(ends):
        z = delta / jnp.where(sd_t > 0, sd_t, 1.0)
        q = jnp.exp(-2.0 * (theta[0] + sign * delta))  # 1/α² at the point
        bsum, psum, qsum = _lobe_sums(sums[j * per : (j + 1) * per], q)
        _, chi_t, sbf, sbb, _ = _profile(bsum, qsum, psum, p.wsum, jnp.zeros_like(p.wsum), p.mult, p.k0)
        rises.append((chi_t - chi2) / scale)
        predicted.append(z * z)
        s_new = jnp.maximum(s_hat + sign * sign_r * z * sd_s, 0.0)
        chi = p.k0 - 2.0 * s_new * sbf + s_new * s_new * sbb
        rises.append((chi - chi2) / scale)
        predicted.append(corner * z * z)
    rises, predicted = jnp.stack(rises), jnp.stack(predicted)
    # χ² differences round at ε K₀ (the centred sums cancel): no verdict below that. In
    # float64 this is far below the tolerance; in float32 it lets high-signal fits pass.
    rounding = 64.0 * jnp.finfo(scale.dtype).eps * p.k0 / scale
    bad = jnp.any(~(jnp.abs(rises - predicted) <= CURVATURE_TOL * predicted + rounding))
    return bad.astype(jnp.int32)


def solve_scanline(
    p: Prepared, *, iso: bool, rtol: float, check: bool = True, steps: int | None = None, raw=None
) -> ScanlineSolution:
    """Search and statistics of one prepared scanline (stage B, vmapped over a chunk).

    ``check``: run the curvature check, :func:`curvature_pass` (isotropic fits).
    ``steps``: LM steps after the grid start (default ``ISO_STEPS``; the
    anisotropic fit takes ``ANISO_STEPS`` more).
    ``raw``: ``(f, u, v, g, w)`` of the geometry stage, given to report the sandwich covariance
    (:func:`~wardjax.fit._sandwich.sandwich_pass`) as ``cov`` (``cov_gn`` keeps Gauss–Newton's), formed
    in the same program at the optimum, with ρd/π taken from the search.
    """
    n_steps = ISO_STEPS if steps is None else steps
    theta = grid_start(p)
    if iso:
        theta, st = lm(theta, p, True, n_steps, rtol)
    else:
        # Start from αx = αy at the grid optimum; the 2-D steps move both.
        theta = jnp.concatenate([theta, theta])
        theta, st = lm(theta, p, False, n_steps + ANISO_STEPS, rtol)
    k = theta.shape[0]
    n_par = 4 + k
    n_samples = p.n_samples
    dof = p.n_obs - n_par
    s = st.s
    rho_d = jnp.pi * (p.fbar - s * jnp.broadcast_to(st.bbar, (3,)))
    scale = st.chi2 / jnp.maximum(dof, 1).astype(st.chi2.dtype)
    cov = covariance(theta, st, p, scale)

    # Convergence: the remaining Gauss–Newton step versus the standard error.
    gn = _solve_small(st.jtj, -st.jtr)
    sigma_theta = jnp.sqrt(jnp.abs(jnp.diag(_inv_small(st.jtj))) * scale)
    # float32 rounding in the algebraic centring limits how small a remaining
    # step can be certified: allow 3 % of σ there (still far below the error).
    tol = STEP_TOL_SIGMA if theta.dtype == jnp.float64 else STEP_TOL_SIGMA_F32
    small = jnp.all(jnp.abs(gn) <= tol * sigma_theta + STEP_TOL_ABS)
    lo, hi = math.log(ALPHA_MIN), math.log(ALPHA_MAX)
    # ∂χ²/∂θ = 2 Jᵀr: outward at the lower bound means Jᵀr > 0 (χ² falls as θ falls).
    at_lo = (theta <= lo + 1e-6) & (st.jtr > 0)
    at_hi = (theta >= hi - 1e-6) & (st.jtr < 0)
    at_bound = jnp.any(at_lo | at_hi)
    # Valid numbers, not only finite ones: in float32 the algebraic centring
    # can cancel into a negative χ² or variance at a spurious optimum.
    finite = (
        jnp.all(jnp.isfinite(theta))
        & jnp.isfinite(st.chi2)
        & (st.chi2 >= 0)
        & jnp.all(jnp.isfinite(rho_d))
        & jnp.all(jnp.isfinite(jnp.diag(cov)) & (jnp.diag(cov) >= 0))
    )
    # Identifiability: the lobe must be detected (likelihood-ratio Δχ² of the
    # lobe against a lobe-free model, in units of the residual variance, at
    # least DETECT_CHI2) and its width resolved (σ_α/α ≤ MAX_REL_SIGMA for the
    # best-constrained α). Otherwise α is not identified by these data.
    detect = st.sbf * s / jnp.where(scale > 0, scale, 1.0)
    rel_sigma = jnp.min(jnp.sqrt(jnp.abs(jnp.diag(cov)[4:])) / jnp.exp(theta))
    identified = (detect >= DETECT_CHI2) & (rel_sigma <= MAX_REL_SIGMA)
    insufficient = (n_samples < k + 3) | (dof < 1) | ~(s > 0) | ~(st.sbb > 0) | ~identified
    insufficient = insufficient | ~p.channels_ok
    rho_d = jnp.where(jnp.broadcast_to(p.has, (3,)), rho_d, jnp.nan)
    status = jnp.where(
        insufficient,
        Status.INSUFFICIENT_DATA,
        jnp.where(
            ~finite,
            Status.NONFINITE,
            jnp.where(at_bound, Status.AT_BOUND, jnp.where(small, Status.CONVERGED, Status.MAX_STEPS)),
        ),
    )
    # The curvature check and the sandwich, both sums over the samples at the optimum: a reduction each.
    # One variadic reduction of all 18 sums (samples read once) cost more than two (1,024 × 256 samples,
    # one core, median of paired runs: 0.3 ms more).
    passes = []
    if iso and check:
        passes.append(curvature_pass(theta, st.chi2, s, p, cov, scale))
    if raw is not None:
        mean = p.fbar - s * jnp.broadcast_to(st.bbar, (3,))
        f, _, _, g, w = raw
        passes.append(sandwich_pass(theta, s, cov, scale, f, p.x, g, w, mean))
    done = [finish(sum_samples(terms)) for terms, finish in passes]
    nonlinear = done.pop(0) if iso and check else jnp.zeros((), jnp.int32)
    nonlinear = jnp.where(status == Status.CONVERGED, 2 * nonlinear, 0)  # 2: the profile is pending
    reported = done.pop(0) if raw is not None else cov
    status = status.astype(jnp.int32)
    return ScanlineSolution(rho_d, s, jnp.exp(theta), reported, st.chi2, dof, status, nonlinear, cov)


__all__ = ["Prepared", "ScanlineSolution", "prepare", "solve_scanline"]
