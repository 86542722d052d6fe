"""Soak: many simulated captures fitted in one process — memory, compiled programs, results as fitting alone.

``python -m benchmarks.soak [--n 200] [--sizes 64x48,80x60,96x72] [--reference 12] [--json PATH]``

1. Simulates ``n`` small captures (our own renders: :func:`wardjax.simulate_capture`,
   random Ward parameters, the image sizes cycled), then fits them one after another
   in this process, each by its own :func:`wardjax.run_batch` call (the path of
   ``wardjax fit``).
2. After each fit: the resident set size (psutil, after ``gc.collect()``) and the
   number of XLA compilations so far (``jax.monitoring``'s backend-compile events).
3. In a fresh process, fits a sample of ``reference`` captures, each alone, and
   compares their ``params.json`` with the soak's (the ``created`` timestamp aside).

Prints, and writes as JSON: the RSS slope over captures 20…n (MB per 100 captures,
least squares), the compilations after each size's first capture, and the
number of ``params.json`` files equal to the fresh process's.
"""

from __future__ import annotations

import argparse
import gc
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

COMPILE_EVENT = "/jax/core/compile/backend_compile_duration"
WARM = 20  # captures before the RSS slope is measured: caches, allocator pools and imports settle


def make_captures(root: Path, n: int, sizes: list[tuple[int, int]], seed: int = 0) -> list[Path]:
    """``n`` simulated captures with random (anisotropic) Ward parameters, the sizes cycled."""
    import wardjax as wj

    rng = np.random.default_rng(seed)
    folders = []
    for i in range(n):
        rho_d = tuple(float(v) for v in rng.uniform(0.2, 0.7, 3))
        ax = float(rng.uniform(0.08, 0.2))
        p = wj.WardParams(rho_d=rho_d, rho_s=float(rng.uniform(0.02, 0.08)), alpha_x=ax, alpha_y=ax * 1.3)
        folder = root / f"cap{i:03d}"
        wj.simulate_capture(p, folder, seed=i, image_size=sizes[i % len(sizes)])
        folders.append(folder)
    return folders


def _params(path: Path) -> dict:
    doc = json.loads(path.read_text())
    doc.pop("created", None)
    return doc


def soak(captures: list[Path], out: Path) -> dict:
    """Fit ``captures`` one by one in this process; RSS and compilations after each."""
    import jax
    import psutil

    import wardjax as wj

    compiles = [0]
    jax.monitoring.register_event_duration_secs_listener(
        lambda event, duration, **kw: compiles.__setitem__(0, compiles[0] + (event == COMPILE_EVENT))
    )
    proc = psutil.Process()
    rss, n_compiled, seconds = [], [], []
    for cap in captures:
        t0 = time.perf_counter()
        (item,) = wj.run_batch([cap], out)
        if item.status != "ok":
            raise RuntimeError(f"{cap.name}: {item.error}")
        seconds.append(time.perf_counter() - t0)
        gc.collect()
        rss.append(proc.memory_info().rss / 2**20)
        n_compiled.append(compiles[0])
    return {"rss_mb": rss, "compiles": n_compiled, "seconds": seconds}


def fit_alone(captures: list[Path], out: Path) -> None:
    """Each capture fitted by its own :func:`wardjax.run_batch` call (run in a fresh process)."""
    import wardjax as wj

    for cap in captures:
        (item,) = wj.run_batch([cap], out)
        if item.status != "ok":
            raise RuntimeError(f"{cap.name}: {item.error}")


def figures(run: dict, captures: list[Path], sizes: list[tuple[int, int]], out: Path, ref_out: Path, ref) -> dict:
    """The soak's figures from its samples and the fresh process's fits of ``ref`` (indices)."""
    rss = np.asarray(run["rss_mb"])
    k = np.arange(len(rss))
    late = k >= WARM
    slope = float(np.polyfit(k[late], rss[late], 1)[0] * 100) if late.sum() >= 2 else float("nan")
    comp = np.asarray(run["compiles"])
    first_of_size = len(sizes)  # captures 0 … len(sizes)-1 are the first of each size
    after_warm = int(comp[-1] - comp[first_of_size - 1])
    per_capture = np.diff(np.concatenate([[0], comp]))
    same = sum(
        _params(out / captures[i].name / "params.json") == _params(ref_out / captures[i].name / "params.json")
        for i in ref
    )
    return {
        "captures": len(rss),
        "sizes": [f"{w}x{h}" for w, h in sizes],
        "rss_first_mb": float(rss[0]),
        "rss_at_warm_mb": float(rss[min(WARM, len(rss) - 1)]),
        "rss_last_mb": float(rss[-1]),
        "rss_max_mb": float(rss.max()),
        "rss_slope_mb_per_100": slope,
        "compiles_total": int(comp[-1]),
        "compiles_first_of_each_size": [int(c) for c in per_capture[:first_of_size]],
        "compiles_after_first_of_each_size": after_warm,
        "captures_that_compiled": [int(i) for i in np.flatnonzero(per_capture)],
        "reference_fitted_alone": len(ref),
        "reference_identical": int(same),
        "fit_seconds_median": float(np.median(run["seconds"][first_of_size:] or run["seconds"])),
    }


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=200)
    ap.add_argument("--sizes", default="64x48,80x60,96x72", help="image sizes WxH, cycled")
    ap.add_argument("--reference", type=int, default=12, help="captures refitted alone in a fresh process")
    ap.add_argument("--json", type=Path, default=None, help="write the figures here")
    ap.add_argument("--alone", nargs="+", type=Path, help=argparse.SUPPRESS)  # the fresh process's work
    ap.add_argument("--out", type=Path, help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.alone:
        fit_alone(args.alone, args.out)
        return {}
    sizes = [tuple(int(v) for v in s.split("x")) for s in args.sizes.split(",")]
    with tempfile.TemporaryDirectory(prefix="wardjax-soak-") as tmp:
        root = Path(tmp)
        t0 = time.perf_counter()
        captures = make_captures(root / "captures", args.n, sizes)  # type: ignore[arg-type]
        t_sim = time.perf_counter() - t0
        gc.collect()
        t0 = time.perf_counter()
        run = soak(captures, root / "out")
        t_fit = time.perf_counter() - t0
        ref = sorted({int(i) for i in np.linspace(0, args.n - 1, min(args.reference, args.n))})
        cmd = [sys.executable, "-m", "benchmarks.soak", "--out", str(root / "alone"), "--alone"]
        env = dict(os.environ, PYTHONPATH=str(Path(__file__).resolve().parents[1]))
        subprocess.run(cmd + [str(captures[i]) for i in ref], check=True, env=env)
        fig = figures(run, captures, sizes, root / "out", root / "alone", ref)  # type: ignore[arg-type]
    fig |= {"simulate_seconds": t_sim, "soak_seconds": t_fit, "rss_mb": run["rss_mb"], "compiles": run["compiles"]}
    print(f"soak: {fig['captures']} captures ({', '.join(fig['sizes'])}) fitted in one process in {t_fit:.0f} s")
    print(
        f"  RSS: {fig['rss_first_mb']:.0f} MB after the first, {fig['rss_at_warm_mb']:.0f} MB after {WARM}, "
        f"{fig['rss_last_mb']:.0f} MB after the last (max {fig['rss_max_mb']:.0f}); "
        f"slope over captures {WARM}–{fig['captures']}: {fig['rss_slope_mb_per_100']:+.2f} MB per 100 captures"
    )
    print(
        f"  XLA compilations: {fig['compiles_total']} in all, {fig['compiles_first_of_each_size']} at the first "
        f"capture of each size, {fig['compiles_after_first_of_each_size']} after; captures that compiled: "
        f"{fig['captures_that_compiled']}"
    )
    print(
        f"  results: {fig['reference_identical']} of {fig['reference_fitted_alone']} params.json identical to "
        "fitting each capture alone in a fresh process (created timestamp aside)"
    )
    if args.json:
        args.json.write_text(json.dumps(fig, indent=1))
    return fig


if __name__ == "__main__":
    main()
