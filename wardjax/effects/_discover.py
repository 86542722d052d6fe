"""``discover``: find where a model and the data disagree, name the missing effect, add it.

Algorithm (DESIGN.md, "Missing effects")
    1. Fit the baseline; the *gap* is the reduced χ², ``χ²/dof`` of the
       whitened residuals ``(y − f)/σ`` — 1 when the model explains the data
       to the noise level.
    2. Test the residuals for structure against each candidate's telling
       covariate (binned means of the whitened residuals in quantile bins;
       ``Σ n_b r̄_b² ~ χ²_B`` under noise).
    3. Fit every candidate extension (current model + one effect) from
       several starts, all in one batched, jitted Levenberg–Marquardt solve,
       and score it by evidence that penalises its extra parameters.
    4. Add the best-supported candidate if it is justified; repeat. Fits
       that stopped at the step cap are continued where they decide (the
       baseline, the winner, runners-up within half its ΔBIC): γ and a
       second lobe lie in curved valleys that can need hundreds of steps.
    5. Report the structure no library effect explains.

Evidence: why BIC *and* a boundary-corrected likelihood ratio
    A candidate with ``k`` extra parameters that lowers the deviance by
    ``Δχ² = −2 Δ log L`` is scored by the Schwarz criterion,
    ``ΔBIC = Δχ² − k ln N``, ``−½ΔBIC`` approximating the log Bayes factor
    against the current model (unit-information prior); the winner is the
    candidate with the largest ΔBIC, so an effect with more parameters must
    buy its extra freedom — never the largest raw drop. BIC's penalty grows
    with ``N``, which is what keeps false additions rare on the large
    scanline problems (``N`` ≈ 10⁴: a one-parameter effect needs
    ``Δχ² > 9.2``). On small problems (Table 1: ``N = 16``) BIC alone is
    lenient, so the winner must *also* pass the likelihood-ratio test at
    level ``alpha`` Bonferroni-corrected over the ``m`` candidates of the
    step. Amplitudes that are physical only on one side of their absent
    value (a second lobe's weight, a Fresnel κ) are fitted unconstrained; a
    fit on the unphysical side counts as no evidence, and the LR reference is
    the boundary mixture ``½χ²_{k−1} + ½χ²_k`` (Self & Liang 1987). Grouped
    cross-validation was not chosen: it needs a refit per fold and candidate,
    and its noise on small data (16 points) is larger than the effects.

Guard against confident wrong names
    A library effect that is strongly supported but explains less than
    ``min_explained`` of the current excess (``χ² − dof``) *and* leaves a gap
    that still exceeds the noise level (``P(χ²_dof ≥ χ²_after) < structure_p``)
    is *not* added: a large discrepancy that a library effect only dents is
    the signature of an effect outside the library that it partly mimics. It
    is reported as a partial match next to the unexplained structure.

    Both conditions are needed. The excess ``χ² − dof`` carries the noise of
    χ² itself, SD ``√(2 dof)`` (≈ 110 on 6,144 residuals): an effect whose
    residual signature is mostly absorbed by the baseline (a γ mismatch at
    ``ε ≈ −0.1`` moves the data by 5 σ RMS, of which ρd, ρs and α take all but
    ``Δχ² ≈ 30``) is decisively supported, yet "explains" a small fraction of
    an excess that is mostly noise. When the model with the effect leaves no
    significant gap, nothing is left for an out-of-library effect to explain
    and the effect is named.
"""

from __future__ import annotations

import functools
import math
import time

import jax
import jax.numpy as jnp
import lineax as lx
import numpy as np
import optimistix as optx
from scipy import stats

from ._effect import Effect, Param
from ._library import library
from ._report import Candidate, DiscoveryReport, FitState, Step

__all__ = ["discover"]

_N_BINS = 20
_LINEAR_SOLVER = lx.QR()
_PLOT_MAX = 20_000
_SOLO_MIN_OBS = 20_000  # from this many residuals on, each fit is solved alone (_fit_batch)
_REFINE_ROUNDS = 3  # an unconverged fit that matters gets up to this many more rounds of lm_steps (discover)
_REFINE_BIC = 0.5  # ... a runner-up matters if its ΔBIC (a lower bound) is at least this fraction of the winner's


class _Layout:
    """Flat parameter vector: the model's parameters, then each testable effect's."""

    def __init__(self, base: tuple[Param, ...], effects: tuple[Effect, ...]):
        self.entries: list[tuple[str, Param]] = [("model", p) for p in base]
        self.slices: dict[str, list[int]] = {"model": list(range(len(base)))}
        for e in effects:
            i0 = len(self.entries)
            self.entries += [(e.name, p) for p in e.params]
            self.slices[e.name] = list(range(i0, len(self.entries)))
        self.size = len(self.entries)
        self.kinds = tuple(p.kind for _, p in self.entries)
        self.scales = np.array([p.scale for _, p in self.entries])
        self.prior_w = np.array([1.0 / p.prior_sd if p.prior_sd > 0 else 0.0 for _, p in self.entries] + [0.0])

    def u_initial(self) -> np.ndarray:
        u = np.zeros(self.size + 1)  # last slot: a dummy for padding
        for i, (owner, p) in enumerate(self.entries):
            v = p.init if (owner == "model" or math.isnan(p.absent)) else p.absent
            u[i] = p.to_u(v)
        return u

    def natural(self, u) -> dict[str, dict[str, float]]:
        out: dict[str, dict[str, float]] = {k: {} for k in self.slices}
        for i, (owner, p) in enumerate(self.entries):
            out.setdefault(owner, {})[p.name] = float(self._nat(p, u[i]))
        return out

    @staticmethod
    def _nat(p: Param, ui):
        return p.scale * (jnp.exp(ui) if p.kind == "log" else ui)

    @property
    def key(self) -> tuple:
        """What the traced functions need of the layout (hashable: one compilation per layout shape)."""
        return tuple((owner, p.name, p.kind, p.scale) for owner, p in self.entries)

    def unpack(self, u, names: tuple[str, ...]):
        return _unpack(self.key, u, names)

    def sigma(self, u, cov_u) -> dict[str, dict[str, float]]:
        out: dict[str, dict[str, float]] = {k: {} for k in self.slices}
        for i, (owner, p) in enumerate(self.entries):
            s = math.sqrt(max(cov_u[i, i], 0.0)) if np.isfinite(cov_u[i, i]) else math.nan
            d = p.scale * (math.exp(min(u[i], 700.0)) if p.kind == "log" else 1.0)
            out.setdefault(owner, {})[p.name] = abs(d) * s
        return out


def _unpack(key: tuple, u, names: tuple[str, ...]):
    out = {n: {} for n in names}
    out["model"] = {}
    for i, (owner, name, kind, scale) in enumerate(key):
        out[owner][name] = scale * (jnp.exp(u[i]) if kind == "log" else u[i])
    return out


@functools.partial(jax.jit, static_argnames=("model", "effects", "layout_key", "max_steps"))
def _solve_batch(u0, a0, idx, kmask, active, prior_w, data, *, model, effects, layout_key, max_steps):
    names = tuple(e.name for e in effects)
    ctx = model.context(data) if hasattr(model, "context") else None

    def one(u0, a0, idx, kmask, active):
        pw = jnp.where(kmask, prior_w[idx], 0.0)
        z0 = a0[idx]  # the priors' centres: the starting values, kept when a fit is continued

        def data_resid(z):
            u = u0.at[idx].set(jnp.where(kmask, z, u0[idx]))
            vals = _unpack(layout_key, u, names)
            act = {e.name: active[i] for i, e in enumerate(effects)}
            return model.residuals(vals, act, effects, data, ctx)

        def resid(z, _):
            return jnp.concatenate([data_resid(z), pw * (z - z0)])

        solver = optx.LevenbergMarquardt(rtol=1e-6, atol=1e-8, linear_solver=_LINEAR_SOLVER)
        sol = optx.least_squares(resid, solver, u0[idx], max_steps=max_steps, throw=False)
        z = sol.value
        r = data_resid(z)
        chi2 = jnp.sum(r * r)
        jac = jax.jacfwd(data_resid)(z)
        jtj = jac.T @ jac
        ok = (sol.result == optx.RESULTS.successful) & jnp.isfinite(chi2)
        u = u0.at[idx].set(jnp.where(kmask, z, u0[idx]))
        return u, chi2, jtj, ok, sol.stats["num_steps"]

    return jax.vmap(one)(u0, a0, idx, kmask, active)


@functools.partial(jax.jit, static_argnames=("model", "effects", "layout_key"))
def _residual_view(u, active, data, *, model, effects, layout_key):
    """Whitened residuals (flat), prediction and censored mask of one fitted state, in one program.

    Run eagerly, the model's few dozen operations would each compile on their
    own (~76 small programs, ~3 s, per process and data shape).
    """
    names = tuple(e.name for e in effects)
    vals = _unpack(layout_key, u, names)
    act = {e.name: active[i] for i, e in enumerate(effects)}
    r = model.residuals(vals, act, effects, data)
    pred, _, cens = model.predict(vals, act, effects, data)
    return r, pred, cens


def _job_rows(jobs, layout, n_e, width):
    """Pad each job ``(u0, free indices, active effect indices[, prior centres])`` to ``width`` free slots.

    Slots past a job's free parameters point at the dummy entry ``layout.size``
    with ``kmask`` false: the solver sees a zero Jacobian column there.
    """
    rows = []
    for u0, free, act, *anchor in jobs:
        idx = np.full(width, layout.size, np.int32)
        idx[: len(free)] = free
        km = np.zeros(width, bool)
        km[: len(free)] = True
        a = np.zeros(n_e, bool)
        a[list(act)] = True
        rows.append((u0, anchor[0] if anchor else u0, idx, km, a))
    return rows


def _solve_rows(rows, layout, model, effects, data, max_steps):
    """One ``_solve_batch`` call on stacked rows; host arrays back."""
    U0, A0, IDX, KM, A = (np.stack(col) for col in zip(*rows))
    with jax.enable_x64(True):
        u, chi2, jtj, ok, _ = _solve_batch(jnp.asarray(U0), jnp.asarray(A0), jnp.asarray(IDX), jnp.asarray(KM),
                                           jnp.asarray(A),
                                           jnp.asarray(layout.prior_w), data, model=model, effects=effects,
                                           layout_key=layout.key, max_steps=max_steps)
        return tuple(np.asarray(x) for x in (u, chi2, jtj, ok))


def _fit_batch(jobs, layout, model, effects, data, k_pad, b_pad, max_steps, chunk, solo=False):
    """Solve a list of jobs ``(u0, free indices, active effect indices)``; one result per job, in order.

    Batched (``solo=False``): chunks of ``min(b_pad, chunk)`` jobs, each padded
    to ``k_pad`` free slots, so that every call has one shape and one compiled
    program serves the whole run — what pays on small data, where a call costs
    little more than its overhead.

    Solo (``solo=True``, large data): each job alone, so that it takes its
    own number of LM steps. Under ``vmap`` the ``while_loop`` runs every
    member until the slowest converges, the padding copies too (the baseline's
    3 starts padded to the step's 16 candidate starts ran 16 fits); on
    ``N ≳ 10⁴`` residuals an LM step (a Jacobian of ``k_pad`` JVP columns over
    all ``N`` residuals and an ``(N + k_pad) × k_pad`` QR) costs far more than
    a call's overhead, so that waste dominated. Same width ``k_pad``, hence
    one compiled program and the same arithmetic per fit: the same fits as
    batched (to rounding). Solving at each job's own width instead would
    save more per step but compiles once per width and moves the fits by
    ~10⁻⁹ (QR rounding, amplified by the LM stopping rule).
    """
    rows = _job_rows(jobs, layout, len(effects), k_pad)
    if solo:
        chunk = width = 1
    else:
        width = min(b_pad, chunk)
    out = []
    for c0 in range(0, len(rows), chunk):
        part = rows[c0: c0 + chunk]
        pad = part + [part[0]] * (width - len(part)) if len(part) < width else part
        u, chi2, jtj, ok = _solve_rows(pad, layout, model, effects, data, max_steps)
        for i in range(len(part)):
            out.append((u[i], float(chi2[i]), jtj[i], bool(ok[i]), part[i][2], part[i][3], part[i][1]))
    return out


def _cov_full(layout, jtj, idx, km):
    """Covariance of the full u vector (NaN off the free block)."""
    cov = np.full((layout.size + 1, layout.size + 1), np.nan)
    f = idx[km]
    blk = jtj[np.ix_(km, km)]
    try:
        inv = np.linalg.inv(blk)
    except np.linalg.LinAlgError:
        inv = np.linalg.pinv(blk)
    cov[np.ix_(f, f)] = inv
    return cov


def _binned_test(r, x, n_bins=_N_BINS):
    """Structure of whitened residuals ``r`` against covariate ``x``: (χ², dof, p, bin centres, means, sems)."""
    ok = np.isfinite(r) & np.isfinite(x)
    r, x = r[ok], x[ok]
    n = r.size
    nb = int(max(2, min(n_bins, n // 4)))
    ux = np.unique(x)
    if ux.size <= nb:  # categorical covariate (channel)
        bins = np.searchsorted(ux, x)
        nb = ux.size
    else:
        edges = np.quantile(x, np.linspace(0, 1, nb + 1))
        bins = np.clip(np.searchsorted(edges, x, side="right") - 1, 0, nb - 1)
    cnt = np.bincount(bins, minlength=nb).astype(float)
    s = np.bincount(bins, weights=r, minlength=nb)
    keep = cnt > 0
    mean = np.where(keep, s / np.maximum(cnt, 1), np.nan)
    xc = np.bincount(bins, weights=x, minlength=nb) / np.maximum(cnt, 1)
    chi2 = float(np.nansum(cnt[keep] * mean[keep] ** 2))
    dof = int(keep.sum())
    p = float(stats.chi2.sf(chi2, dof)) if dof > 0 else 1.0
    return chi2, dof, p, xc[keep], mean[keep], 1.0 / np.sqrt(cnt[keep])


def _lr_p(dchi2: float, e: Effect) -> float:
    if dchi2 <= 0:
        return 1.0
    k = e.k
    if any(p.sign for p in e.params):  # boundary mixture ½χ²_{k−1} + ½χ²_k
        lo = stats.chi2.sf(dchi2, k - 1) if k > 1 else 0.0
        return float(0.5 * lo + 0.5 * stats.chi2.sf(dchi2, k))
    return float(stats.chi2.sf(dchi2, k))


def _gap_p(chi2: float, dof: int) -> float:
    """``P(χ²_dof ≥ chi2)``: whether a gap still exceeds the noise level."""
    return float(stats.chi2.sf(chi2, dof))


def _flat(a, mask):
    a = np.asarray(a)
    return a[mask] if mask is not None else a.ravel()


def discover(
    model,
    data,
    *,
    effects: tuple[Effect, ...] | None = None,
    max_steps: int = 4,
    alpha: float = 0.01,
    min_explained: float = 0.5,
    structure_p: float = 1e-3,
    lm_steps: int = 60,
    chunk: int = 64,
    keep_plot_data: bool = True,
    seed: int = 0,
) -> DiscoveryReport:
    """Find, name and add the effects the data need beyond ``model``.

    Parameters
    ----------
    model
        A :class:`~wardjax.effects.ScanlineModel` or :class:`~wardjax.effects.ThresholdModel`
        (anything with ``kind``, ``base_params``, ``residuals``, ``predict``,
        ``covariates``, ``n_profiled``).
    data
        Its observations (:func:`~wardjax.effects.scanline_data`,
        :func:`~wardjax.effects.threshold_data`), with the noise σ.
    effects
        Candidate effects; default the library's effects for ``model.kind``.
    max_steps
        At most this many effects are added.
    alpha
        Family-wise level of the likelihood-ratio test, Bonferroni-corrected
        over the candidates of a step.
    min_explained
        A winner must remove at least this fraction of the current excess
        ``χ² − dof``, unless it leaves no significant gap (see the module
        docstring).
    structure_p
        Level (Bonferroni over covariates) below which residual structure is
        reported as unexplained.
    lm_steps, chunk
        Levenberg–Marquardt step cap; fits solved together in one batch.
    keep_plot_data
        Keep residuals and covariates (≤ 20,000 points) for the plots.
    seed
        Seeds the subsample kept for plots.

    Returns
    -------
    DiscoveryReport
        ``found`` (effect names, in order), ``gap`` (after each step, from the
        baseline), the steps with parameters ± σ and evidence, and the
        unexplained structure.
    """
    t0 = time.perf_counter()
    for attr in ("kind", "base_params", "residuals", "predict", "covariates", "n_profiled"):
        if not hasattr(model, attr):
            raise TypeError(f"model must provide {attr!r} (a ScanlineModel or ThresholdModel), got {type(model)!r}")
    if getattr(data, "kind", None) not in (("ratio", "brdf") if model.kind == "scanline" else ("threshold",)):
        raise TypeError(f"data of kind {getattr(data, 'kind', type(data))!r} do not suit a {model.kind} model")
    if not 0 < alpha < 1:
        raise ValueError(f"alpha must be in (0, 1), got {alpha}")
    lib = library(model.kind) if effects is None else tuple(effects)
    testable, skipped = [], []
    for e in lib:
        if e.model != model.kind:
            continue
        why = e.applicable(data)
        if why is None:
            testable.append(e)
        else:
            skipped.append((e.name, why, e.cancels_by_symmetry))
    testable = tuple(testable)
    base = model.base_params(data)
    layout = _Layout(base, testable)
    n_obs = int(data.n_obs)
    solo = n_obs >= _SOLO_MIN_OBS
    with jax.enable_x64(True):  # on the device once, not once per solve
        data_dev = jax.tree_util.tree_map(jnp.asarray, data)
    n_prof = int(model.n_profiled(data))
    ln_n = math.log(n_obs)
    k_pad = len(base) + max([len(e.params) for e in testable] + [0]) + 4
    rng = np.random.default_rng(seed)

    def refine(r, active=()):
        """Continue a fit that stopped at the step cap from where it stopped, up to ``_REFINE_ROUNDS`` times.

        Curved valleys (γ against ρd, ρs and α; a second lobe against the
        first) can take Levenberg–Marquardt more than ``lm_steps`` steps; a
        fit whose parameters are reported, or whose Δχ² decides, must have
        converged. The priors stay centred on the first start.
        """
        for _ in range(_REFINE_ROUNDS):
            u, chi2, _, ok, idx, km, anchor = r
            if ok or not np.isfinite(chi2):
                break
            job = (u, [int(j) for j in idx[km]], tuple(active), anchor)
            # the run's own batch width and mode: the compiled program is reused, not a new one for width 1
            r = _fit_batch([job], layout, model, testable, data_dev, k_pad, b_pad, lm_steps, chunk, solo)[0]
        return r

    # jobs: baseline multi-start over the model's own starting values
    u_init = layout.u_initial()
    base_free = layout.slices["model"]
    jobs = []
    b_starts: list[tuple[float, ...]] = [()]
    for p in base:
        vals = (p.init,) + tuple(v for v in p.starts if v != p.init)
        b_starts = [o + (v,) for o in b_starts for v in vals]
    for st in b_starts:
        u0 = u_init.copy()
        for j, v in zip(base_free, st):
            u0[j] = layout.entries[j][1].to_u(v)
        jobs.append((u0, base_free, ()))
    n_cand_jobs = sum(len(e.starts()) for e in testable)
    b_pad = max(len(jobs), n_cand_jobs, 1)
    res = _fit_batch(jobs, layout, model, testable, data_dev, k_pad, b_pad, lm_steps, chunk, solo)
    best = refine(min(res, key=lambda t: t[1] if np.isfinite(t[1]) else np.inf))

    def state_of(r, active):
        u, chi2, jtj, ok, idx, km, _ = r
        n_par = int(km.sum()) + n_prof + sum(testable[i].n_data_params for i in active)
        dof = max(n_obs - n_par, 1)
        cov = _cov_full(layout, jtj, idx, km)
        return FitState(u=u, chi2=chi2, dof=dof, gap=chi2 / dof, ok=ok, cov=cov, active=tuple(active),
                        values=layout.natural(u), sigma=layout.sigma(u, cov))

    cur = state_of(best, ())
    states = [cur]
    found: list[str] = []
    steps: list[Step] = []
    partial: list[Candidate] = []

    def residual_view(st: FitState):
        act = np.array([i in st.active for i in range(len(testable))], bool)
        with jax.enable_x64(True):  # the parameters too: outside, jnp.asarray would round them to float32
            r, pred, cens = _residual_view(jnp.asarray(st.u), jnp.asarray(act), data_dev, model=model,
                                           effects=testable, layout_key=layout.key)
        return np.asarray(r), np.asarray(pred), np.asarray(cens)

    mask = np.asarray(data.mask) if hasattr(data, "mask") else None
    r_cur, pred_cur, _ = residual_view(cur)
    covs_cur = model.covariates(data, pred_cur)
    pick = None
    n_flat = int(mask.sum()) if mask is not None else r_cur.size
    if keep_plot_data and n_flat > _PLOT_MAX:
        pick = np.sort(rng.choice(n_flat, _PLOT_MAX, replace=False))

    def view(a):
        v = _flat(a, mask)
        return v[pick] if pick is not None else v

    for _ in range(max_steps):
        remaining = [i for i in range(len(testable)) if i not in cur.active]
        if not remaining:
            break
        r_flat = _flat(r_cur.reshape(mask.shape) if mask is not None else r_cur, mask)
        cand_jobs, owner = [], []
        free_cur = base_free + [j for i in cur.active for j in layout.slices[testable[i].name]]
        for i in remaining:
            e = testable[i]
            for st in e.starts():
                u0 = cur.u.copy()
                for j, v in zip(layout.slices[e.name], st):
                    u0[j] = layout.entries[j][1].to_u(v)
                cand_jobs.append((u0, free_cur + layout.slices[e.name], cur.active + (i,)))
                owner.append(i)
        if len(free_cur) + 2 > k_pad:
            break
        structure_p_of = {}  # binned test per covariate: the residuals and covariates are fixed within a step
        res = _fit_batch(cand_jobs, layout, model, testable, data_dev, k_pad, b_pad, lm_steps, chunk, solo)
        m = len(remaining)

        def score(i, rs):
            """The candidate of effect ``i`` from its fits ``rs`` (best physical start), and that fit."""
            e = testable[i]
            sts = [state_of(r, cur.active + (i,)) for r in rs]
            phys = [k for k, st in enumerate(sts) if e.physical(st.values[e.name])]
            pool = phys or range(len(sts))
            k = min(pool, key=lambda k: sts[k].chi2) if sts else None
            cov_name = e.covariate
            sp = math.nan
            if cov_name in covs_cur:
                if cov_name not in structure_p_of:
                    structure_p_of[cov_name] = _binned_test(r_flat, _flat(covs_cur[cov_name], mask))[2]
                sp = structure_p_of[cov_name]
            if k is None:
                return Candidate(e.name, e.k, math.nan, -math.inf, 1.0, 0.0, sp, False, None, math.nan), None
            chosen = sts[k]
            dchi2 = max(cur.chi2 - chosen.chi2 if phys else 0.0, 0.0)
            excess = max(cur.chi2 - cur.dof, dchi2, 1e-300)
            return Candidate(
                effect=e.name, k=e.k, delta_chi2=dchi2, delta_bic=dchi2 - e.k * ln_n, p_value=_lr_p(dchi2, e),
                explained=dchi2 / excess, structure_p=sp, physical=bool(phys), state=chosen,
                gap_p_after=_gap_p(chosen.chi2, chosen.dof) if phys else _gap_p(cur.chi2, cur.dof),
            ), k

        fits = {i: [r for r, o in zip(res, owner) if o == i and np.isfinite(r[1])] for i in remaining}
        scored = {i: score(i, fits[i]) for i in remaining}
        # Fits stopped at the step cap are continued where they decide or are reported: the
        # winner, and runners-up whose ΔBIC (a lower bound then) already reaches half the winner's.
        refined: set[int] = set()
        while True:
            top = max(scored[i][0].delta_bic for i in remaining)
            todo = [i for i in remaining if i not in refined and scored[i][1] is not None
                    and not scored[i][0].state.ok
                    and (scored[i][0].delta_bic == top or scored[i][0].delta_bic >= _REFINE_BIC * top > 0)]
            if not todo:
                break
            for i in todo:
                k = scored[i][1]
                fits[i][k] = refine(fits[i][k], cur.active + (i,))
                scored[i] = score(i, fits[i])
                refined.add(i)
        cands = [scored[i][0] for i in remaining]
        by_effect = {i: scored[i][0].state for i in remaining if scored[i][1] is not None}
        cands.sort(key=lambda c: -c.delta_bic)
        win = cands[0]
        justified = win.delta_bic > 0 and win.p_value * m < alpha
        if not justified:
            break
        if win.explained < min_explained and win.gap_p_after < structure_p:
            partial.append(win)
            break
        i_win = next(i for i in remaining if testable[i].name == win.effect)
        new = by_effect[i_win]
        r_new, pred_new, _ = residual_view(new)
        e = testable[i_win]
        covs_new = model.covariates(data, pred_new)
        plot = None
        if keep_plot_data and e.covariate in covs_cur:
            plot = {
                "covariate": e.covariate,
                "x_before": view(covs_cur[e.covariate]), "r_before": view(r_cur.reshape(np.shape(pred_cur))),
                "x_after": view(covs_new[e.covariate]), "r_after": view(r_new.reshape(np.shape(pred_new))),
            }
        steps.append(Step(
            effect=e.name, title=e.title, side=e.side, params=new.values[e.name], stderr=new.sigma[e.name],
            evidence=win, candidates=cands, gap_before=cur.gap, gap_after=new.gap, plot=plot,
        ))
        found.append(e.name)
        cur, r_cur, pred_cur, covs_cur = new, r_new, pred_new, covs_new
        states.append(cur)

    # ---------------------------------------------------------------- unexplained structure
    r_flat = _flat(r_cur.reshape(np.shape(pred_cur)), mask)
    unexplained: list[str] = []
    structure: dict[str, dict] = {}
    z = (cur.chi2 - cur.dof) / math.sqrt(2 * cur.dof)
    p_gap = float(stats.norm.sf(z))
    n_cov = max(len(covs_cur), 1)
    for name, x in covs_cur.items():
        chi2, dof, p, xc, mean, sem = _binned_test(r_flat, _flat(x, mask))
        structure[name] = {"chi2": chi2, "dof": dof, "p": p,
                           "worst_bin": float(xc[np.argmax(np.abs(mean))]) if len(xc) else math.nan}
        if p < structure_p / n_cov:
            unexplained.append(
                f"unexplained discrepancy against {name} (binned χ² = {chi2:.1f} on {dof} bins, p = {p:.1e}; "
                f"largest near {name} = {structure[name]['worst_bin']:.3g})")
    if p_gap < structure_p:
        unexplained.insert(0, f"gap {cur.gap:.3f} exceeds the noise level (χ² = {cur.chi2:.1f} on {cur.dof} dof, "
                              f"p = {p_gap:.1e})")
    for c in partial:
        unexplained.append(f"{c.effect} is supported (ΔBIC = {c.delta_bic:.1f}) but explains only "
                           f"{100 * c.explained:.0f} % of the excess: a partial match, not named")

    return DiscoveryReport(
        model=getattr(model, "title", type(model).__name__), model_kind=model.kind, n_obs=n_obs,
        n_profiled=n_prof, baseline=states[0], final=cur, found=found, gap=[s.gap for s in states], steps=steps,
        unexplained=unexplained, structure=structure,
        not_detectable=[(n, w) for n, w, c in skipped if c], not_testable=[(n, w) for n, w, c in skipped if not c],
        partial=[c.effect for c in partial], tested=[e.name for e in testable], seconds=time.perf_counter() - t0,
        settings={"alpha": alpha, "min_explained": min_explained, "max_steps": max_steps, "criterion": "BIC+LR"},
    )
