"""Batched, jitted Levenberg–Marquardt fits of a model plus candidate effects.

The parameters of the model and of every testable effect live in one flat
vector (:class:`_Layout`); a fit frees a subset of it and switches a subset of
the effects on. :func:`_fit_batch` solves many such fits with one compiled
program, which is what makes fitting every candidate from several starts
affordable in ``discover``.
"""

from __future__ import annotations

import functools
import math

import jax
import jax.numpy as jnp
import lineax as lx
import numpy as np
import optimistix as optx

from . import _exported
from ._effect import Effect, Param

_LINEAR_SOLVER = lx.QR()
# Levenberg–Marquardt's stopping rule (relative, absolute) on every parameter and every residual; passed to the
# compiled program as data, so another rule would not trace a new program
TOL = (1e-6, 1e-8)


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


@functools.partial(jax.custom_jvp, nondiff_argnums=(0,))
def _materialised(f, z, args):
    """``f(z, args)``, whose linearisation in ``z`` is its Jacobian as a matrix ``(M, K)``: ``J dz``.

    Levenberg–Marquardt (optimistix) keeps the linearisation of the residuals
    in its loop state and copies it in every step's accept/reject branch.
    Linearised by JAX, it holds what the tangents read: the texture's whitening
    ``W`` (tens of MB, a constant of the fit) and the model's intermediates;
    here it holds ``J``, computed with the residuals (:func:`jax.jacfwd`, ``K``
    tangents over the primal's evaluation, as the solver's QR took them from the
    linearisation before). ``args`` is data: its tangents are not propagated.
    """
    return f(z, args)


@_materialised.defjvp
def _materialised_jvp(f, primals, tangents):
    z, args = primals
    dz, _ = tangents
    jac, r = jax.jacfwd(lambda x: (f(x, args),) * 2, has_aux=True)(z)
    return r, jac @ dz


def _data_residuals(z, args, *, model, effects, layout_key):
    """The whitened residuals ``(M,)`` with ``u[idx] = z`` where ``kmask`` (``args``: ``u0, idx, kmask, active, data,
    ctx``)."""
    u0, idx, kmask, active, data, ctx = args
    u = u0.at[idx].set(jnp.where(kmask, z, u0[idx]))
    vals = _unpack(layout_key, u, tuple(e.name for e in effects))
    act = {e.name: active[i] for i, e in enumerate(effects)}
    return model.residuals(vals, act, effects, data, ctx)


@functools.partial(jax.jit, static_argnames=("model", "effects", "layout_key", "max_steps"))
def _solve_batch(u0, a0, idx, kmask, active, prior_w, tol, data, *, model, effects, layout_key, max_steps):
    ctx = model.context(data) if hasattr(model, "context") else None
    f = functools.partial(_data_residuals, model=model, effects=effects, layout_key=layout_key)

    def one(u0, a0, idx, kmask, active):
        pw = jnp.where(kmask, prior_w[idx], 0.0)
        z0 = a0[idx]  # the priors' centres: the starting values, kept when a fit is continued
        args = (u0, idx, kmask, active, data, ctx)
        n_data = jax.eval_shape(f, u0[idx], args).shape[0]

        def resid(z, _):
            return jnp.concatenate([_materialised(f, z, args), pw * (z - z0)])

        # the tolerances are data (``tol``: rtol, atol): another rule would not trace a new program
        solver = optx.LevenbergMarquardt(rtol=tol[0], atol=tol[1], linear_solver=_LINEAR_SOLVER)
        sol = optx.least_squares(resid, solver, u0[idx], max_steps=max_steps, throw=False)
        z = sol.value
        # the residuals and the Jacobian at the solution are the solver's last accepted linearisation
        # (``f_info``: the data's rows, then the priors'), not evaluated again: the model stays one copy in the program
        info = sol.state.f_info
        r = info.residual[:n_data]
        chi2 = jnp.sum(r * r)
        jac = info.jac.as_matrix()[:n_data]
        jtj = jac.T @ jac
        ok = (sol.result == optx.RESULTS.successful) & jnp.isfinite(chi2)
        u = u0.at[idx].set(jnp.where(kmask, z, u0[idx]))
        return u, chi2, jtj, ok, sol.stats["num_steps"]

    if u0.shape[0] == 1:
        # one fit (solo mode): not vmapped, so the effects' flags stay unbatched and each inactive effect's
        # ``lax.cond`` skips it (under vmap a batched flag evaluates both branches)
        return jax.tree_util.tree_map(lambda a: a[None], one(u0[0], a0[0], idx[0], kmask[0], active[0]))
    return jax.vmap(one)(u0, a0, idx, kmask, active)


@functools.partial(jax.jit, static_argnames=("model", "effects", "layout_key"))
def _residual_view(u, active, data, *, model, effects, layout_key):
    """Whitened residuals of the values (flat), prediction, profiled ρd and the scanline levels' χ², in one program.

    Run eagerly, the model's few dozen operations would each compile on their
    own (~76 small programs, ~3 s, per process and data shape).
    """
    names = tuple(e.name for e in effects)
    vals = _unpack(layout_key, u, names)
    act = {e.name: active[i] for i, e in enumerate(effects)}
    if hasattr(model, "evaluate"):  # residuals and prediction from one evaluation: one copy of the model to compile
        r, pred, rho = model.evaluate(vals, act, effects, data)
    else:
        pred, rho, _ = model.predict(vals, act, effects, data)
        r = model.residuals(vals, act, effects, data)
    # r: the values', then the scanline levels'
    return r[: pred.size], pred, rho, jnp.sum(r[pred.size :] ** 2)


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
    """One ``_solve_batch`` call on stacked rows, dispatched: device arrays back, not yet waited for.

    JAX dispatches asynchronously, so a caller that dispatches several calls
    before reading any lets the runtime execute them side by side (on CPU,
    on more than one core).
    """
    U0, A0, IDX, KM, A = (np.stack(col) for col in zip(*rows))
    static = dict(model=model, effects=effects, layout_key=layout.key, max_steps=max_steps)
    with jax.enable_x64(True):
        args = tuple(jnp.asarray(x) for x in (U0, A0, IDX, KM, A, layout.prior_w, np.asarray(TOL, float))) + (data,)
        fn = functools.partial(_solve_batch, **static)
        u, chi2, jtj, ok, _ = _exported.call("lm", fn, static_key(static), args)
    return u, chi2, jtj, ok


def static_key(static: dict) -> tuple:
    """What names a traced program's static arguments on disk (:mod:`wardjax.effects._exported`): the model, each
    effect's class, name and parameters (the effects hash by class and name), the layout, the step cap."""
    out = []
    for k, v in sorted(static.items()):
        if k == "effects":
            v = tuple((type(e).__module__, type(e).__qualname__, e.name, e.params) for e in v)
        out.append((k, v))
    return tuple(out)


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
    calls = []
    for c0 in range(0, len(rows), chunk):  # every call dispatched before any is read: they may run side by side
        part = rows[c0 : c0 + chunk]
        pad = part + [part[0]] * (width - len(part)) if len(part) < width else part
        calls.append((part, _solve_rows(pad, layout, model, effects, data, max_steps)))
    out = []
    for part, dev in calls:
        u, chi2, jtj, ok = (np.asarray(x) for x in dev)
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
