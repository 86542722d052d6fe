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
among them) fitted by :func:`scipy.optimize.least_squares`. Holding the
structure can only raise χ², so the candidate's Δχ² read this way is a lower
bound of what a full refit gives: the evidence is conservative. The winner
of a step is then refitted in full once.
"""

from __future__ import annotations

import dataclasses
import functools

import numpy as np

from ._photo_model import RADIAL, PhotoData, SharedFit, gains

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


def _residuals(theta, names, data: PhotoData, held: HeldStructure, keep, kappa=None):
    """``√w (f − G (q a + κ S))`` with ``a`` and, unless given, ``κ ≥ 0`` profiled; and ``κ``."""
    g = gains(data, {n: t for n, t in _split(theta, names).items()})
    w = data.w * keep[..., None]
    seen = np.any(w > 0, -1)
    if np.any(g[seen] <= _MIN_GAIN):
        return np.full(data.f.shape, 1e6), 0.0
    gq, gs = (g * held.q)[..., None], (g * held.spec)[..., None]
    qq = np.sum(w * gq * gq, 1)
    inv = np.where(qq > 0, 1.0 / np.where(qq > 0, qq, 1.0), 0.0)
    f_t = data.f - gq * (np.sum(w * gq * data.f, 1) * inv)[:, None]
    s_t = gs - gq * (np.sum(w * gq * gs, 1) * inv)[:, None]
    if kappa is None:
        ss = float(np.sum(w * s_t * s_t))
        kappa = max(float(np.sum(w * f_t * s_t)), 0.0) / ss if ss > 0 else 0.0
    return np.sqrt(w) * (f_t - kappa * s_t), kappa


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
    from scipy.optimize import least_squares

    keep = np.ones(data.radius2.shape, bool) if keep is None else keep
    theta0 = [v for n in names for v in (base.effects.get(n) or (0.0,) * len(RADIAL[n].params))]
    lo = [b[0] for n in names for b in RADIAL[n].bounds]
    hi = [b[1] for n in names for b in RADIAL[n].bounds]
    res = functools.partial(_residuals, names=names, data=data, held=held, keep=keep)
    if names:
        x0 = np.clip(np.asarray(theta0, float), np.add(lo, 1e-9), np.subtract(hi, 1e-9))
        sol = least_squares(lambda t: res(t)[0].ravel(), x0, bounds=(lo, hi), method="trf")
        x, jac = sol.x, sol.jac
    else:
        x, jac = np.zeros(0), np.zeros((1, 0))
    r, kappa = res(x)
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
    r, _ = _residuals(theta, names, data, held, keep, kappa=fit.rho_s)
    return float(np.sum(r**2))
