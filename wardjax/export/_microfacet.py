"""Microfacet lobes (GGX, Beckmann) and their best fit to a Ward lobe.

Renderers that do not implement Ward (Mitsuba 3's conductors and plastics,
glTF 2.0) take a microfacet BRDF (Walter et al. 2007, eq. 20):

.. math::

    f_s(ω_i, ω_o) = k_s\\,F(ω_o·h)\\,\\frac{D(h)\\,G_1(ω_i)\\,G_1(ω_o)}{4\\,\\cos θ_i \\cos θ_o},
    \\qquad h = \\frac{ω_i + ω_o}{\\lVert ω_i + ω_o \\rVert}

with the anisotropic distributions (slopes ``s_x = -h_x/h_z``, ``s_y = -h_y/h_z``)

.. math::

    D_\\mathrm{GGX} = \\frac{1}{π α_x α_y \\cos^4θ_h\\,(1 + s_x^2/α_x^2 + s_y^2/α_y^2)^2},
    \\qquad
    D_\\mathrm{Beckmann} = \\frac{\\exp(-s_x^2/α_x^2 - s_y^2/α_y^2)}{π α_x α_y \\cos^4θ_h}

and the separable Smith masking ``G1(ω) = 2 / (1 + Λ(a))``, ``a = 1/(α_ω tan θ)``
with ``α_ω² = (α_x² ω_x² + α_y² ω_y²)/(ω_x² + ω_y²)``:
``Λ_GGX = (√(1 + 1/a²) − 1)/2``, ``Λ_Beckmann = (erf(a) − 1)/2 + e^{−a²}/(2a√π)``.
``F`` is 1 for Mitsuba's ``roughconductor`` with ``material = "none"`` and
Schlick's ``F0 + (F90 − F0)(1 − ω_o·h)⁵`` for glTF's dielectric.

The fit: the microfacet parameters ``θ`` (``k_s`` or ``F0, F90``; ``α_x``,
``α_y``) minimise the cosine-weighted squared difference of the lobes over
the hemisphere of light directions, summed over a fixed set of view
directions ``ω_o`` (0–75° from the normal, three azimuths):

.. math::

    E(θ) = \\sum_{ω_o} \\int_{Ω} \\bigl(f_\\mathrm{Ward} - f_θ\\bigr)^2 \\cos θ_i\\,dω_i,

a least-squares problem solved by the engine's own solver (optimistix's
`LevenbergMarquardt`, float64, in log coordinates) over a deterministic
quadrature: a stratified grid drawn half from Ward's own lobe (Walter 2005's importance sampling, widened 1.5×) and
half from the cosine, each node weighted by ``1/pdf`` of the mixture. The
reported error is ``√(E(θ̂)/E_0)`` with ``E_0`` the same integral of
``f_Ward²`` (the relative L² difference of the lobes) and the largest relative
difference of the directional albedos ``∫ f cos θ_i dω_i`` over the view
directions.
"""

from __future__ import annotations

import math
from typing import Literal, NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import jax.scipy.special as jsp
import numpy as np
import optimistix as optx

from ..ward import WardParams, ward_brdf

__all__ = [
    "Distribution",
    "MicrofacetFit",
    "fit_microfacet",
    "gltf_dielectric_specular",
    "microfacet_specular",
]

Distribution = Literal["ggx", "beckmann"]
DISTRIBUTIONS = ("ggx", "beckmann")
# View directions of the fit: polar angles (degrees) × azimuths (degrees from the tangent).
VIEW_THETA_DEG = (0.0, 20.0, 40.0, 60.0, 75.0)
VIEW_PHI_DEG = (0.0, 45.0, 90.0)
GRID = 32  # light directions per view direction: 2 · GRID² (lobe half and cosine half)
MAX_STEPS = 256  # Levenberg–Marquardt steps; the fits take 20–30


def _smith_g1(w, ax, ay, distribution: str):
    """Separable Smith masking ``G1`` of direction ``w (..., 3)`` (local frame), unit microfacet normal side."""
    cz2 = w[..., 2] ** 2
    xy = (ax * w[..., 0]) ** 2 + (ay * w[..., 1]) ** 2  # α_ω² sin²θ
    safe = xy > 0
    t2 = jnp.where(safe, xy / jnp.maximum(cz2, 1e-300), 1.0)  # (α_ω tan θ)² = 1/a²
    if distribution == "ggx":
        g1 = 2.0 / (1.0 + jnp.sqrt(1.0 + t2))
    else:
        a = 1.0 / jnp.sqrt(t2)
        lam = 0.5 * (jsp.erf(a) - 1.0) + jnp.exp(-a * a) / (2.0 * a * jnp.sqrt(jnp.pi))
        g1 = 1.0 / (1.0 + lam)
    return jnp.where(safe, g1, 1.0)


def _distribution(h, ax, ay, distribution: str):
    """``D(h)`` (sr⁻¹) of a unit half vector ``h (..., 3)``."""
    hz = h[..., 2]
    s2 = ((h[..., 0] / ax) ** 2 + (h[..., 1] / ay) ** 2) / (hz * hz)
    cos4 = hz**4
    if distribution == "ggx":
        return 1.0 / (jnp.pi * ax * ay * cos4 * (1.0 + s2) ** 2)
    return jnp.exp(-s2) / (jnp.pi * ax * ay * cos4)


def microfacet_specular(wi, wo, alpha_x, alpha_y, distribution: str = "ggx"):
    """The microfacet lobe per unit ``k_s`` with ``F = 1``: ``D G1(ωi) G1(ωo) / (4 cos θi cos θo)`` (sr⁻¹).

    Parameters
    ----------
    wi, wo
        ``(..., 3)`` unit directions to the light and the viewer, local frame
        (z = normal, x = the tangent of ``alpha_x``).
    alpha_x, alpha_y
        Roughness (> 0) along the tangent and the bitangent.
    distribution
        ``"ggx"`` or ``"beckmann"`` (module docstring).

    Returns
    -------
    Array, shape ``(...)``
        0 where either direction is at or below the horizon.
    """
    if distribution not in DISTRIBUTIONS:
        raise ValueError(f"distribution must be one of {DISTRIBUTIONS}, got {distribution!r}")
    wi, wo = jnp.asarray(wi), jnp.asarray(wo)
    ci, co = wi[..., 2], wo[..., 2]
    valid = (ci > 1e-9) & (co > 1e-9)
    h = wi + wo
    h = jnp.where(valid[..., None], h, jnp.asarray([0.0, 0.0, 1.0], h.dtype))
    h = h / jnp.linalg.norm(h, axis=-1, keepdims=True)
    d = _distribution(h, alpha_x, alpha_y, distribution)
    g = _smith_g1(wi, alpha_x, alpha_y, distribution) * _smith_g1(wo, alpha_x, alpha_y, distribution)
    f = d * g / (4.0 * jnp.where(valid, ci * co, 1.0))
    return jnp.where(valid, f, 0.0)


def gltf_dielectric_specular(wi, wo, f0, f90, alpha_x, alpha_y):
    """glTF's dielectric lobe: Schlick ``F = F0 + (F90 − F0)(1 − ωo·h)⁵`` times the GGX lobe; and ``F``.

    Returns ``(specular, F)``, each ``(...)``: the diffuse part of glTF's
    ``fresnel_mix`` is ``(1 − F) · baseColor/π``.
    """
    wi, wo = jnp.asarray(wi), jnp.asarray(wo)
    h = wi + wo
    n = jnp.linalg.norm(h, axis=-1)
    voh = jnp.clip(jnp.sum(wo * h, axis=-1) / jnp.where(n > 0, n, 1.0), 0.0, 1.0)
    fr = f0 + (f90 - f0) * (1.0 - voh) ** 5
    return fr * microfacet_specular(wi, wo, alpha_x, alpha_y, "ggx"), fr


class MicrofacetFit(NamedTuple):
    """The microfacet equivalent of a Ward lobe (`fit_microfacet`).

    Attributes
    ----------
    distribution
        ``"ggx"`` or ``"beckmann"``.
    target
        ``"conductor"`` (``F = 1``, scale ``k_s``) or ``"gltf"`` (Schlick ``F0``, ``F90``).
    k_s
        Scale of the lobe (``"conductor"``); for ``"gltf"`` the normal-incidence ``F0``.
    f90
        Schlick's grazing reflectance (``"gltf"``); 1 for ``"conductor"``.
    alpha_x, alpha_y
        Roughness along the tangent and the bitangent.
    relative_l2
        ``√(E(θ̂)/E_0)``: the cosine-weighted L² difference of the lobes over
        the hemisphere, relative to the Ward lobe's own (module docstring).
    albedo_error
        The largest relative difference of the directional albedos over the
        view directions.
    """

    distribution: str
    target: str
    k_s: float
    f90: float
    alpha_x: float
    alpha_y: float
    relative_l2: float
    albedo_error: float

    def metadata(self) -> dict:
        """The fit as JSON (recorded in ``params.json`` and the exports)."""
        return {
            "distribution": self.distribution,
            "k_s" if self.target == "conductor" else "f0": self.k_s,
            **({"f90": self.f90} if self.target == "gltf" else {}),
            "alpha_x": self.alpha_x,
            "alpha_y": self.alpha_y,
            "error": {"relative_l2": self.relative_l2, "albedo_max_relative": self.albedo_error},
        }


def _ward_lobe_pdf(h, wo, ax, ay):
    """Solid-angle pdf of ``ωi`` under Ward's half-vector sampling (Walter 2005), NumPy."""
    hz = np.clip(h[..., 2], 1e-12, None)
    e = ((h[..., 0] / ax) ** 2 + (h[..., 1] / ay) ** 2) / hz**2
    ph = np.exp(-e) / (np.pi * ax * ay * hz**3)
    return ph / (4.0 * np.clip(np.sum(wo * h, -1), 1e-12, None))


def quadrature(alpha_x: float, alpha_y: float, grid: int = GRID):
    """Light directions, view directions and weights of the fit's integral.

    Returns ``wi, wo (V, M, 3)`` and ``weight (V, M)``: ``Σ weight · g(ωi)``
    approximates ``∫ g(ωi) cos θi dωi`` for each of the ``V`` view directions
    (weight 0 below the horizon).
    """
    u1, u2 = np.meshgrid((np.arange(grid) + 0.5) / grid, (np.arange(grid) + 0.5) / grid, indexing="ij")
    u1, u2 = u1.ravel(), u2.ravel()
    sx, sy = 1.5 * alpha_x, 1.5 * alpha_y  # sample a little wider than the lobe: its tails matter too
    phi = np.arctan2(sy * np.sin(2 * np.pi * u2), sx * np.cos(2 * np.pi * u2))
    tan2 = -np.log(u1) / (np.cos(phi) ** 2 / sx**2 + np.sin(phi) ** 2 / sy**2)
    ct = 1.0 / np.sqrt(1.0 + tan2)
    st = np.sqrt(np.clip(1.0 - ct**2, 0.0, None))
    h_s = np.stack([st * np.cos(phi), st * np.sin(phi), ct], -1)  # (G², 3)
    r = np.sqrt(u1)  # cosine-weighted hemisphere (Malley)
    cos_dirs = np.stack([r * np.cos(2 * np.pi * u2), r * np.sin(2 * np.pi * u2), np.sqrt(1.0 - u1)], -1)
    wis, wos, ws = [], [], []
    for t in VIEW_THETA_DEG:
        for p in VIEW_PHI_DEG:
            if t == 0.0 and p != VIEW_PHI_DEG[0]:
                continue
            tr, pr = math.radians(t), math.radians(p)
            wo = np.array([math.sin(tr) * math.cos(pr), math.sin(tr) * math.sin(pr), math.cos(tr)])
            wi_lobe = 2.0 * (h_s @ wo)[:, None] * h_s - wo
            wi = np.concatenate([wi_lobe, cos_dirs])
            h = wi + wo
            h = h / np.linalg.norm(h, axis=-1, keepdims=True)
            ci = wi[:, 2]
            pdf = 0.5 * _ward_lobe_pdf(h, wo, sx, sy) + 0.5 * np.clip(ci, 0.0, None) / np.pi
            w = np.where((ci > 1e-9) & (pdf > 0), ci / np.where(pdf > 0, pdf, 1.0), 0.0) / len(wi)
            wis.append(wi)
            wos.append(np.broadcast_to(wo, wi.shape))
            ws.append(w)
    return np.stack(wis), np.stack(wos), np.stack(ws)


class _Problem(eqx.Module):
    wi: jax.Array
    wo: jax.Array
    sqrt_w: jax.Array
    target: jax.Array  # (V, M) the Ward lobe (grey, per unit ρs … times ρs)
    rho_d: jax.Array  # () grey ρd, only for glTF's diffuse coupling


def _model(theta, prob: _Problem, distribution: str, target: str, iso: bool):
    ax = jnp.exp(theta[1])
    ay = ax if iso else jnp.exp(theta[2])
    if target == "conductor":
        return jnp.exp(theta[0]) * microfacet_specular(prob.wi, prob.wo, ax, ay, distribution)
    f0 = jnp.exp(theta[0])
    f90 = jax.nn.sigmoid(theta[-1])
    spec, fr = gltf_dielectric_specular(prob.wi, prob.wo, f0, f90, ax, ay)
    base = prob.rho_d / (1.0 - f0)  # baseColor of the export: ρd at normal incidence
    return spec + (1.0 - fr) * base / jnp.pi - prob.rho_d / jnp.pi  # the difference to Ward's ρd/π included


def _residual(theta, prob: _Problem, distribution: str, target: str, iso: bool):
    """``√w (f_θ − f_Ward)`` over the quadrature, flattened ``(V·M,)``."""
    return (prob.sqrt_w * (_model(theta, prob, distribution, target, iso) - prob.target)).ravel()


@eqx.filter_jit
def _solve(theta0, prob: _Problem, distribution: str, target: str, iso: bool):
    """Levenberg–Marquardt (optimistix, the engine's solver) on the weighted residual, in float64.

    The residual carries its Jacobian as a ``custom_jvp``: forward mode over
    the 3–4 parameters, materialised once per step, so that the solver's
    linearisation, its transpose and the QR of the damped system all reuse one
    ``(V·M, P)`` matrix instead of each tracing the lobe model again (a
    smaller program, quicker to compile). Returns ``(θ̂,
    converged)``; ``throw=False``: a failure is reported by `fit_microfacet`,
    not raised inside the compiled solve.
    """

    def raw(t, p: _Problem):
        return _residual(t, p, distribution, target, iso)

    @jax.custom_jvp
    def residual(t, p: _Problem):
        return raw(t, p)

    @residual.defjvp
    def _jvp(primals, tangents):
        t, p = primals
        return raw(t, p), jax.jacfwd(raw)(t, p) @ tangents[0]  # the quadrature (p) is data: no tangent

    solver = optx.LevenbergMarquardt(rtol=1e-10, atol=1e-14)
    sol = optx.least_squares(residual, solver, theta0, args=prob, max_steps=MAX_STEPS, throw=False)
    return sol.value, sol.result == optx.RESULTS.successful


def fit_microfacet(
    params: WardParams,
    *,
    normalization: str = "ward1992",
    distribution: Distribution = "ggx",
    target: Literal["conductor", "gltf"] = "conductor",
    isotropic: bool | None = None,
) -> MicrofacetFit:
    """The GGX or Beckmann lobe closest to a Ward lobe (module docstring).

    Parameters
    ----------
    params
        One (unbatched) `WardParams`; a coloured ``ρs`` is
        fitted on its mean (scale ``k_s`` by the colour afterwards).
    normalization
        The Ward normalisation ``params`` were fitted in.
    distribution
        ``"ggx"`` or ``"beckmann"``.
    target
        ``"conductor"``: ``k_s · D G / (4 cos cos)`` (Mitsuba's ``roughconductor``,
        ``material = "none"``); ``"gltf"``: glTF's dielectric, Schlick Fresnel
        with free ``F0`` and ``F90`` and its diffuse part ``(1 − F) ρd/(1 − F0)/π``
        (GGX only).
    isotropic
        Tie ``α_x = α_y``; default when the Ward lobe is isotropic.

    Returns
    -------
    MicrofacetFit
    """
    if distribution not in DISTRIBUTIONS:
        raise ValueError(f"distribution must be one of {DISTRIBUTIONS}, got {distribution!r}")
    if target not in ("conductor", "gltf"):
        raise ValueError(f"target must be 'conductor' or 'gltf', got {target!r}")
    if target == "gltf" and distribution != "ggx":
        raise ValueError("glTF's microfacet distribution is GGX")
    ax, ay = float(np.asarray(params.alpha_x)), float(np.asarray(params.alpha_y))
    rho_s = float(np.mean(np.asarray(params.rho_s)))
    rho_d = float(np.mean(np.asarray(params.rho_d)))
    if not (ax > 0 and ay > 0 and math.isfinite(ax * ay) and rho_s > 0 and math.isfinite(rho_s)):
        raise ValueError(f"a microfacet fit needs ρs > 0 and α > 0, finite; got ρs = {rho_s}, αx = {ax}, αy = {ay}")
    iso = (ax == ay) if isotropic is None else isotropic
    with jax.enable_x64(True):
        wi, wo, w = quadrature(ax, ay)
        grey = WardParams(rho_d=np.zeros(3), rho_s=rho_s, alpha_x=ax, alpha_y=ay)
        f_ward = np.asarray(ward_brdf(grey, wi, wo, normalization=normalization))[..., 0]
        prob = _Problem(
            wi=jnp.asarray(wi),
            wo=jnp.asarray(wo),
            sqrt_w=jnp.sqrt(jnp.asarray(w)),
            target=jnp.asarray(f_ward),
            rho_d=jnp.asarray(rho_d),
        )
        alphas = [math.log(ax)] if iso else [math.log(ax), math.log(ay)]
        if target == "conductor":
            theta0 = jnp.asarray([math.log(rho_s), *alphas])
        else:  # Fresnel nearly flat to start: F0 = ρs, F90 a little above
            theta0 = jnp.asarray([math.log(rho_s), *alphas, math.log(0.2 / 0.8)])
        theta, ok = _solve(theta0, prob, distribution, target, iso)
        if not bool(ok):
            raise ValueError(
                f"the {distribution} fit to the Ward lobe (ρs = {rho_s:.4g}, αx = {ax:.4g}, αy = {ay:.4g}) did not "
                f"converge in {MAX_STEPS} steps"
            )
        model = np.asarray(_model(theta, prob, distribution, target, iso))
        theta = np.asarray(theta)
    e = float(np.sum(w * (model - f_ward) ** 2))
    e0 = float(np.sum(w * f_ward**2))
    alb_w, alb_m = np.sum(w * f_ward, -1), np.sum(w * model, -1)
    fx = float(np.exp(theta[1]))
    return MicrofacetFit(
        distribution=distribution,
        target=target,
        k_s=float(np.exp(theta[0])),
        f90=float(1.0 / (1.0 + np.exp(-theta[-1]))) if target == "gltf" else 1.0,
        alpha_x=fx,
        alpha_y=fx if iso else float(np.exp(theta[2])),
        relative_l2=math.sqrt(e / e0),
        albedo_error=float(np.max(np.abs(alb_m - alb_w) / alb_w)),
    )
