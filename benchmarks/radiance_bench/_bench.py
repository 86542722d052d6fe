"""Draw each case's capture, run ``wardjax diagnose``'s discovery on it blind, and keep one CSV row per capture.

Discovery is called as ``wardjax diagnose`` calls it (the capture loaded with
:func:`wardjax.load_capture`, binned to the CLI's default samples with the
texture carried, :func:`wardjax.effects.discover` from the isotropic
baseline). A row holds the truth, what was named first, the verdict, the gap
before, after the true effect's step and at the end, and z of ρs and α (the
model-averaged σ) against the truth; where the Fresnel rise is named on the
``fresnel`` case, ρs at the scene's reference angle (the scene's ρs is there,
the library's at normal incidence), with its σ from ρs and κ's covariance.
Rows are written atomically after every capture, and a rerun skips the
captures already in the file.
"""

from __future__ import annotations

import csv
import math
import os
import tempfile
import time
from pathlib import Path

import numpy as np

from ._cases import CASES, components
from ._sensor import write_capture

FIELDS = (
    "case",
    "kind",
    "material",
    "texture",
    "seed",
    "size",
    "bits",
    "expected",
    "found",
    "first",
    "outcome",
    "verdict",
    "gap_before",
    "gap_true",
    "gap_after",
    "dof",
    "rho_s",
    "rho_s_sigma",
    "rho_s_true",
    "z_rho_s",
    "alpha",
    "alpha_sigma",
    "alpha_true",
    "z_alpha",
    "seconds",
    "commit",
    "date",
    "load",
)
KEY = ("case", "material", "texture", "seed", "size", "bits")


def materials() -> dict:
    """Ward parameters of the desk and marble (``wardjax simulate --material``), the satin and the metal."""
    from benchmarks.null_captures import materials as null_materials

    return null_materials()


def present(material: str) -> set[str]:
    """Library effects the material itself carries: anisotropy where αx ≠ αy."""
    p = materials()[material]
    return {"anisotropy"} if float(p.alpha_x) != float(p.alpha_y) else set()


def outcome(kind: str, expected: set[str], found: list[str]) -> str:
    """``right first`` / ``later`` / ``missed`` / ``wrong`` (an effect is present), ``clean`` / ``false name``
    (a null) and ``not named`` / ``named`` (outside the library)."""
    if kind in ("null", "out"):
        extra = set(found) - expected
        return ("false name" if kind == "null" else "named") if extra else ("clean" if kind == "null" else "not named")
    if not found:
        return "missed"
    if found[0] in expected:
        return "right first"
    return "later" if expected & set(found) else "wrong"


def run_case(case: str, material: str, texture: str, seed: int, size: tuple[int, int], bits: int, keep=None) -> dict:
    """Draw one capture, diagnose it, return its CSV row (``keep``: a folder to keep the capture in)."""
    import wardjax as wj
    from wardjax.effects import ScanlineModel, discover
    from wardjax.effects._capture import capture_data
    from wardjax.run._cli import _DIAGNOSE_SAMPLES

    c, p = CASES[case], materials()[material]
    t0 = time.perf_counter()
    comp = components(c, p, texture, seed, size)
    name = f"{case}-{material}-{texture}-s{seed}-{size[0]}x{size[1]}-{bits}"
    with tempfile.TemporaryDirectory(prefix="radbench-") as tmp:
        folder = Path(keep or tmp) / name
        write_capture(folder, comp, c, bits, seed, name)
        cap = wj.load_capture(folder)
        data = capture_data(cap, max_samples=_DIAGNOSE_SAMPLES[True])
        rep = discover(ScanlineModel(cap.config.fit.normalization), data, texture=True)
    expected = set(c.expected) | present(material)
    found = list(rep.found)
    true_gaps = [s.gap_after for s in rep.steps if s.effect in expected]
    rho_s_true, ax, ay = comp["truth"]
    av = rep.averaged
    rs, al = av["rho_s"], av.get("alpha") or _geo_alpha(av)
    if c.fresnel_n and "fresnel" in rep.found:  # the scene's ρs is at its reference angle, the library's at normal
        rs = _rho_s_at(rep.final, math.cos(math.radians(c.angle)))
    a_true = math.sqrt(ax * ay)
    return {
        "case": case,
        "kind": c.kind,
        "material": material,
        "texture": texture,
        "seed": seed,
        "size": f"{size[0]}x{size[1]}",
        "bits": bits,
        "expected": " ".join(sorted(expected)) or "-",
        "found": " ".join(found) or "-",
        "first": found[0] if found else ("unexplained" if rep.verdict().startswith("unexplained") else "nothing"),
        "outcome": outcome(c.kind, expected, found),
        "verdict": rep.verdict(),
        "gap_before": f"{rep.gap[0]:.4f}",
        "gap_true": f"{true_gaps[-1]:.4f}" if true_gaps else "-",
        "gap_after": f"{rep.gap[-1]:.4f}",
        "dof": rep.final.dof,
        "rho_s": f"{rs['value']:.6g}",
        "rho_s_sigma": f"{rs['sigma']:.3g}",
        "rho_s_true": f"{rho_s_true:.6g}",
        "z_rho_s": f"{(rs['value'] - rho_s_true) / rs['sigma']:.3f}",
        "alpha": f"{al['value']:.6g}",
        "alpha_sigma": f"{al['sigma']:.3g}",
        "alpha_true": f"{a_true:.6g}",
        "z_alpha": f"{(al['value'] - a_true) / al['sigma']:.3f}",
        "seconds": f"{time.perf_counter() - t0:.0f}",
        "commit": _commit(),
        "date": time.strftime("%Y-%m-%d"),
        "load": f"{os.getloadavg()[0]:.1f}",
    }


def _rho_s_at(state, cos_ref: float) -> dict:
    """ρs at the incidence ``cos_ref`` of the Fresnel rise's Schlick form, ``ρs (1 + κ (1 − cos)^5)``, with its σ
    by the delta method on the fitted state's covariance of ρs and κ (strongly anticorrelated: each alone is
    pinned far worse than the value at the angles the capture sees)."""
    from wardjax.effects import get_effect

    flat = [(owner, name) for owner, d in state.values.items() for name in d]
    i, j = flat.index(("model", "rho_s")), flat.index(("fresnel", "kappa"))
    rho_s, kappa = state.values["model"]["rho_s"], state.values["fresnel"]["kappa"]
    d = np.array([rho_s, get_effect("fresnel").params[0].scale])  # d natural / d u: ρs is log, κ linear
    cov = np.asarray(state.cov)[np.ix_([i, j], [i, j])] * np.outer(d, d)
    c = (1.0 - cos_ref) ** 5
    grad = np.array([1.0 + kappa * c, rho_s * c])
    return {"value": rho_s * (1.0 + kappa * c), "sigma": float(np.sqrt(grad @ cov @ grad))}


def _geo_alpha(av: dict) -> dict:
    """√(αx αy) and its σ to first order, where the model reports αx and αy apart."""
    x, y = av["alpha_x"], av["alpha_y"]
    g = math.sqrt(x["value"] * y["value"])
    return {"value": g, "sigma": 0.5 * g * math.hypot(x["sigma"] / x["value"], y["sigma"] / y["value"])}


def _commit() -> str:
    from benchmarks.bench_diagnose import _commit as commit

    return commit()


def read_rows(path: Path) -> list[dict]:
    return list(csv.DictReader(path.open())) if path.exists() else []


def write_rows(path: Path, rows: list[dict]) -> None:
    """Write all ``rows`` to ``path`` through a temporary file beside it (never a half-written CSV)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", dir=path.parent)
    with os.fdopen(fd, "w", newline="") as f:
        w = csv.DictWriter(f, FIELDS)
        w.writeheader()
        w.writerows(rows)
    os.replace(tmp, path)


def key(row: dict) -> tuple[str, ...]:
    return tuple(str(row[k]) for k in KEY)


def robust_sd(z) -> float:
    """1.4826 × the median absolute deviation: the SD of a normal sample, insensitive to a few outliers."""
    z = np.asarray(z, float)
    return float(1.4826 * np.median(np.abs(z - np.median(z)))) if z.size else float("nan")
