"""Radial gains fitted on a held structure: the lobes, labels and normals of a fit kept, the gains refitted.

Once a model carries structure (a lobe per cluster, a normal per problem),
refitting it is the expensive part of discovery. A radial candidate
(:data:`~wardjax.effects._photo_model.RADIAL`) changes none of it, so it is
scored, and its hold-out read, with the structure of the current fit held:

.. math::

    f[p, v, c] = G(θ)[p, v]\\,\\bigl(q[p, v]\\,a[p, c] + κ\\,S[p, v]\\bigr)

with ``q`` the cosine factor and ``S`` the specular part of the current fit
(its lobes, labels and normals, :func:`wardjax.predict_pixels`), ``a = ρd/π``
per problem and channel and one scale ``κ ≥ 0`` of the specular part profiled
in closed form (variable projection, as :mod:`._photo_model`), and the
gains' parameters ``θ`` (every radial effect of the model, the candidate's
among them) fitted by :class:`optimistix.LevenbergMarquardt` in float64, in
coordinates ``u`` free of the gains' bounds, ``θ = m + h tanh u`` (``m``,
``h`` the middle and half-width of each bound), with σ from the Jacobian in
``θ`` at the solution. Holding the
structure can only raise χ², so the candidate's Δχ² read this way is a lower
bound of what a full refit gives: the evidence is conservative. The winner
of a step is then refitted in full once.
"""

from __future__ import annotations

import dataclasses
import functools
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx

from ._photo_model import RADIAL, PhotoData, SharedFit, _gain, _Geometry

__all__ = ["HeldStructure", "chi2_gains_held", "fit_gains_held"]

_MIN_GAIN = 1e-3


@dataclasses.dataclass(frozen=True, eq=False)
class HeldStructure:
    """``q`` and ``S`` ``(P, V)`` of a structural fit: what the gains multiply."""

    q: np.ndarray
    spec: np.ndarray

    @classmethod
    def of(cls, pixel, data: PhotoData) -> HeldStructure:
        """The structure of :func:`wardjax.fit_pixels`' result ``pixel`` on the views of ``data``."""
        from ..fit import predict_pixels

        zero = np.zeros_like(np.asarray(pixel.rho_d))
        spec = np.asarray(predict_pixels(dataclasses.replace(pixel, rho_d=zero), data.wi, data.wo))[..., 0]
        one = np.asarray(predict_pixels(dataclasses.replace(pixel, rho_d=np.full_like(zero, np.pi)), data.wi, data.wo))
        return cls(one[..., 0] - spec, spec)


class _Args(NamedTuple):
    f: jax.Array  # (P, V, C)
    w: jax.Array  # (P, V, C): the weights of the views fitted
    q: jax.Array  # (P, V)
    spec: jax.Array  # (P, V)
    geom: _Geometry
    mid: jax.Array  # (n,) the bounds' middles
    half: jax.Array  # (n,) the bounds' half-widths


def _residuals_jax(theta, names: tuple[str, ...], a: _Args, kappa=None):
    """``√w (f − G (q a + κ S))`` with ``a`` and, unless given, ``κ ≥ 0`` profiled (variable projection); and κ.

    A gain at or below :data:`_MIN_GAIN` where a view is seen is no gain: every residual is then 10⁶."""
    g = _gain(theta, names, a.geom)
    seen = jnp.any(a.w > 0, -1)
    bad = jnp.any(seen & (g <= _MIN_GAIN))
    gq, gs = (g * a.q)[..., None], (g * a.spec)[..., None]
    qq = jnp.sum(a.w * gq * gq, 1)
    inv = jnp.where(qq > 0, 1.0 / jnp.where(qq > 0, qq, 1.0), 0.0)
    f_t = a.f - gq * (jnp.sum(a.w * gq * a.f, 1) * inv)[:, None]
    s_t = gs - gq * (jnp.sum(a.w * gq * gs, 1) * inv)[:, None]
    if kappa is None:
        ss = jnp.sum(a.w * s_t * s_t)
        kappa = jnp.where(ss > 0, jnp.maximum(jnp.sum(a.w * f_t * s_t), 0.0) / jnp.where(ss > 0, ss, 1.0), 0.0)
    r = jnp.sqrt(a.w) * (f_t - kappa * s_t)
    return jnp.where(bad, 1e6, r), kappa


@functools.partial(jax.jit, static_argnames=("names",))
def _solve(u0, names: tuple[str, ...], a: _Args):
    """LM in the unbounded ``u``; returns ``θ``, the residuals and κ there, and ``∂r/∂θ``."""

    def theta_of(u):
        return a.mid + a.half * jnp.tanh(u)

    sol = optx.least_squares(
        lambda u, _: _residuals_jax(theta_of(u), names, a)[0].ravel(),
        optx.LevenbergMarquardt(rtol=1e-10, atol=1e-12),
        u0,
        max_steps=256,
        throw=False,
    )
    theta = theta_of(sol.value)
    r, kappa = _residuals_jax(theta, names, a)
    jac = jax.jacfwd(lambda t: _residuals_jax(t, names, a)[0].ravel())(theta)
    return theta, r, kappa, jac


def _args(data: PhotoData, held: HeldStructure, keep, names: tuple[str, ...]) -> _Args:
    lo = np.array([b[0] for n in names for b in RADIAL[n].bounds], float)
    hi = np.array([b[1] for n in names for b in RADIAL[n].bounds], float)
    f64 = functools.partial(jnp.asarray, dtype=jnp.float64)
    return _Args(
        f64(data.f),
        f64(data.w * keep[..., None]),
        f64(held.q),
        f64(held.spec),
        _Geometry(f64(data.radius2), f64(data.lamp_cos)),
        f64((lo + hi) / 2),
        f64((hi - lo) / 2),
    )


def _split(theta, names) -> dict[str, tuple[float, ...]]:
    out, i = {}, 0
    for n in names:
        k = len(RADIAL[n].params)
        out[n] = tuple(float(v) for v in theta[i : i + k])
        i += k
    return out


def fit_gains_held(
    names: tuple[str, ...],
    data: PhotoData,
    held: HeldStructure,
    base: SharedFit,
    keep: np.ndarray | None = None,
    n_structure: int = 0,
) -> SharedFit:
    """The radial gains ``names`` on the held structure, fitted to the views ``keep (P, V)``.

    ``base``: the current fit, whose gains start this one (a new gain starts at 0, no effect) and whose α is
    kept; ``n_structure``: the structure's parameters (lobes, normals), counted in the dof.
    """
    keep = np.ones(data.radius2.shape, bool) if keep is None else keep
    theta0 = np.array([v for n in names for v in (base.effects.get(n) or (0.0,) * len(RADIAL[n].params))], float)
    with jax.enable_x64(True):
        a = _args(data, held, keep, names)
        if names:
            mid, half = np.asarray(a.mid), np.asarray(a.half)
            u0 = np.arctanh(np.clip((theta0 - mid) / half, -1 + 1e-9, 1 - 1e-9))
            theta, r, kappa, jac = (np.asarray(v) for v in _solve(jnp.asarray(u0), names, a))
            x = theta
        else:
            x, jac = np.zeros(0), np.zeros((1, 0))
            r, kappa = (np.asarray(v) for v in _residuals_jax(jnp.zeros(0), (), a))
    w = data.w * keep[..., None]
    n_obs = int(np.sum(w > 0))
    n_rho = int(np.sum(w.sum(1) > 0))
    dof = max(n_obs - n_rho - 1 - n_structure - len(x), 1)
    try:
        sd = np.sqrt(np.clip(np.diag(np.linalg.inv(jac.T @ jac)), 0, None)) if len(x) else x
    except np.linalg.LinAlgError:
        sd = np.full(len(x), np.nan)
    return SharedFit(
        float(np.sum(r**2)),
        dof,
        base.alpha,
        float(kappa),
        _split(x, names),
        _split(sd, names),
        base.alpha_sigma,
        np.concatenate([[np.log(base.alpha)], x]),
    )


def chi2_gains_held(fit: SharedFit, names, data: PhotoData, held: HeldStructure, keep: np.ndarray) -> float:
    """χ² of the views ``keep`` with ``fit``'s gains and ``κ`` held, ρd profiled on them."""
    theta = np.asarray([v for n in names for v in fit.effects[n]], float)
    with jax.enable_x64(True):
        r, _ = _residuals_jax(jnp.asarray(theta), tuple(names), _args(data, held, keep, tuple(names)), kappa=fit.rho_s)
        return float(jnp.sum(r**2))
