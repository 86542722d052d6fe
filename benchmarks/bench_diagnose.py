"""``wardjax diagnose`` on a 320 × 240 capture: cold and warm compile cache, beside the figure before.

A capture is written by ``wardjax simulate`` (default material and wood
texture, and the same with ``--texture none``); ``wardjax diagnose`` then runs
in a fresh subprocess twice per capture, each capture with its own compile
cache folder (``wardjax --cache-dir``, :func:`wardjax.run._cache.enable_compile_cache`):

- *cold*: the cache folder empty (every program is compiled);
- *warm*: the same folder again, now populated by the cold run.

For each run it prints the wall time, the CPU time of the subprocess (user +
system: what the run cost, less sensitive than the wall time to other
processes on a shared machine) and the 1-minute load average before and
after, what diagnose found (effects named, gap before → after), each stage's
line of ``diagnose --progress`` (its wall time and the part spent compiling; kept
in the JSON as ``stages``), and the ratio
to the figures measured with this benchmark on the code before the speed work
(:data:`BEFORE`, recorded with its commit and date: the old code cannot be
run from this tree). The issue's target (13, item 5): ≤ 15 s warm, ≤ 30 s cold
on the 2-core machine.

``wardjax diagnose`` carries the ρd texture by default (a Gaussian process,
:mod:`wardjax.effects._texture`, binned to 6,000 pixels per channel); on the
textured captures the benchmark also times ``diagnose --no-texture`` (20,000
pixels, the path :data:`BEFORE` measured) beside it.

Run alone: ``python -m benchmarks.bench_diagnose [--size 320 240] [--textures wood none] [--terms on off]
[--json out.json]`` (``--terms on``: only the default, texture-carrying run).
"""

from __future__ import annotations

import argparse
import functools
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

# This benchmark run on main at ee80ae7 (2026-11-25 20:34 UTC, before the speed work) on the 2-core machine
# shared with other sessions: (wall s, CPU s, 1-min load average at the start) per texture and cache state.
BEFORE = {
    "commit": "ee80ae7",
    "date": "2026-11-25",
    "runs": {
        ("wood", "cold"): (52.2, 39.4, 5.1),
        ("wood", "warm"): (47.5, 30.1, 4.7),
        ("none", "cold"): (86.0, 59.1, 5.1),
        ("none", "warm"): (69.4, 45.4, 5.9),
    },
}
TARGET = {"cold": 30.0, "warm": 15.0}

_CLI = [sys.executable, "-c", "import sys; from wardjax.run._cli import main; sys.argv[0] = 'wardjax'; main()"]


def _run(args: list[str]) -> tuple[float, float, float, float, subprocess.CompletedProcess]:
    """Run the CLI with ``args`` in a subprocess: wall s, CPU s (user + system), load before and after."""
    load0 = os.getloadavg()[0]
    r0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    proc = subprocess.run(_CLI + args, capture_output=True, text=True, check=False)
    wall = time.perf_counter() - t0
    r1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (r1.ru_utime - r0.ru_utime) + (r1.ru_stime - r0.ru_stime)
    if proc.returncode != 0:
        raise RuntimeError(f"wardjax {' '.join(args)} failed ({proc.returncode}): {proc.stderr.strip()[-500:]}")
    return wall, cpu, load0, os.getloadavg()[0], proc


def _stages(stderr: str) -> list[str]:
    """The stage lines ``diagnose --progress`` printed (``✓ name (s, of which compiling s)``), in order."""
    return [ln[2:].strip() for ln in stderr.splitlines() if ln.startswith("✓ ")]


def _found(report_dir: Path) -> str:
    rep = json.loads((report_dir / "report.json").read_text())
    names = ", ".join(rep["found"]) or "nothing"
    return f"{names}; gap " + " → ".join(f"{g:.3f}" for g in rep["gap"])


def _commit() -> str:
    """The checkout's short commit (``+`` if it has uncommitted changes), or ``"unknown"`` outside git."""
    try:
        run = functools.partial(subprocess.run, capture_output=True, text=True, check=True, cwd=Path(__file__).parent)
        head = run(["git", "rev-parse", "--short", "HEAD"]).stdout.strip()
        dirty = run(["git", "status", "--porcelain", "--untracked-files=no"]).stdout.strip()
        return head + ("+" if dirty else "")
    except (OSError, subprocess.CalledProcessError):
        return "unknown"


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(prog="python -m benchmarks.bench_diagnose")
    ap.add_argument("--size", type=int, nargs=2, default=(320, 240), metavar=("W", "H"))
    ap.add_argument("--textures", nargs="+", default=["wood", "none"], choices=["wood", "marble", "none"])
    ap.add_argument("--terms", nargs="+", default=["on", "off"], choices=["on", "off"], help="texture term runs")
    ap.add_argument("--json", default=None, help="write the figures here")
    a = ap.parse_args(argv)
    size = [str(v) for v in a.size]
    rows = []
    print(f"wardjax diagnose, {size[0]} × {size[1]} capture, {os.cpu_count()} CPU cores; before = {BEFORE['commit']}")
    print(
        f"{'texture':8s} {'term':4s} {'cache':5s} {'wall s':>7s} {'CPU s':>7s} {'load':>9s} "
        f"{'before s':>9s} {'ratio':>6s} {'CPU before':>10s}  found"
    )
    with tempfile.TemporaryDirectory(prefix="bench_diagnose_") as tmp:
        root = Path(tmp)
        for tex in a.textures:
            cap = root / f"capture_{tex}"
            _run(["simulate", str(cap), "--texture", tex, "--size", *size])
            terms = tuple(t == "on" for t in a.terms) if tex != "none" else (True,)  # the default, then --no-texture
            for term, state in [(t, s) for t in terms for s in ("cold", "warm")]:
                cache = root / f"cache_{tex}_{term}"  # empty: the first diagnose compiles everything
                out = root / f"report_{tex}_{term}_{state}"
                extra = [] if term else ["--no-texture"]
                wall, cpu, l0, l1, proc = _run(
                    ["--cache-dir", str(cache), "diagnose", str(cap), "--out", str(out), "--progress", *extra]
                )
                before = BEFORE["runs"].get((tex, state)) if tuple(a.size) == (320, 240) else None
                ratio = f"{before[0] / wall:5.2f}×" if before else "     —"
                row = {
                    "texture": tex,
                    "texture_term": term,
                    "cache": state,
                    "wall_s": wall,
                    "cpu_s": cpu,
                    "load_before": l0,
                    "load_after": l1,
                    "before_wall_s": before[0] if before else None,
                    "before_cpu_s": before[1] if before else None,
                    "found": _found(out),
                    "stages": _stages(proc.stderr),
                }
                rows.append(row)
                b_wall, b_cpu = (before[0], before[1]) if before else (float("nan"), float("nan"))
                print(
                    f"{tex:8s} {'on' if term else 'off':4s} {state:5s} {wall:7.1f} {cpu:7.1f} {l0:4.1f}→{l1:<4.1f} "
                    f"{b_wall:9.1f} {ratio} {b_cpu:10.1f}  {row['found']}",
                    flush=True,
                )
                for line in row["stages"]:
                    print(f"    {line}", flush=True)
    for term in sorted({r["texture_term"] for r in rows}):
        for state, lim in TARGET.items():
            worst = max(r["wall_s"] for r in rows if r["cache"] == state and r["texture_term"] == term)
            verdict = "met" if worst <= lim else "NOT met"
            on = "on" if term else "off"
            print(f"target {state}, texture term {on}: ≤ {lim:.0f} s; slowest {worst:.1f} s ({verdict})")
    out = {"size": list(a.size), "rows": rows, "before": {f"{k[0]}/{k[1]}": v for k, v in BEFORE["runs"].items()}}
    out |= {"commit": _commit(), "date": time.strftime("%Y-%m-%d"), "cpus": os.cpu_count()}  # what ran, where
    if a.json:
        Path(a.json).write_text(json.dumps(out, indent=2))
    return out


if __name__ == "__main__":
    main()
