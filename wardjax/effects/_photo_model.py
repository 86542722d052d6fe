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
``s ≥ 0``). ``log α`` and the gains' parameters are fitted by
:func:`scipy.optimize.least_squares` on the projected residuals; their
covariance is ``(JᵀJ)⁻¹`` of that fit.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from collections.abc import Callable
from typing import NamedTuple

import numpy as np

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


def _gain(data: PhotoData, effects: dict[str, np.ndarray]) -> np.ndarray:
    g = np.ones(data.radius2.shape)
    for name, t in effects.items():
        g = g * RADIAL[name].gain(np.asarray(t), data)
    return g


def _lobe(data: PhotoData, geom, log_alpha: float) -> np.ndarray:
    u, v, n = geom
    a2 = math.exp(2.0 * log_alpha)
    return n * np.exp(-(u + v) / a2) / a2


def _projected(f, w, lobe, s=None, s_max=math.inf):
    """Residuals ``√w (f − a − s L)`` with ``a`` (per problem and channel) and, unless given, ``0 ≤ s ≤ s_max``
    profiled."""
    s0 = w.sum(1)
    ok = s0 > 0
    inv = np.where(ok, 1.0 / np.where(ok, s0, 1.0), 0.0)
    fm = (w * f).sum(1) * inv
    lm = (w * lobe[..., None]).sum(1) * inv
    ft = f - fm[:, None]
    lt = lobe[..., None] - lm[:, None]
    if s is None:
        bb = float(np.sum(w * lt * lt))
        s = min(max(float(np.sum(w * ft * lt)), 0.0) / bb if bb > 0 else 0.0, s_max)
    return np.sqrt(w) * (ft - s * lt), s


def _split(x: np.ndarray, names: tuple[str, ...]) -> dict[str, np.ndarray]:
    out, i = {}, 1
    for n in names:
        k = len(RADIAL[n].params)
        out[n] = x[i : i + k]
        i += k
    return out


def _residuals(x, data, geom, names, keep, s=None, s_max=math.inf):
    g = _gain(data, _split(x, names))
    w = data.w * keep[..., None]
    if np.any(g[keep & np.any(w > 0, -1)] <= _MIN_GAIN):
        return np.full(data.f.size, 1e6), 0.0
    gg = g[..., None]
    return _projected(data.f / gg, w * gg * gg, _lobe(data, geom, float(x[0])), s, s_max)


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
    from scipy.optimize import least_squares

    keep = np.ones(data.radius2.shape, bool) if keep is None else keep
    geom = data.lobe_geometry
    before = {} if start is None else start.effects
    theta0 = [v for n in names for v in (before.get(n) or (0.0,) * len(RADIAL[n].params))]
    s_max, top = (BOUNDED["rho_s"], math.log(BOUNDED["alpha"])) if bounded else (math.inf, _LOG_ALPHA[1])
    lo = [_LOG_ALPHA[0]] + [b[0] for n in names for b in RADIAL[n].bounds]
    hi = [top] + [b[1] for n in names for b in RADIAL[n].bounds]

    def res(x):
        return _residuals(x, data, geom, names, keep, s_max=s_max)

    if start is None:
        costs = [float(np.sum(res(np.array([t, *theta0]))[0] ** 2)) for t in _GRID]
        log_alpha = float(_GRID[int(np.argmin(costs))])
    else:
        log_alpha = math.log(start.alpha)
    x0 = np.clip(np.array([log_alpha, *theta0]), np.add(lo, 1e-9), np.subtract(hi, 1e-9))
    sol = least_squares(lambda x: res(x)[0].ravel(), x0, bounds=(lo, hi), x_scale=1.0, method="trf")
    r, s = res(sol.x)
    chi2 = float(np.sum(r**2))
    w = data.w * keep[..., None]
    n_obs = int(np.sum(w > 0))
    n_rho = int(np.sum(w.sum(1) > 0))
    dof = max(n_obs - n_rho - 2 - (len(sol.x) - 1), 1)
    try:
        cov = np.linalg.inv(sol.jac.T @ sol.jac)
        sd = np.sqrt(np.clip(np.diag(cov), 0, None))
    except np.linalg.LinAlgError:
        sd = np.full(len(sol.x), np.nan)
    effects = {n: tuple(float(v) for v in t) for n, t in _split(sol.x, names).items()}
    sigma = {n: tuple(float(v) for v in t) for n, t in _split(sd, names).items()}
    alpha = math.exp(float(sol.x[0]))
    return SharedFit(chi2, dof, alpha, float(s), effects, sigma, alpha * float(sd[0]), sol.x)


def chi2_held(data: PhotoData, fit: SharedFit, names: tuple[str, ...], keep: np.ndarray) -> float:
    """χ² of the views ``keep`` with ``fit``'s lobe and gains held, ρd profiled on them."""
    r, _ = _residuals(fit.x, data, data.lobe_geometry, names, keep, s=fit.rho_s)
    return float(np.sum(r**2))


def gains(data: PhotoData, effects: dict[str, tuple[float, ...]]) -> np.ndarray:
    """``(P, V)`` the product of the fitted radial gains (1 without any)."""
    return _gain(data, {n: np.asarray(t) for n, t in effects.items()})


def shared_residuals(data: PhotoData, fit: SharedFit, names: tuple[str, ...]) -> np.ndarray:
    """``(P, V, C)`` the weighted residuals ``√w (f − G (a + s L))`` of ``fit`` on every view (ρd profiled)."""
    r, _ = _residuals(fit.x, data, data.lobe_geometry, names, np.ones(data.radius2.shape, bool), s=fit.rho_s)
    return r


def shared_rho_d(data: PhotoData, fit: SharedFit, names: tuple[str, ...]) -> np.ndarray:
    """``(P, C)`` each problem's ρd under ``fit`` (``π a``, ``a`` the weighted mean of ``f/G − s L``; NaN unseen)."""
    g = _gain(data, _split(fit.x, names))[..., None]
    w = data.w * g * g
    lobe = _lobe(data, data.lobe_geometry, float(fit.x[0]))[..., None]
    sw = w.sum(1)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(sw > 0, np.pi * np.sum(w * (data.f / g - fit.rho_s * lobe), 1) / sw, np.nan)
