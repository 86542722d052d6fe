"""Hidden-effect bench: hide one effect (or none) in simulated scanlines, run ``discover`` blind.

Simulation (independent of the library's hook code where it can be)
    ``S`` scanlines, each in its own rig (lamp and camera 400–900 mm away at
    20–60° from the normal, in the plane x = 0, as in the image-based
    paper's Fig. 2), offset across the stripline so that the half vector tilts
    by up to ±α, ``N`` samples each, RGB. The material is drawn at random
    (ρd 0.1–0.6 per channel, ρs 0.03–0.08, α 0.08–0.25). The Ward lobe is
    evaluated with :func:`wardjax.ward_brdf` (anisotropy by turning the
    directions into the rotated tangent frame); measurement effects are
    applied where they physically act — on the probe pixel ``v_p`` and on
    the standard's mirror pixel ``v_std`` — and the data are the ratio
    ``f = v_p/v_std · ρ_std/π``, so that the effects that cancel by the rig's
    symmetry really do cancel. Noise: 1 % of the value plus a floor of
    0.2 % of ``ρ_std/π``, added to ``v_p`` before clipping (so clipped values
    tie exactly, as on a sensor).

Strength
    Each hidden effect's strength parameter is set by bisection so that the
    RMS change of the noise-free data is a random 3–10 σ (per observation);
    its other parameters (orientations, widths, colours) are drawn at random.

Out-of-library effect: orange peel
    A periodic waviness of the surface, height ``A sin(2π y/P + φ0)`` along the
    scanlines (P = 4–8 mm), tilts the local normal, and with it the highlight,
    back and forth; the data are rendered exactly in the tilted local frame.
    No library effect predicts a residual that oscillates with position, so
    the workflow must report unexplained structure instead of a name.

Run ``python -m benchmarks.bench_effects`` for the full table.
"""

from __future__ import annotations

import math
import time
from typing import NamedTuple

import numpy as np

from wardjax.effects import ScanlineModel, discover, scanline_data
from wardjax.simulate import ScanlineRig, scanline_directions, scanline_positions, ward_values, x_offset_for_slope
from wardjax.ward import WardParams

__all__ = ["DETECTABLE", "CANCELLED", "OUT_OF_LIBRARY", "BenchCase", "simulate_case", "run_bench", "bench_table"]

DETECTABLE = (
    "saturation",
    "ambient",
    "gamma",
    "illumination_gradient",
    "fresnel",
    "anisotropy",
    "second_lobe",
    "coloured_specular",
    "retroreflection",
)
CANCELLED = ("symmetric_falloff", "directional_emission")
OUT_OF_LIBRARY = "orange_peel"
RHO_STD = 0.99
NOISE_REL = 0.01
NOISE_FLOOR = 0.002


class BenchCase(NamedTuple):
    """One simulated case: the data for ``discover`` and the truth."""

    data: object
    hidden: str | None
    strength_sigma: float
    truth: dict


def _rot_z(w, phi):
    c, s = np.cos(phi), np.sin(phi)
    return np.stack([c * w[..., 0] + s * w[..., 1], -s * w[..., 0] + c * w[..., 1], w[..., 2]], -1)


def _rot_x(w, t):
    """Directions expressed in a frame whose normal is tilted by angle ``t`` (…,) about x."""
    c, s = np.cos(t), np.sin(t)
    return np.stack([w[..., 0], c * w[..., 1] - s * w[..., 2], s * w[..., 1] + c * w[..., 2]], -1)


def _ward(rho_d, rho_s, ax, ay, wi, wo):
    return ward_values(WardParams(rho_d=rho_d, rho_s=rho_s, alpha_x=ax, alpha_y=ay), wi, wo)


class _Scene:
    """Geometry and material of one draw."""

    def __init__(self, rng, n_scan, n_samp):
        tl = np.deg2rad(rng.uniform(20, 60, n_scan))
        tc = np.deg2rad(rng.uniform(20, 60, n_scan))
        dl, dc = rng.uniform(400, 900, n_scan), rng.uniform(400, 900, n_scan)
        lamp = np.stack([np.zeros(n_scan), dl * np.sin(tl), dl * np.cos(tl)], -1)
        cam = np.stack([np.zeros(n_scan), -dc * np.sin(tc), dc * np.cos(tc)], -1)
        self.rig = ScanlineRig(lamp, cam)
        self.rho_d = rng.uniform(0.1, 0.6, 3)
        self.rho_s = rng.uniform(0.03, 0.08)
        self.alpha = rng.uniform(0.08, 0.25)
        slopes = rng.uniform(-1.0, 1.0, n_scan) * self.alpha
        x0 = x_offset_for_slope(self.rig, slopes)
        self.points = scanline_positions(self.rig, x0, np.full(n_scan, 3.2 * self.alpha), n_samp)
        self.wi, self.wo = scanline_directions(self.points, ScanlineRig(lamp[:, None, :], cam[:, None, :]))
        self.lamp = lamp
        r2 = np.sum((lamp[:, None, :] - self.points) ** 2, -1)
        self.irr = self.wi[..., 2] / r2  # lamp irradiance (arbitrary units), same at the mirror point
        self.irr_rel = self.irr / np.mean(self.irr)
        self.f_std = RHO_STD / np.pi


def _render(sc: _Scene, effect: str | None, s: float, par: dict) -> tuple[np.ndarray, np.ndarray | None]:
    """Noise-free measured f (S, N, 3) with ``effect`` at strength ``s``, and the sensor scale info."""
    wi, wo = sc.wi, sc.wo
    ax = ay = sc.alpha
    rho_s = np.full(3, sc.rho_s)
    extra = 0.0
    spec_mult = 1.0
    if effect == "anisotropy":
        ax, ay = sc.alpha * math.exp(s), sc.alpha * math.exp(-s)
        wi, wo = _rot_z(wi, par["phi"]), _rot_z(wo, par["phi"])
    if effect == OUT_OF_LIBRARY:
        y = sc.points[..., 1]
        slope = s * 2 * np.pi / par["period"] * np.cos(2 * np.pi * y / par["period"] + par["phase"])
        t = np.arctan(slope)
        wi, wo = _rot_x(wi, t), _rot_x(wo, t)
    if effect == "coloured_specular":
        rho_s = sc.rho_s * np.exp(s * par["tint"])
    diffuse = np.broadcast_to(sc.rho_d / np.pi, wi.shape)
    spec = _ward(np.zeros(3), rho_s, ax, ay, wi, wo)
    if effect == "fresnel":
        h = wi + wo
        cd = np.sum(h * wi, -1) / np.linalg.norm(h, axis=-1)
        spec_mult = (1.0 + s * (1.0 - cd) ** 5)[..., None]
    if effect == "second_lobe":
        a2 = sc.alpha * par["ratio"]
        extra = _ward(np.zeros(3), np.full(3, s * sc.rho_s), a2, a2, wi, wo)
    if effect == "retroreflection":
        psi = np.arccos(np.clip(np.sum(wi * wo, -1), -1, 1))
        extra = (s * np.exp(-0.5 * (psi / par["width"]) ** 2))[..., None]
    f = diffuse + spec * spec_mult + extra
    f = np.where((wi[..., 2:3] > 0) & (wo[..., 2:3] > 0), f, 0.0)
    # ---- measurement: probe pixel and its mirror on the standard (x → −x)
    x = sc.points[..., 0][..., None]
    e_p = sc.irr_rel[..., None]  # the mirror point has the same irradiance (lamp in x = 0)
    g_p = g_s = 1.0
    if effect == "illumination_gradient":
        g_p, g_s = np.exp(0.5 * s * x / 100.0), np.exp(-0.5 * s * x / 100.0)
    if effect == "symmetric_falloff":
        rr = (x / 100.0) ** 2 + ((sc.points[..., 1][..., None] - par["yc"]) / 100.0) ** 2
        g_p = g_s = 1.0 + s * rr
    if effect == "directional_emission":
        # lamp axis in the x = 0 plane, aimed at the mirror point: β(p) = β(p')
        axis = -sc.lamp / np.linalg.norm(sc.lamp, axis=-1, keepdims=True)
        cb = np.sum(-sc.wi * axis[:, None, :], -1)[..., None]
        g_p = g_s = cb**s
    v_p = e_p * g_p * f
    v_s = e_p * g_s * sc.f_std
    amb = s * par.get("amb_scale", 0.0) if effect == "ambient" else 0.0
    return v_p, v_s, amb


def _measure(v_p, v_s, amb, sc, effect, s, noise, vmax=None):
    v_p = v_p + amb
    v_s = v_s + amb
    if effect == "gamma":
        # camera encodes with γ_true = γ_assumed (1 + s): decoded values are v^{1+s} (white level 1)
        v_p = np.maximum(v_p, 1e-12) ** (1.0 + s)
        v_s = v_s ** (1.0 + s)
    f = v_p / v_s * sc.f_std
    if noise is not None:
        f = f + noise
    if vmax is not None:  # clip at the sensor level, in f units (vmax / (E k))
        f = np.minimum(f, vmax / sc.irr_rel[..., None])
    return f


def simulate_case(
    hidden: str | None, seed: int, *, n_scanlines: int = 8, n_samples: int = 256, strength_sigma: float | None = None
) -> BenchCase:
    """Simulate one bench case with ``hidden`` (a library effect name, ``"orange_peel"`` or ``None``).

    Parameters
    ----------
    hidden
        The effect hidden in the data, or ``None`` for null data.
    seed
        Seed of the draw (scene, strength, noise).
    n_scanlines, n_samples
        Size: ``n_scanlines · n_samples · 3`` observations.
    strength_sigma
        RMS change of the data in units of σ; default uniform in 3–10.
    """
    allowed = DETECTABLE + CANCELLED + (OUT_OF_LIBRARY, None)
    if hidden not in allowed:
        raise ValueError(f"hidden must be one of {allowed}, got {hidden!r}")
    rng = np.random.default_rng(seed)
    sc = _Scene(rng, n_scanlines, n_samples)
    target = float(rng.uniform(3.0, 10.0)) if strength_sigma is None else float(strength_sigma)
    par = {
        "phi": rng.uniform(-np.pi / 2, np.pi / 2),
        "ratio": float(np.exp(rng.choice([-1, 1]) * rng.uniform(np.log(2.0), np.log(4.0)))),
        "width": rng.uniform(0.3, 0.8),
        "tint": rng.normal(0, 1, 3) * np.array([1.0, 0.0, 1.0]),
        "period": rng.uniform(4.0, 8.0),
        "phase": rng.uniform(0, 2 * np.pi),
        "yc": rng.uniform(-50, 50),
        "amb_scale": 1.0,
    }
    if np.linalg.norm(par["tint"]) < 0.5:
        par["tint"] = par["tint"] / max(np.linalg.norm(par["tint"]), 1e-9) * 0.5
    v0p, v0s, _ = _render(sc, None, 0.0, par)
    f0 = _measure(v0p, v0s, 0.0, sc, None, 0.0, None)
    sigma = NOISE_REL * np.abs(f0) + NOISE_FLOOR * sc.f_std
    noise = sigma * rng.standard_normal(f0.shape)

    def rms(s):
        if hidden == "saturation":
            f = np.minimum(f0, s / sc.irr_rel[..., None])
        else:
            vp, vs, amb = _render(sc, hidden, s, par)
            f = _measure(vp, vs, amb, sc, hidden, s, None)
        return float(np.sqrt(np.mean(((f - f0) / sigma) ** 2)))

    s = 0.0
    if hidden is not None:
        if hidden == "saturation":
            top = float(np.max(f0 * sc.irr_rel[..., None]))
            lo, hi = 0.2 * top, top
            for _ in range(60):
                mid = 0.5 * (lo + hi)
                lo, hi = (mid, hi) if rms(mid) > target else (lo, mid)
            s = 0.5 * (lo + hi)
        elif hidden in CANCELLED:
            s = {"symmetric_falloff": 0.5, "directional_emission": 4.0}[hidden]  # strong, yet cancels
        else:
            sign = (
                -1.0
                if (hidden in ("gamma", "ambient", "illumination_gradient", "anisotropy") and rng.uniform() < 0.5)
                else 1.0
            )
            hi = 1e-3
            while rms(sign * hi) < target and hi < 1e4:
                hi *= 2.0
            lo = 0.0
            for _ in range(60):
                mid = 0.5 * (lo + hi)
                lo, hi = (mid, hi) if rms(sign * mid) < target else (lo, mid)
            s = sign * 0.5 * (lo + hi)
    if hidden == "saturation":
        vp, vs, amb = _render(sc, None, 0.0, par)
        f = _measure(vp, vs, amb, sc, None, 0.0, noise, vmax=s)
    else:
        vp, vs, amb = _render(sc, hidden, s, par)
        f = _measure(vp, vs, amb, sc, hidden, s, noise)
    data = scanline_data(f, sc.wi, sc.wo, sigma, points=sc.points, lamp=sc.lamp, kind="ratio", rho_standard=RHO_STD)
    truth = {"rho_d": sc.rho_d, "rho_s": sc.rho_s, "alpha": sc.alpha, "strength": s, **par}
    return BenchCase(data=data, hidden=hidden, strength_sigma=rms(s) if hidden not in (None,) else 0.0, truth=truth)


def case_seed(seed: int, hidden: str | None, k: int) -> int:
    """The seed of draw ``k`` of ``hidden`` (distinct streams per effect and draw)."""
    idx = 0 if hidden is None else 1 + (DETECTABLE + CANCELLED + (OUT_OF_LIBRARY,)).index(hidden)
    return 1_000_003 * seed + 10_007 * idx + k


def run_bench(
    n_draws: int = 10,
    n_null: int = 100,
    *,
    effects=DETECTABLE,
    seed: int = 0,
    n_scanlines: int = 8,
    n_samples: int = 256,
    out_of_library: int = 0,
    cancelled: int = 0,
    draws: dict | None = None,
    progress=None,
) -> dict:
    """Run ``discover`` blind on hidden-effect and null draws; tabulate.

    ``draws`` overrides ``n_draws`` per effect (``{"gamma": 20}``: more draws
    where one miss in ten would leave the ≥ 95 % rate in doubt); draw ``k`` of
    an effect is the same case whatever the count.

    Returns
    -------
    dict
        ``confusion``: ``{hidden: {first named or "none": count}}``;
        ``named_first``: fraction named first per effect; ``null_false_rate``;
        ``gap_before``/``gap_after`` per case; ``cases`` (one row per run).
    """
    model = ScanlineModel()
    rows = []
    draws = draws or {}
    plan = [(e, k) for e in effects for k in range(draws.get(e, n_draws))] + [(None, k) for k in range(n_null)]
    plan += [(OUT_OF_LIBRARY, k) for k in range(out_of_library)] + [(e, k) for e in CANCELLED for k in range(cancelled)]
    for j, (hidden, k) in enumerate(plan):
        case = simulate_case(hidden, case_seed(seed, hidden, k), n_scanlines=n_scanlines, n_samples=n_samples)
        t0 = time.perf_counter()
        rep = discover(model, case.data, keep_plot_data=False)
        rows.append(
            {
                "hidden": hidden or "none",
                "draw": k,
                "strength_sigma": case.strength_sigma,
                "found": list(rep.found),
                "first": rep.found[0] if rep.found else "none",
                "gap_before": rep.gap[0],
                "gap_after": rep.gap[-1],
                "n_obs": rep.n_obs,
                "unexplained": bool(rep.unexplained),
                "partial": list(rep.partial),
                "dof": rep.final.dof,
                **_z_fields(rep, case.truth),
                "seconds": time.perf_counter() - t0,
            }
        )
        if progress:
            progress(j, len(plan), rows[-1])
    return summarise(rows)


def _z_fields(rep, truth: dict) -> dict:
    """ρs and α after discovery (model-averaged, :attr:`~wardjax.effects.DiscoveryReport.averaged`), their σ and
    ``z = (value − truth)/σ``; α's truth is ``√(αx αy)``, the scene's α."""
    av = rep.averaged
    out = {}
    for k in ("rho_s", "alpha"):
        v, sd = float(av[k]["value"]), float(av[k]["sigma"])
        out |= {k: v, f"{k}_sigma": sd, f"z_{k}": (v - float(truth[k])) / sd if sd > 0 else math.nan}
    return out


def _robust_sd(z) -> float:
    """1.4826 × the median absolute deviation of the finite ``z``: a normal sample's SD, robust to outliers."""
    z = np.asarray([v for v in z if math.isfinite(v)], float)
    return float(1.4826 * np.median(np.abs(z - np.median(z)))) if z.size else math.nan


def summarise(rows: list[dict]) -> dict:
    """Confusion matrix, rates and gaps from bench rows.

    Also ``z_robust_sd`` (ρs and α after discovery against the truth, over every row) and ``gap_band``: of the
    detectable draws named first, how many end with the gap in ``1 ± 2 √(2/dof)`` and how many below it.
    """
    conf: dict[str, dict[str, int]] = {}
    for r in rows:
        conf.setdefault(r["hidden"], {}).setdefault(r["first"], 0)
        conf[r["hidden"]][r["first"]] += 1
    named = {
        h: sum(1 for r in rows if r["hidden"] == h and r["first"] == h)
        / max(1, sum(1 for r in rows if r["hidden"] == h))
        for h in conf
        if h in DETECTABLE
    }
    nulls = [r for r in rows if r["hidden"] == "none"]
    det = [r for r in rows if r["hidden"] in DETECTABLE]
    return {
        "confusion": conf,
        "named_first": named,
        "named_first_all": (sum(1 for r in det if r["first"] == r["hidden"]) / len(det)) if det else math.nan,
        "null_false_rate": (sum(1 for r in nulls if r["found"]) / len(nulls)) if nulls else math.nan,
        "n_null": len(nulls),
        "gap_after_max_detectable": max((r["gap_after"] for r in det if r["first"] == r["hidden"]), default=math.nan),
        "z_robust_sd": {k: _robust_sd(r[f"z_{k}"] for r in rows if f"z_{k}" in r) for k in ("rho_s", "alpha")},
        "gap_band": _gap_band([r for r in det if r["first"] == r["hidden"] and "dof" in r]),
        "rows": rows,
    }


def _gap_band(rows: list[dict]) -> dict:
    """How many ``rows`` end with the gap within ``1 ± 2 √(2/dof)``, below it, and above it."""
    half = [2.0 * math.sqrt(2.0 / r["dof"]) for r in rows]
    return {
        "n": len(rows),
        "within": sum(abs(r["gap_after"] - 1.0) <= h for r, h in zip(rows, half)),
        "below": sum(r["gap_after"] < 1.0 - h for r, h in zip(rows, half)),
        "above": sum(r["gap_after"] > 1.0 + h for r, h in zip(rows, half)),
    }


def bench_table(summary: dict) -> str:
    """Markdown confusion matrix (rows: hidden, columns: first effect named)."""
    conf = summary["confusion"]
    cols = sorted({c for d in conf.values() for c in d} | {"none"})
    lines = [
        "| hidden \\ named first | " + " | ".join(cols) + " | gap before → after (median) |",
        "|---" * (len(cols) + 2) + "|",
    ]
    for h, d in conf.items():
        rs = [r for r in summary["rows"] if r["hidden"] == h]
        gb = np.median([r["gap_before"] for r in rs])
        ga = np.median([r["gap_after"] for r in rs])
        lines.append(f"| {h} | " + " | ".join(str(d.get(c, 0)) or "" for c in cols) + f" | {gb:.2f} → {ga:.3f} |")
    return "\n".join(lines)
