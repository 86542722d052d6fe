"""A physical model of the reflected-grating threshold: lobe blur, diffuse floor and a CSF.

The smartphone method's observer lowers the bar width of a square-wave grating on the
phone until its reflection in the surface is just visible (smartphone paper, section 5).
This module predicts that threshold from physics instead of from Table 1's lines.

Reflected image (geometry from ``calibration/smartphone_setup.toml``)
    The eye sees the surface point P from ``D_s`` (18 in) and the screen's reflection at
    ``D`` (19.1 in), so the screen is ``d = D − D_s`` behind P along the reflected ray. A
    specular lobe of angular SD ``σ_lobe`` (the glossmeter's lobe SD) spreads each reflected
    ray over ``d σ_lobe`` on the screen, a Gaussian blur of SD ``σ_v = σ_lobe d / D`` in
    visual angle. A grating of frequency ``f`` (cycles/deg) keeps the modulation
    ``M(f) = exp(−2π² σ_v² f²)``; the square wave's fundamental has amplitude ``4/π`` of
    its half-swing.

Luminance seen and contrast
    Mean screen luminance ``L̄ = (L_max + L_min)/2``. The reflected grating has mean
    ``ρs L̄`` and fundamental amplitude ``(4/π) ρs (L_max − L_min)/2 · M(f)``. The diffuse
    floor is the screen's light scattered by ρd: ``L_d = ρd L̄ F`` with ``F`` the view
    factor of the screen rectangle from P, ``F = ∫ cos θ_P cos θ_S / (π r²) dA`` (the phone
    rests on its short edge, its face turned 45° towards P, facing the reflected ray).
    The contrast seen is ``C(f) = amplitude / (ρs L̄ + L_d + L_ambient)``.

Threshold
    The grating is at threshold where ``C(f) · S(f, L) = 1``, with ``S`` a contrast
    sensitivity function at the luminance ``L`` actually seen: Barten's (1999; colour-science's
    ``contrast_sensitivity_function_Barten1999`` with pupil diameter and retinal illuminance
    computed for ``L`` and the reflected screen's angular size as the field size ``X_0``), or
    Mannos & Sakrison's (1974; no luminance or size dependence). The threshold PPB is the bar
    width of that frequency, :func:`wardjax.smartphone.cpd_to_ppb`.

Constants
    Each CSF's few constants are fitted by least squares on log10 sensitivity to castleCSF
    data, never to the smartphone paper's Table 1: by default to Rovamo et al.'s (1993)
    gratings of varying area (``calibration/csf_rovamo1993.csv``; 50 cd/m²), the stimulus
    the phone shows; or to the 14 ModelFest thresholds (``calibration/csf_modelfest.csv``;
    small Gabors at 30 cd/m²), whose fit extrapolates badly to a full-field grating. Barten: the signal-to-noise
    ratio ``k``, the eye's optical blur ``σ0`` (arcmin; ``σ = √(σ0² + (0.08 arcmin/mm · d)²)``
    with ``d`` the pupil diameter) and the factor ``a`` from Gabor envelope SD to Barten's
    field size (``X_0 = a · σ_gabor``). Mannos–Sakrison: an overall scale ``A`` and a
    frequency scale ``c`` in ``S = A (0.0192 + 0.114 c f) exp(−(0.114 c f)^1.1)``.
"""

from __future__ import annotations

import csv
from functools import cache
from typing import NamedTuple

import colour
import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._data import calibration_path
from ..capture import Display, Viewing, load_display, load_viewing
from ._gratings import cpd_to_ppb, ppb_to_cpd

__all__ = [
    "CSF_METHODS",
    "CSFFit",
    "csf_cv_scatter",
    "csf_sensitivity",
    "CSF_CALIBRATIONS",
    "fit_csf_gratings",
    "fit_csf_modelfest",
    "lobe_sd_from_threshold",
    "load_csf_gratings",
    "load_modelfest",
    "screen_view_factor",
    "threshold_ppb",
]

CSF_METHODS: tuple[str, ...] = ("Barten 1999", "Mannos 1974")
CSF_CALIBRATIONS: tuple[str, ...] = ("gratings", "modelfest")
_MM_PER_IN = 25.4


class CSFFit(NamedTuple):
    """A CSF with its constants fitted to castleCSF data, and the fit's RMS error of log10 S."""

    method: str
    constants: tuple[float, ...]
    rms_log10: float


def load_modelfest() -> dict[str, NDArray]:
    """The 14 ModelFest stimuli: ``luminance``, ``frequency`` (cpd), ``sigma`` (deg), ``sensitivity``."""
    with open(calibration_path("csf_modelfest.csv"), encoding="utf-8") as fh:
        rows = list(csv.DictReader(r for r in fh if not r.startswith("#")))
    col = {
        "luminance": "luminance_cd_m2",
        "frequency": "s_frequency_cpd",
        "sigma": "ge_sigma_deg",
        "sensitivity": "sensitivity",
    }
    return {k: np.array([float(r[c]) for r in rows]) for k, c in col.items()}


def load_csf_gratings() -> dict[str, NDArray]:
    """Rovamo et al. (1993) gratings: ``luminance``, ``frequency`` (cpd), ``size`` (deg, √area), ``sensitivity``."""
    with open(calibration_path("csf_rovamo1993.csv"), encoding="utf-8") as fh:
        rows = list(csv.DictReader(r for r in fh if not r.startswith("#")))
    out = {
        "luminance": np.array([float(r["luminance_cd_m2"]) for r in rows]),
        "frequency": np.array([float(r["s_frequency_cpd"]) for r in rows]),
        "size": np.sqrt(np.array([float(r["area_deg2"]) for r in rows])),
        "sensitivity": np.array([float(r["sensitivity"]) for r in rows]),
    }
    return out


def csf_sensitivity(
    frequency: ArrayLike, luminance: ArrayLike, size_deg: ArrayLike, fit: CSFFit | str = "Barten 1999"
) -> NDArray:
    """Contrast sensitivity at ``frequency`` (cpd), ``luminance`` (cd/m²) and field size (deg).

    ``fit``: a :class:`CSFFit` or a method name (its ModelFest fit, :func:`fit_csf_modelfest`).
    For Barten, ``size_deg`` is the field size ``X_0``; Mannos–Sakrison ignores it and the
    luminance. Inputs broadcast.
    """
    if isinstance(fit, str):
        fit = fit_csf_modelfest(fit)
    f = np.asarray(frequency, dtype=np.float64)
    if fit.method == "Barten 1999":
        k, sigma0, _ = fit.constants
        lum = np.asarray(luminance, dtype=np.float64)
        x0 = np.asarray(size_deg, dtype=np.float64)
        d = colour.contrast.pupil_diameter_Barten1999(lum, x0)
        e = colour.contrast.retinal_illuminance_Barten1999(lum, d, True)
        sigma = np.sqrt((sigma0 / 60.0) ** 2 + (0.08 / 60.0 * d) ** 2)
        return np.asarray(colour.contrast.contrast_sensitivity_function_Barten1999(u=f, sigma=sigma, k=k, X_0=x0, E=e))
    if fit.method == "Mannos 1974":
        a, c = fit.constants
        g = 0.114 * c * f
        out = a * (0.0192 + g) * np.exp(-(g**1.1))
        return np.asarray(np.broadcast_to(out, np.broadcast_shapes(f.shape, np.shape(luminance), np.shape(size_deg))))
    raise ValueError(f"CSF method must be one of {CSF_METHODS}; got {fit.method!r}")


def _fit_csf(method: str, data: dict[str, NDArray], size: NDArray) -> CSFFit:
    """Least squares on log10 S; Barten's field size is ``X_0 = a · size`` (``a`` fitted)."""
    from scipy.optimize import least_squares

    if method not in CSF_METHODS:
        raise ValueError(f"CSF method must be one of {CSF_METHODS}; got {method!r}")
    target = np.log10(data["sensitivity"])

    def residual(p):
        c = tuple(float(v) for v in np.exp(p))
        x0 = c[2] * size if method == "Barten 1999" else size
        s = csf_sensitivity(data["frequency"], data["luminance"], x0, CSFFit(method, c, np.nan))
        return np.log10(s) - target

    p0 = np.log([3.0, 0.5, 2.0]) if method == "Barten 1999" else np.log([100.0, 1.0])
    sol = least_squares(residual, p0)
    return CSFFit(method, tuple(float(v) for v in np.exp(sol.x)), float(np.sqrt(np.mean(sol.fun**2))))


@cache
def fit_csf_modelfest(method: str = "Barten 1999") -> CSFFit:
    """Fit a CSF's constants to the ModelFest thresholds (least squares on log10 S; cached)."""
    mf = load_modelfest()
    return _fit_csf(method, mf, mf["sigma"])


@cache
def csf_cv_scatter(method: str = "Barten 1999", calibration: str = "gratings") -> float:
    """Out-of-sample RMS error of log10 S: leave-one-out over the calibration's castleCSF data.

    Each threshold is predicted by the CSF refitted without it; the RMS of those errors is
    the model's own scatter on data it was not fitted to (cached).
    """
    if calibration not in CSF_CALIBRATIONS:
        raise ValueError(f"CSF calibration must be one of {CSF_CALIBRATIONS}; got {calibration!r}")
    data = load_csf_gratings() if calibration == "gratings" else load_modelfest()
    size = data["size"] if calibration == "gratings" else data["sigma"]
    errs = []
    for i in range(size.size):
        keep = np.arange(size.size) != i
        fit = _fit_csf(method, {k: v[keep] for k, v in data.items()}, size[keep])
        x0 = fit.constants[2] * size[i] if method == "Barten 1999" else size[i]
        s = csf_sensitivity(data["frequency"][i], data["luminance"][i], x0, fit)
        errs.append(float(np.log10(s)) - float(np.log10(data["sensitivity"][i])))
    return float(np.sqrt(np.mean(np.square(errs))))


@cache
def fit_csf_gratings(method: str = "Barten 1999") -> CSFFit:
    """Fit a CSF's constants to Rovamo et al.'s (1993) gratings of varying area (log10 S; cached).

    Sine gratings filling square apertures of 0.003–980 deg² at 50 cd/m² (castleCSF's
    ``rovamo1993``, ``calibration/csf_rovamo1993.csv``): the stimulus the phone shows
    (a grating filling the reflected screen), unlike ModelFest's small Gabor patches.
    Barten's field size is ``X_0 = a · √area``.
    """
    g = load_csf_gratings()
    return _fit_csf(method, g, g["size"])


def _resolve_csf(csf: CSFFit | str, calibration: str) -> CSFFit:
    if not isinstance(csf, str):
        return csf
    if calibration not in CSF_CALIBRATIONS:
        raise ValueError(f"CSF calibration must be one of {CSF_CALIBRATIONS}; got {calibration!r}")
    return fit_csf_gratings(csf) if calibration == "gratings" else fit_csf_modelfest(csf)


def _screen_frame(display: Display, viewing: Viewing):
    """Screen rectangle (mm) seen from P at the origin: corner, edge vectors, normal."""
    if viewing.eye_to_surface_mm is None or viewing.view_angle_deg is None:
        raise ValueError("viewing needs eye_to_surface and view_angle for the threshold model")
    d = viewing.eye_to_screen_mm - viewing.eye_to_surface_mm
    if not d > 0:
        raise ValueError(f"eye_to_screen must exceed eye_to_surface; got {viewing.eye_to_screen_mm} mm")
    t = np.deg2rad(viewing.view_angle_deg)
    ray = np.array([np.sin(t), 0.0, np.cos(t)])  # reflected ray from P
    up = np.array([-np.cos(t), 0.0, np.sin(t)])  # along the screen, perpendicular to the ray
    q = d * ray  # where the ray meets the screen
    hinge = q - (q[2] / up[2]) * up  # the screen's edge on the surface
    w = display.width_px * display.pixel_pitch_mm
    h = display.height_px * display.pixel_pitch_mm
    corner = hinge - 0.5 * w * np.array([0.0, 1.0, 0.0])
    return corner, h * up, w * np.array([0.0, 1.0, 0.0]), -ray, d


def screen_view_factor(display: str | Display = "iphone5s", viewing: str | Viewing = "paper", n: int = 200) -> float:
    """View factor ``F`` of the phone's screen from the viewed surface point (midpoint rule)."""
    corner, e1, e2, normal, _ = _screen_frame(load_display(display), load_viewing(viewing))
    u = (np.arange(n) + 0.5) / n
    pts = corner + u[:, None, None] * e1 + u[None, :, None] * e2
    r2 = np.sum(pts**2, -1)
    cos_p = pts[..., 2] / np.sqrt(r2)
    cos_s = np.clip(-(pts @ normal) / np.sqrt(r2), 0.0, None)
    da = np.linalg.norm(e1) * np.linalg.norm(e2) / n**2
    return float(np.sum(cos_p * cos_s / (np.pi * r2)) * da)


def threshold_ppb(
    lobe_sd_deg: ArrayLike,
    rho_d: ArrayLike,
    *,
    rho_s: float = 0.05,
    csf: CSFFit | str = "Barten 1999",
    calibration: str = "gratings",
    ambient_cd_m2: float = 0.0,
    display: str | Display = "iphone5s",
    viewing: str | Viewing = "paper",
    sensitivity_scale: float = 1.0,
) -> NDArray:
    """Predicted threshold PPB of a surface from its lobe SD (degrees) and grey ρd (broadcast).

    Solves ``C(f) S(f, L) = 1`` for the highest visible frequency by bisection in log f
    (see the module docstring). Returns continuous PPB, clipped to the display's range
    ``[ppb_min, ppb_max]``: a grating visible at 1 PPB gives ``ppb_min``, one invisible at
    ``ppb_max`` gives ``ppb_max``. A method name in ``csf`` takes its constants from
    ``calibration``: ``"gratings"`` (default, :func:`fit_csf_gratings`) or ``"modelfest"``
    (:func:`fit_csf_modelfest`). ``sensitivity_scale`` multiplies the CSF (a model error
    in log S, used to propagate the CSF's scatter to the threshold).
    """
    disp, view = load_display(display), load_viewing(viewing)
    fit = _resolve_csf(csf, calibration)
    sd, rd = np.broadcast_arrays(np.asarray(lobe_sd_deg, np.float64), np.asarray(rho_d, np.float64))
    _, e1, e2, _, d = _screen_frame(disp, view)
    size = np.rad2deg(min(np.linalg.norm(e1), np.linalg.norm(e2)) / view.eye_to_screen_mm)
    lmax, lmin = disp.luminance_max, disp.luminance_min
    lbar = 0.5 * (lmax + lmin)
    lum = rho_s * lbar + rd * lbar * screen_view_factor(disp, view) + ambient_cd_m2
    sigma_v = sd * d / view.eye_to_screen_mm  # degrees of visual angle

    def visibility(f):
        amp = 4.0 / np.pi * rho_s * 0.5 * (lmax - lmin) * np.exp(-2.0 * np.pi**2 * sigma_v**2 * f**2)
        return sensitivity_scale * amp / lum * csf_sensitivity(f, lum, size, fit) - 1.0

    f_lo = np.full(sd.shape, float(ppb_to_cpd(disp.ppb_max, disp, view)))
    f_hi = np.full(sd.shape, float(ppb_to_cpd(disp.ppb_min, disp, view)))
    lo, hi = np.log(f_lo), np.log(f_hi)
    vis_lo, vis_hi = visibility(f_lo) > 0, visibility(f_hi) > 0
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        up = visibility(np.exp(mid)) > 0
        lo, hi = np.where(up, mid, lo), np.where(up, hi, mid)
    f_star = np.where(vis_hi, f_hi, np.where(vis_lo, np.exp(0.5 * (lo + hi)), f_lo))
    return np.asarray(np.clip(np.asarray(cpd_to_ppb(f_star, disp, view)), disp.ppb_min, disp.ppb_max))


def lobe_sd_from_threshold(
    ppb: ArrayLike,
    rho_d: ArrayLike,
    *,
    sd_range_deg: tuple[float, float] = (1e-3, 300.0),
    **model,
) -> NDArray:
    """Lobe SD (degrees) whose predicted threshold is ``ppb``: :func:`threshold_ppb` inverted.

    The predicted PPB rises monotonically with the lobe SD, so bisection in log SD over
    ``sd_range_deg`` (60 halvings) inverts it; ``model`` passes ``rho_s``, ``csf``,
    ``calibration``, ``ambient_cd_m2``, ``display`` and ``viewing`` through. A PPB at or below the mirror's
    threshold gives the range's low end, one above the range's prediction its high end.
    """
    target, rd = np.broadcast_arrays(np.asarray(ppb, np.float64), np.asarray(rho_d, np.float64))
    if np.any(~(target > 0)):
        raise ValueError(f"ppb must be > 0; got {ppb!r}")
    lo = np.full(target.shape, np.log(sd_range_deg[0]))
    hi = np.full(target.shape, np.log(sd_range_deg[1]))
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        above = threshold_ppb(np.exp(mid), rd, **model) > target
        lo, hi = np.where(above, lo, mid), np.where(above, mid, hi)
    return np.asarray(np.exp(0.5 * (lo + hi)))
