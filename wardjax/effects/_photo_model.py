"""A photograph capture's data for discovery, and the paper's model with radial gains fitted by variable projection.

Every problem ``p`` (a pixel, or a block of pixels that share ρd, as
:func:`wardjax.fit_pixels` fits them) holds ``V`` views ``v`` (its pixels in
each photo) of ``C`` channels. The baseline is the image-based paper's model
on a flat sample, one lobe shared by the sample and ρd per problem:

.. math::

    f[p, v, c] = G(φ)[p, v]\\,\\bigl(a[p, c] + s\\,L_α[p, v]\\bigr),\\qquad
    a = ρ_d/π,\\quad L_α = N(ω_i, ω_o)\\,\\frac{e^{-\\tan^2 δ/α^2}}{α^2}

(Ward 1992, the paper's eq. "f_r,Ward", ``N`` the normalisation of
:func:`wardjax.ward.ward_geometry`), with ``G = 1`` in the baseline and
``G`` the product of the radial gains of :data:`RADIAL` that discovery adds:

* ``vignetting``: the lens's falloff, ``G = 1 + a₁ r² + a₂ r⁴`` with ``r``
  the tangent of the angle between the pixel's ray and the camera's axis,
  divided by its largest value over the pixels fitted (the even polynomial
  of Goldman 2010, eq. 5, as the flat-field fit of
  :func:`wardjax.capture.fit_vignetting`);
* ``flash_falloff``: the lamp's emission ``G = cos^n ψ``, ``ψ`` the angle
  between the lamp's axis (parallel to the camera's: a flash on the camera
  body points where the lens points) and the direction to the point.

Given ``α`` and the gains the model is linear in ``a`` (per problem and
channel) and ``s = ρs``: dividing the data by ``G`` (``f/G``, weights
``w G²``) leaves the baseline's least-squares problem, whose ``a`` and ``s``
follow in closed form (variable projection, Golub & Pereyra 1973;
``s ≥ 0``). ``log α`` and the gains' parameters ``x`` are fitted by
:class:`optimistix.LevenbergMarquardt` on the projected residuals, in float64,
in coordinates ``u`` free of their bounds, ``x = m + h tanh u`` (``m``, ``h``
the middle and half-width of each bound), from the best ``log α`` of a grid
(or a fit made before); their covariance is ``(JᵀJ)⁻¹``, ``J = ∂r/∂x`` at the
solution (:func:`jax.jacfwd` of the residuals, in the same compiled program as
the LM loop; the starting grid is evaluated on the host, in NumPy). Each step's
damped system is solved by its normal equations (a Cholesky factor of
``JᵀJ + λI``, at most 4 × 4: a smaller program than a QR of ``J``). One compiled program
serves every set of gains (those not fitted held at 0, no gain) and every
capture of a size bucket: the problems and views are padded with unweighted ones
to the next size of :func:`wardjax._shapes.bucket`.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from collections.abc import Callable
from typing import NamedTuple

import jax
import jax.numpy as jnp
import lineax as lx
import numpy as np
import optimistix as optx

from .._shapes import bucket
from ..ward import ward_geometry

__all__ = [
    "BOUNDED",
    "RADIAL",
    "PhotoData",
    "RadialEffect",
    "SharedFit",
    "chi2_held",
    "fit_shared",
    "gains",
    "photo_covariates",
    "shared_residuals",
    "shared_rho_d",
]

_LOG_ALPHA = (math.log(1e-3), math.log(2.0))  # α searched within [1e-3, 2], as wj.fit_pixels
_GRID = np.linspace(math.log(0.005), 0.0, 15)  # starting log α
_MIN_GAIN = 1e-3  # a gain at or below this on a fitted view is no lens or lamp
BOUNDED = {"alpha": 1.0, "rho_s": 1.0}  # the largest α and ρs of a lobe held within what a material has


@dataclasses.dataclass(frozen=True, eq=False)
class PhotoData:
    """A photograph capture as discovery reads it.

    Attributes
    ----------
    f, w
        ``(P, V, C)`` BRDF estimates (sr⁻¹) and their weights ``1/σ²`` (0 where unusable).
    wi, wo
        ``(P, V, 3)`` unit directions to the lamp and to the camera, sample frame.
    radius2
        ``(P, V)`` ``r²`` of the vignetting (1 at the farthest pixel fitted).
    lamp_cos
        ``(P, V)`` ``cos ψ`` of the flash falloff.
    column
        ``(P,)`` each problem's position across the image, 0 (left) to 1 (right): the hold-out's halves.
    fold
        ``(P, V)`` 0 or 1: the views' halves within each problem (photos alternate, pixels of a block
        alternate as a checkerboard), for effects with parameters per problem.
    grid
        ``(rows, columns, block)``: the problems tile the image as ``rows × columns`` blocks of
        ``block × block`` pixels, row-major.
    lamp_offset
        The lamp's distance from the lens over the camera's distance to the sample (largest over the photos).
    normalization
        The Ward normalisation fitted.
    """

    f: np.ndarray
    w: np.ndarray
    wi: np.ndarray
    wo: np.ndarray
    radius2: np.ndarray
    lamp_cos: np.ndarray
    column: np.ndarray
    fold: np.ndarray
    grid: tuple[int, int, int]
    lamp_offset: float
    normalization: str = "ward1992"

    @functools.cached_property
    def lobe_geometry(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``u``, ``v`` (``h_x²/h_z²``, ``h_y²/h_z²``) and the normalisation ``N``, ``(P, V)`` each."""
        import jax

        with jax.enable_x64(True):  # float64 for fitting, scoped (the user's setting is left alone)
            geo = jax.jit(ward_geometry, static_argnames="normalization")(self.wi, self.wo, self.normalization)
            return tuple(np.asarray(a, np.float64) for a in (geo.u, geo.v, geo.g))  # pyright: ignore[reportReturnType]

    @property
    def n_obs(self) -> int:
        return int(np.sum(self.w > 0))

    @property
    def n_channels(self) -> int:
        return int(self.f.shape[-1])

    @property
    def n_photos(self) -> int:
        """``K``: each problem's views are its ``block²`` pixels in each of ``K`` photos."""
        return max(int(self.f.shape[1]) // (self.grid[2] ** 2), 1)


def _meet(points: np.ndarray, dirs: np.ndarray) -> np.ndarray:
    """``(3,)`` the point nearest (least squares) to the lines ``points + t·dirs`` (``(N, 3)`` each)."""
    d = dirs / np.linalg.norm(dirs, axis=-1, keepdims=True)
    proj = np.eye(3)[None] - d[:, :, None] * d[:, None, :]
    return np.linalg.solve(proj.sum(0), np.einsum("nij,nj->i", proj, points))


def photo_covariates(
    points: np.ndarray, wi: np.ndarray, wo: np.ndarray, mask: np.ndarray, target: np.ndarray
) -> tuple[np.ndarray, np.ndarray, float]:
    """The radial effects' covariates of ``K`` photos: ``r²`` and ``cos ψ`` ``(H, W, K)``, and the lamp's offset.

    ``points (H, W, 3)`` the pixels' sample points; ``wi``, ``wo`` ``(H, W, K, 3)``; ``mask (H, W, K)``;
    ``target (3,)`` the point the camera looks at. Each photo's camera and lamp are where its pixels'
    rays to them meet.
    """
    k = wi.shape[2]
    r2 = np.zeros(mask.shape)
    cos_psi = np.ones(mask.shape)
    offset = 0.0
    for j in range(k):
        m = mask[:, :, j] if mask[:, :, j].sum() >= 3 else np.ones(mask.shape[:2], bool)
        cam = _meet(points[m], wo[:, :, j][m])
        lamp = _meet(points[m], wi[:, :, j][m])
        axis = (target - cam) / np.linalg.norm(target - cam)
        ray = points - cam
        along = ray @ axis
        tan2 = np.maximum(np.sum(ray * ray, -1) / along**2 - 1.0, 0.0)
        r2[:, :, j] = tan2
        to_point = points - lamp
        cos_psi[:, :, j] = (to_point @ axis) / np.linalg.norm(to_point, axis=-1)
        offset = max(offset, float(np.linalg.norm(lamp - cam) / np.linalg.norm(target - cam)))
    top = float(np.max(r2[mask])) if mask.any() else 1.0
    return r2 / max(top, 1e-12), cos_psi, offset


class RadialEffect(NamedTuple):
    """A multiplicative gain on every view: ``gain(θ, data) → (P, V)``, 1 at ``θ = 0``."""

    name: str
    title: str
    params: tuple[str, ...]
    bounds: tuple[tuple[float, float], ...]
    gain: Callable[[np.ndarray, PhotoData], np.ndarray]


RADIAL = {
    "vignetting": RadialEffect(
        "vignetting",
        "lens falloff (vignetting), 1 + a₁ r² + a₂ r⁴",
        ("a1", "a2"),
        ((-3.0, 3.0), (-3.0, 3.0)),
        lambda t, d: 1.0 + d.radius2 * (t[0] + t[1] * d.radius2),
    ),
    "flash_falloff": RadialEffect(
        "flash_falloff",
        "the lamp's angular falloff, cos^n ψ",
        ("n",),
        ((-10.0, 20.0),),
        lambda t, d: d.lamp_cos.clip(1e-6) ** t[0],  # a method NumPy and JAX arrays share (_photo_held)
    ),
}


class SharedFit(NamedTuple):
    """The shared-lobe model with radial gains, fitted: χ² and dof, the lobe, the gains' parameters ± σ."""

    chi2: float
    dof: int
    alpha: float
    rho_s: float
    effects: dict[str, tuple[float, ...]]
    sigma: dict[str, tuple[float, ...]]
    alpha_sigma: float
    x: np.ndarray


_Arr = jax.Array | np.ndarray | np.floating


class _Geometry(NamedTuple):
    """What a radial gain reads (``RadialEffect.gain(θ, d)``), ``(P, V)`` JAX or NumPy arrays."""

    radius2: _Arr
    lamp_cos: _Arr


class _Args(NamedTuple):
    """A fit's data as float64 arrays (NumPy, or JAX inside the fit): ``f``, ``w`` ``(P, V, C)`` (``w`` 0
    on views not fitted), the lobe's ``u``, ``v``, ``N`` and the gains' covariates ``(P, V)``, the bounds'
    middles and half-widths ``(1 + n,)`` (``log α`` first), and the largest ρs."""

    f: _Arr
    w: _Arr
    u: _Arr
    v: _Arr
    n: _Arr
    geom: _Geometry
    mid: _Arr
    half: _Arr
    s_max: _Arr


_ALL = tuple(RADIAL)  # every gain: one compiled fit serves each set of them, the others held at 0 (no gain)


def _layout(names: tuple[str, ...]) -> np.ndarray:
    """The places in ``x = (log α, every gain's parameters in the order of RADIAL)`` of ``(log α, names' …)``."""
    start = dict(zip(_ALL, np.cumsum([1] + [len(RADIAL[n].params) for n in _ALL])))
    return np.array([0] + [int(start[n]) + i for n in names for i in range(len(RADIAL[n].params))], int)


def _args(data: PhotoData, keep: np.ndarray, bounded: bool = False, pad: bool = False) -> _Args:
    """:class:`_Args` of the views ``keep (P, V)``; ``pad``: problems and views padded to their
    :func:`~wardjax._shapes.bucket` with unweighted views (gain 1, a lobe of 0), which change no residual."""
    top, s_max = (math.log(BOUNDED["alpha"]), BOUNDED["rho_s"]) if bounded else (_LOG_ALPHA[1], math.inf)
    lo = np.array([_LOG_ALPHA[0]] + [b[0] for n in _ALL for b in RADIAL[n].bounds])
    hi = np.array([top] + [b[1] for n in _ALL for b in RADIAL[n].bounds])
    p, v = data.radius2.shape
    shape = (bucket(p), bucket(v)) if pad else (p, v)

    def put(a, fill=0.0):
        out = np.full(shape + a.shape[2:], fill)
        out[:p, :v] = a
        return out

    u, vv, n = data.lobe_geometry
    return _Args(
        put(data.f),
        put(data.w * keep[..., None]),
        put(u),
        put(vv),
        put(n),
        _Geometry(put(data.radius2), put(data.lamp_cos, 1.0)),
        (lo + hi) / 2,
        (hi - lo) / 2,
        np.float64(s_max),
    )


def _gain(theta, names: tuple[str, ...], geom):
    """``(P, V)`` the product of the gains ``names`` at their parameters ``theta`` (NumPy or JAX, as given)."""
    g, i = geom.radius2 * 0.0 + 1.0, 0
    for n in names:
        k = len(RADIAL[n].params)
        g = g * RADIAL[n].gain(theta[i : i + k], geom)
        i += k
    return g


def _residuals(x, a: _Args, s=None, xp=jnp):
    """``√w (f/G − a − s L)`` (weights ``w G²``) at ``x = (log α, every gain's parameters)``, with ``a`` per
    problem and channel and, unless given, ``0 ≤ s ≤ s_max`` profiled; and ``s``. A gain at or below
    :data:`_MIN_GAIN` on a seen view is no lens or lamp: every residual is then 10⁶. ``xp``: ``jax.numpy``
    (traced into the fit) or ``numpy`` (the grid, the Jacobian and the checks, on the host)."""
    g = _gain(x[1:], _ALL, a.geom)
    bad = xp.any(xp.any(a.w > 0, -1) & (g <= _MIN_GAIN))
    g = xp.where(g > _MIN_GAIN, g, 1.0)[..., None]
    f, w = a.f / g, a.w * g * g
    a2 = xp.exp(2.0 * x[0])
    lobe = (a.n * xp.exp(-(a.u + a.v) / a2) / a2)[..., None]
    s0 = w.sum(1)
    inv = xp.where(s0 > 0, 1.0 / xp.where(s0 > 0, s0, 1.0), 0.0)
    ft = f - ((w * f).sum(1) * inv)[:, None]
    lt = lobe - ((w * lobe).sum(1) * inv)[:, None]
    if s is None:
        bb = xp.sum(w * lt * lt)
        s = xp.minimum(xp.where(bb > 0, xp.maximum(xp.sum(w * ft * lt), 0.0) / xp.where(bb > 0, bb, 1.0), 0.0), a.s_max)
    return xp.where(bad, 1e6, xp.sqrt(a.w) * g * (ft - s * lt)), s  # √(w G²), differentiable where w = 0


@jax.jit
def _solve(x0, free, a: _Args):
    """LM in the unbounded ``u`` from ``x0``, the parameters not ``free`` held at 0; returns ``x`` and
    ``∂r/∂x`` there ``(M, len(x))`` (forward-mode autodiff; the padded views' rows are 0)."""

    def x_of(u):
        return jnp.where(free, a.mid + a.half * jnp.tanh(u), 0.0)

    sol = optx.least_squares(
        lambda u, _: _residuals(x_of(u), a)[0].ravel(),
        optx.LevenbergMarquardt(rtol=1e-10, atol=1e-12, linear_solver=lx.Normal(lx.Cholesky())),
        jnp.arctanh(jnp.clip((x0 - a.mid) / a.half, -1 + 1e-9, 1 - 1e-9)),
        max_steps=256,
        throw=False,
    )
    x = x_of(sol.value)
    return x, jax.jacfwd(lambda y: _residuals(y, a)[0].ravel())(x)


def _split(x: np.ndarray, names: tuple[str, ...]) -> dict[str, np.ndarray]:
    out, i = {}, 1
    for n in names:
        k = len(RADIAL[n].params)
        out[n] = x[i : i + k]
        i += k
    return out


def fit_shared(
    data: PhotoData,
    names: tuple[str, ...] = (),
    keep: np.ndarray | None = None,
    start: SharedFit | None = None,
    bounded: bool = False,
) -> SharedFit:
    """Fit the shared lobe and the radial gains ``names`` to the views ``keep (P, V)`` (default all).

    ``start``: a fit made before, whose α and gains start this one (other gains start at 0, no effect);
    without it α starts from the best of a grid. ``bounded``: the lobe held within what a material has,
    ``α ≤ 1`` and ``ρs ≤ 1`` (:data:`BOUNDED`).
    """
    keep = np.ones(data.radius2.shape, bool) if keep is None else keep
    before = {} if start is None else start.effects
    at = _layout(tuple(names))
    x0 = np.zeros(_layout(_ALL).size)
    x0[at] = [0.0 if start is None else math.log(start.alpha)] + [
        v for n in names for v in (before.get(n) or (0.0,) * len(RADIAL[n].params))
    ]
    free = np.zeros(x0.size, bool)
    free[at] = True
    a = _args(data, keep, bounded)
    if start is None:  # log α from the best of a grid
        x0[0] = _GRID[int(np.argmin([np.sum(_residuals(np.r_[t, x0[1:]], a, xp=np)[0] ** 2) for t in _GRID]))]
    with jax.enable_x64(True):  # float64 for fitting, scoped (the user's setting is left alone)
        padded = jax.tree.map(jnp.asarray, _args(data, keep, bounded, pad=True))
        x, jac = (np.asarray(v) for v in _solve(jnp.asarray(x0), jnp.asarray(free), padded))
    r, s = _residuals(x, a, xp=np)
    x, jac = x[at], jac[:, at]
    chi2 = float(np.sum(r**2))
    w = data.w * keep[..., None]
    n_obs = int(np.sum(w > 0))
    n_rho = int(np.sum(w.sum(1) > 0))
    dof = max(n_obs - n_rho - 2 - (len(x) - 1), 1)
    try:
        sd = np.sqrt(np.clip(np.diag(np.linalg.inv(jac.T @ jac)), 0, None))
    except np.linalg.LinAlgError:
        sd = np.full(len(x), np.nan)
    effects = {n: tuple(float(v) for v in t) for n, t in _split(x, names).items()}
    sigma = {n: tuple(float(v) for v in t) for n, t in _split(sd, names).items()}
    alpha = math.exp(float(x[0]))
    return SharedFit(chi2, dof, alpha, float(s), effects, sigma, alpha * float(sd[0]), x)


def _residuals_at(data: PhotoData, fit: SharedFit, names: tuple[str, ...], keep: np.ndarray) -> np.ndarray:
    x = np.zeros(_layout(_ALL).size)
    x[_layout(tuple(names))] = fit.x
    return _residuals(x, _args(data, keep), s=fit.rho_s, xp=np)[0]


def chi2_held(data: PhotoData, fit: SharedFit, names: tuple[str, ...], keep: np.ndarray) -> float:
    """χ² of the views ``keep`` with ``fit``'s lobe and gains held, ρd profiled on them."""
    return float(np.sum(_residuals_at(data, fit, names, keep) ** 2))


def gains(data: PhotoData, effects: dict[str, tuple[float, ...]]) -> np.ndarray:
    """``(P, V)`` the product of the fitted radial gains (1 without any)."""
    names = tuple(effects)
    x = np.array([0.0, *(v for n in names for v in effects[n])])
    return np.asarray(_gain(x[1:], names, data))


def shared_residuals(data: PhotoData, fit: SharedFit, names: tuple[str, ...]) -> np.ndarray:
    """``(P, V, C)`` the weighted residuals ``√w (f − G (a + s L))`` of ``fit`` on every view (ρd profiled)."""
    return _residuals_at(data, fit, names, np.ones(data.radius2.shape, bool))


def shared_rho_d(data: PhotoData, fit: SharedFit, names: tuple[str, ...]) -> np.ndarray:
    """``(P, C)`` each problem's ρd under ``fit`` (``π a``, ``a`` the weighted mean of ``f/G − s L``; NaN unseen)."""
    g = np.asarray(_gain(np.asarray(fit.x[1:]), tuple(names), data))[..., None]
    w = data.w * g * g
    u, v, n = data.lobe_geometry
    a2 = math.exp(2.0 * float(fit.x[0]))
    lobe = (n * np.exp(-(u + v) / a2) / a2)[..., None]
    sw = w.sum(1)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(sw > 0, np.pi * np.sum(w * (data.f / g - fit.rho_s * lobe), 1) / sw, np.nan)
