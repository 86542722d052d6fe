"""Whether a photograph fit describes a material: a verdict on the capture, not an error in its input.

A fit of a real photo can leave the physical range — a mean ρd below 0, a
lobe with ρs > 1 or α > 1 — when the model lacks an effect the photo holds
(vignetting, the flash's angular falloff, processing in the camera) and the
free parameters stand in for it. That is a finding about the capture: the
report and the command line say it in one line naming the parameter, its
value and σ, and the photos; the material a renderer would load is not
exported with those values.

The physical ranges are those every entry point applies
(:mod:`wardjax._rules`, :mod:`wardjax.effects._photo_checks`): ``0 ≤ ρd ≤ 1``
per channel, ``0 ≤ ρs``, ``ρd + ρs ≤ 1`` per channel (energy conservation,
image-based paper eq. 1), ``0 < α ≤ 1`` (beyond 1 a "lobe" is a diffuse
tilt). A value outside by at most :data:`NOISE_SIGMAS` σ is noise: the
material takes the bound, and a note says so. The σ are the fit's, scaled by
``√(χ²/dof)`` where that exceeds 1 (the model's σ hold only if the model
fits; the scale is the usual Birge ratio).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ..ward import WardParams

__all__ = ["ALPHA_MAX", "MAX_NEGATIVE", "NOISE_SIGMAS", "Verdict", "physical_verdict"]

NOISE_SIGMAS = 3.0  # a value further than this many σ outside its range is not noise
ALPHA_MAX = 1.0  # beyond this a "lobe" is a diffuse tilt, not a specular peak (effects._photo_checks)
MAX_NEGATIVE = 0.1  # a larger share of ρd values below 0 beyond noise is no material's texture
_CHANNELS = ("R", "G", "B")


@dataclasses.dataclass(frozen=True)
class Verdict:
    """A fit held to the physical ranges.

    Attributes
    ----------
    physical
        ``False`` where an estimate leaves its range by more than :data:`NOISE_SIGMAS` σ.
    material
        The estimate with the values outside by noise alone set to the bound; ``None`` when not physical.
    why
        ``"ρs = 1.853 ± 0.69 > 1; …"``: each value outside beyond noise (empty when physical).
    notes
        One line per value set to its bound.
    """

    physical: bool
    material: WardParams | None
    why: str
    notes: tuple[str, ...]

    def line(self, name: str, photos) -> str:
        """One line for the command line and the report: the capture, its photos and why."""
        return (
            f"{name} ({', '.join(photos)}): not a physical material: {self.why}; the fitted lobe and ρd stand in "
            "for an effect the model lacks (see wardjax diagnose); no material exported"
        )


def _pm(v: float, s: float) -> str:
    return f"{v:.4g} ± {s:.2g}"


class _Hold:
    """Values held to their ranges: the reasons beyond noise, the notes within it."""

    def __init__(self) -> None:
        self.why: list[str] = []
        self.notes: list[str] = []

    def __call__(self, label: str, v: float, s: float, lo: float, hi: float) -> float:
        """``v`` within ``[lo, hi]``; outside by noise alone: the bound (noted); beyond: a reason, ``v`` kept."""
        if lo <= v <= hi:
            return v
        bound, op = (lo, f"< {lo:g}") if v < lo else (hi, f"> {hi:g}")
        if abs(v - bound) <= NOISE_SIGMAS * max(s, 0.0):
            self.notes.append(
                f"{label} = {_pm(v, s)} lies within {NOISE_SIGMAS:g} σ of {bound:g}: the material takes {bound:g}"
            )
            return bound
        self.why.append(f"{label} = {_pm(v, s)} {op}")
        return v


def physical_verdict(
    rho_d: np.ndarray,
    rho_d_err: np.ndarray,
    lobes: dict,
    *,
    chi2_per_dof: float | None = None,
    rho_d_map: np.ndarray | None = None,
    rho_d_map_err: np.ndarray | None = None,
) -> Verdict:
    """Hold a photograph fit's estimate to the physical ranges.

    Parameters
    ----------
    rho_d, rho_d_err
        ``(3,)`` the mean ρd and its 1-σ.
    lobes
        ``rho_s``, ``alpha_x``, ``alpha_y`` and their ``…_err``: lists, one value per lobe (``fit.lobes`` of
        ``params.json``). The material exported is lobe 0's.
    chi2_per_dof
        The fit's reduced χ²; every σ is scaled by its square root where it exceeds 1.
    rho_d_map, rho_d_map_err
        ``(H, W, 3)`` the per-pixel ρd and σ (NaN: no data): more than :data:`MAX_NEGATIVE` of the values
        below 0 by more than :data:`NOISE_SIGMAS` σ is a reason too.
    """
    scale = float(np.sqrt(chi2_per_dof)) if chi2_per_dof is not None and chi2_per_dof > 1 else 1.0
    hold = _Hold()
    rd = np.asarray(rho_d, float).reshape(3).copy()
    srd = np.asarray(rho_d_err, float).reshape(3) * scale
    first = {}
    for i in range(len(lobes["rho_s"])):
        tag = "" if len(lobes["rho_s"]) == 1 else f" (lobe {i})"
        v = {k: float(lobes[k][i]) for k in ("rho_s", "alpha_x", "alpha_y")}
        s = {k: float(lobes[f"{k}_err"][i]) * scale for k in v}
        v["rho_s"] = hold(f"ρs{tag}", v["rho_s"], s["rho_s"], 0.0, 1.0)
        if v["alpha_x"] == v["alpha_y"]:  # isotropic: one α
            v["alpha_x"] = v["alpha_y"] = hold(f"α{tag}", v["alpha_x"], s["alpha_x"], 1e-300, ALPHA_MAX)
        else:
            for k, label in (("alpha_x", "αx"), ("alpha_y", "αy")):
                v[k] = hold(f"{label}{tag}", v[k], s[k], 1e-300, ALPHA_MAX)
        first = first or v
    for c in range(3):
        rd[c] = hold(f"mean ρd {_CHANNELS[c]}", rd[c], srd[c], 0.0, 1.0)
        if first["rho_s"] <= 1 < rd[c] + first["rho_s"]:  # energy conservation (ρs > 1 is said already)
            s = float(np.hypot(srd[c], float(lobes["rho_s_err"][0]) * scale))
            rd[c] = hold(f"mean ρd {_CHANNELS[c]} + ρs", rd[c] + first["rho_s"], s, 0.0, 1.0) - first["rho_s"]
    if rho_d_map is not None and rho_d_map_err is not None:
        ok = np.isfinite(rho_d_map) & np.isfinite(rho_d_map_err)
        below = np.mean(rho_d_map[ok] < -NOISE_SIGMAS * scale * rho_d_map_err[ok]) if ok.any() else 0.0
        if below > MAX_NEGATIVE:
            hold.why.append(f"ρd < 0 beyond {NOISE_SIGMAS:g} σ in {100 * below:.0f} % of the pixel values")
    why = "; ".join(hold.why)
    if why and scale > 1:
        why += f" (σ × √(χ²/dof) = {scale:.3g})"
    if why:
        return Verdict(False, None, why, ())  # nothing is exported: no value is held to a bound
    material = WardParams(rho_d=rd, rho_s=first["rho_s"], alpha_x=first["alpha_x"], alpha_y=first["alpha_y"])
    return Verdict(True, material, "", tuple(hold.notes))
