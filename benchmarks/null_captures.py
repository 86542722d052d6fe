"""Null captures: untouched simulated captures of the papers' materials through ``wardjax diagnose``'s discovery.

Nothing is hidden in these captures: the only effect truly present is the material's own anisotropy where
it has one (Table 1's desk, αx 0.137 / αy 0.15, and marble, 0.041 / 0.056; the satin is isotropic), which
the isotropic baseline lacks. Any other name is a false one; the right verdict on the satin is "nothing
needed", on the desk and marble "found anisotropy" then nothing further.
Each case is simulated (``wardjax simulate``'s forward model, or Radiance with ``--renderer
radiance``), reconstructed as ``diagnose`` does (:func:`wardjax.effects._capture.capture_data`, 6,000 samples
per channel) and discovered with the texture carried; one CSV row per case with the commit, date and load::

    python -m benchmarks.null_captures --materials desk marble satin metal --textures wood none --seeds 0 1 2
    python -m benchmarks.null_captures --summary          # the null rate of the stored rows

Rows are appended to ``benchmarks/results/null_captures.csv`` (``--out``), so an interrupted run resumes
with ``--append`` (cases already in the file are skipped).
"""

from __future__ import annotations

import argparse
import csv
import os
import tempfile
import time
from pathlib import Path

import numpy as np

from benchmarks.bench_diagnose import _commit

OUT = Path(__file__).parent / "results" / "null_captures.csv"
FIELDS = (
    "material",
    "texture",
    "renderer",
    "size",
    "seed",
    "found",
    "partial",
    "gap_before",
    "gap_after",
    "dof",
    "verdict",
    "rho_s",
    "rho_s_sigma",
    "rho_s_true",
    "alpha",
    "alpha_sigma",
    "alpha_true",
    "seconds",
    "commit",
    "date",
    "load",
)


def materials() -> dict:
    """The image-based paper's Table 1 materials, a satin (the fit notebook's) and a metal.

    The metal is dark and glossy (ρd 0.03, ρs 0.35, α 0.08, grey): the lobe is ~30× the diffuse floor, so
    the exposure set by the highlight leaves the floor a few codes above black.
    """
    import wardjax as wj
    from wardjax._data import table1_materials

    out = dict(table1_materials())
    out["satin"] = wj.WardParams(rho_d=(0.2, 0.3, 0.5), rho_s=0.06, alpha_x=0.09, alpha_y=0.09)
    out["metal"] = wj.WardParams(rho_d=(0.03, 0.03, 0.03), rho_s=0.35, alpha_x=0.08, alpha_y=0.08)
    return out


def run_case(material: str, texture: str, renderer: str, size: tuple[int, int], seed: int) -> dict:
    """Simulate one untouched capture, run discovery on it as ``diagnose`` does, and return its CSV row."""
    import wardjax as wj
    from wardjax.effects import ScanlineModel, discover
    from wardjax.effects._capture import capture_data

    p = materials()[material]
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        cap = wj.simulate_capture(p, Path(tmp) / "cap", seed=seed, image_size=size, texture=texture, renderer=renderer)
        data = capture_data(cap, max_samples=6000)
        rep = discover(ScanlineModel(cap.config.fit.normalization), data, texture=True)
    av = rep.averaged
    return {
        "material": material,
        "texture": texture,
        "renderer": renderer,
        "size": f"{size[0]}x{size[1]}",
        "seed": seed,
        "found": " ".join(rep.found) or "-",
        "partial": " ".join(rep.partial) or "-",
        "gap_before": f"{rep.gap[0]:.4f}",
        "gap_after": f"{rep.gap[-1]:.4f}",
        "dof": rep.final.dof,
        "verdict": rep.verdict(),
        "rho_s": f"{av['rho_s']['value']:.6g}",
        "rho_s_sigma": f"{av['rho_s']['sigma']:.3g}",
        "rho_s_true": f"{float(p.rho_s):.6g}",
        "alpha": f"{av['alpha']['value']:.6g}",
        "alpha_sigma": f"{av['alpha']['sigma']:.3g}",
        "alpha_true": f"{float(np.sqrt(float(p.alpha_x) * float(p.alpha_y))):.6g}",
        "seconds": f"{time.perf_counter() - t0:.0f}",
        "commit": _commit(),
        "date": time.strftime("%Y-%m-%d"),
        "load": f"{os.getloadavg()[0]:.1f}",
    }


def _robust_sd(z: np.ndarray) -> float:
    """1.4826 × the median absolute deviation: the SD of a normal sample, insensitive to a few outliers."""
    return float(1.4826 * np.median(np.abs(z - np.median(z)))) if z.size else float("nan")


def figures(rows: list[dict]) -> dict:
    """The bench's figures over ``rows``: null rate, clean verdicts, gaps in the noise band, z of ρs and α.

    An isotropic material's capture is *clean* (nothing is present); on the desk and marble anisotropy is.
    ``band``: the final gap within ``1 ± 2 √(2/dof)``. ``z``: ``(value − truth)/σ`` with the model-averaged σ.
    """
    present = {m: {"anisotropy"} if float(p.alpha_x) != float(p.alpha_y) else set() for m, p in materials().items()}
    false = [r for r in rows if set(r["found"].split()) - {"-"} - present[r["material"]]]
    clean = [r for r in rows if not present[r["material"]]]
    clean_ok = [r for r in clean if r["verdict"].startswith("nothing needed")]
    band = [r for r in rows if abs(float(r["gap_after"]) - 1.0) <= 2.0 * np.sqrt(2.0 / float(r["dof"]))]
    z = {
        k: np.array([(float(r[k]) - float(r[f"{k}_true"])) / float(r[f"{k}_sigma"]) for r in rows])
        for k in ("rho_s", "alpha")
    }
    return {"n": len(rows), "false": false, "clean": clean, "clean_ok": clean_ok, "band": band, "z": z}


def summary(path: Path) -> str:
    """The null rate, the gap band, z of ρs and α, and the verdicts of the rows in ``path``."""
    rows = list(csv.DictReader(path.open()))
    if not rows:
        return f"{path}: no rows"
    f = figures(rows)
    n = f["n"]
    zs, za = f["z"]["rho_s"], f["z"]["alpha"]
    lines = [
        f"{n} untouched captures: an effect not truly present named in {len(f['false'])} "
        f"({100 * len(f['false']) / n:.1f} %); clean (isotropic) captures read 'nothing needed' in "
        f"{len(f['clean_ok'])} of {len(f['clean'])}; final gap within 1 ± 2√(2/dof) in {len(f['band'])} of {n}",
        f"z (model-averaged σ): ρs robust SD {_robust_sd(zs):.2f} (median {np.median(zs):+.2f}), "
        f"α robust SD {_robust_sd(za):.2f} (median {np.median(za):+.2f})",
        "| material | texture | renderer | seed | found | gap | z ρs | z α | verdict |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for r, a, b in zip(rows, zs, za):
        lines.append(
            f"| {r['material']} | {r['texture']} | {r['renderer']} | {r['seed']} | {r['found']} | "
            f"{r['gap_before']} → {r['gap_after']} | {a:+.1f} | {b:+.1f} | {r['verdict']} |"
        )
    return "\n".join(lines)


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--materials", nargs="+", default=["desk", "marble", "satin", "metal"])
    ap.add_argument("--textures", nargs="+", default=["wood", "none"])
    ap.add_argument("--renderers", nargs="+", default=["wardjax"], choices=["wardjax", "radiance"])
    ap.add_argument("--seeds", nargs="+", type=int, default=[0, 1, 2])
    ap.add_argument("--size", nargs=2, type=int, default=[160, 120])
    ap.add_argument("--out", type=Path, default=OUT)
    ap.add_argument("--append", action="store_true", help="keep the rows already in --out and skip their cases")
    ap.add_argument("--summary", action="store_true", help="print the stored rows' null rate and stop")
    a = ap.parse_args(argv)
    if a.summary:
        print(summary(a.out))
        return
    done = set()
    if a.append and a.out.exists():
        done = {
            (r["material"], r["texture"], r["renderer"], r["size"], int(r["seed"]))
            for r in csv.DictReader(a.out.open())
        }
    else:
        a.out.parent.mkdir(parents=True, exist_ok=True)
        with a.out.open("w", newline="") as f:
            csv.DictWriter(f, FIELDS).writeheader()
    size = (a.size[0], a.size[1])
    for renderer in a.renderers:
        for material in a.materials:
            for texture in a.textures:
                for seed in a.seeds:
                    if (material, texture, renderer, f"{size[0]}x{size[1]}", seed) in done:
                        continue
                    row = run_case(material, texture, renderer, size, seed)
                    with a.out.open("a", newline="") as f:
                        csv.DictWriter(f, FIELDS).writerow(row)
                    print(
                        f"{material} {texture} {renderer} seed {seed}: {row['verdict']}; gap "
                        f"{row['gap_before']} → {row['gap_after']} ({row['seconds']} s)",
                        flush=True,
                    )
    print(summary(a.out))


if __name__ == "__main__":
    main()
