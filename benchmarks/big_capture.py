"""Benchmark: big 16-bit captures (12 MP and 50 MP) as ``wardjax fit`` runs them: peak memory and time.

Run with ``.venv/bin/python -m benchmarks.big_capture [--sizes 12,50] [--limit-gb 9.5]``.
For each size a capture (desk of the paper's Table 1, wood texture, 16-bit
linear TIFF) is simulated in a child process, then fitted in a fresh child
process exactly as a batch does it (:func:`wardjax.run.fit_one`: load,
reconstruct in bands, bin, fit, ρd texture band by band, outputs: tiled
``rho_d.tif``, ``rho_d.png``, ``texture.json``, …). The parent samples each
child's resident memory (psutil, every 20 ms) and kills it past
``--limit-gb`` (the machine is shared); the child reports its own peak
(``ru_maxrss``) and the time of each phase. The 12 MP run is the reference
the 50 MP one is compared with. Target: 50 MP in ≤ 8 GB.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

SIZES = {12: (4000, 3000), 50: (8192, 6144)}

SIMULATE = r"""
import json, resource, sys, time
import wardjax as wj
t = time.perf_counter()
desk = wj.WardParams(rho_d=(0.676,) * 3, rho_s=0.039, alpha_x=0.137, alpha_y=0.150)
wj.simulate_capture(desk, sys.argv[1], seed=0, image_size=(int(sys.argv[2]), int(sys.argv[3])), texture="wood",
                    encoding="linear", bit_depth=16, image_format="tif")
print(json.dumps({"simulate_s": time.perf_counter() - t,
                  "peak_rss_gb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20}))
"""

FIT = r"""
import json, resource, sys, time
t0 = time.perf_counter()
from pathlib import Path
import wardjax as wj
from wardjax.run import _fit_capture, fit_one
from wardjax import export
phases = {}
fit_capture, write = _fit_capture.fit_capture, export.write_capture_outputs
def timed(name, fn):
    def run(*a, **k):
        t = time.perf_counter()
        try:
            return fn(*a, **k)
        finally:
            phases[name] = time.perf_counter() - t
    return run
import wardjax.run._batch as batch
batch.load_capture = timed("load_s", batch.load_capture)
_fit_capture_timed = timed("fit_s", fit_capture)
batch.FITTERS["scanline"] = lambda cap, out, created: timed("outputs_s", write)(_fit_capture_timed(cap), out, created=created)
t1 = time.perf_counter()
item, tb = fit_one(Path(sys.argv[1]), "big", Path(sys.argv[2]), "2026-01-01T00:00:00Z")
t2 = time.perf_counter()
assert item.status == "ok", (item.error, tb)
p = item.params["params"]
print(json.dumps({**phases, "import_s": t1 - t0, "total_s": t2 - t1,
                  "peak_rss_gb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20,
                  "rho_s": p["rho_s"], "alpha_x": p["alpha_x"], "alpha_y": p["alpha_y"],
                  "binning": item.params["fit"]["diagnostics"]["binning"],
                  "texture_region": json.loads((Path(sys.argv[2]) / "big" / "texture.json").read_text())["region_source"]}))
"""


def _run_watched(args: list[str], limit_gb: float) -> tuple[dict, float]:
    """Run a child, sample its RSS, kill it past ``limit_gb``; its JSON line and the sampled peak (GB)."""
    import psutil

    proc = subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    ps, peak = psutil.Process(proc.pid), 0.0
    while proc.poll() is None:
        try:
            rss = ps.memory_info().rss / 2**30
        except psutil.NoSuchProcess:
            break
        peak = max(peak, rss)
        if rss > limit_gb:
            proc.kill()
            proc.wait()
            raise RuntimeError(f"{args[2:4]}: killed at {rss:.2f} GB resident (limit {limit_gb} GB)")
        time.sleep(0.02)
    out, err = proc.communicate()
    if proc.returncode != 0:
        raise RuntimeError(f"child failed ({proc.returncode}): {err.strip().splitlines()[-1:]}")
    return json.loads(out.strip().splitlines()[-1]), peak


def measure(mp: int, tmp: Path, limit_gb: float) -> dict:
    """Simulate and fit one capture of ``mp`` megapixels; the figures of both children."""
    w, h = SIZES[mp]
    folder = tmp / f"cap{mp}"
    sim, sim_peak = {"simulate_s": float("nan"), "peak_rss_gb": float("nan")}, float("nan")
    if not (folder / "capture.toml").exists():  # --work: a capture simulated by an earlier run is reused
        sim, sim_peak = _run_watched([sys.executable, "-c", SIMULATE, str(folder), str(w), str(h)], limit_gb)
    fit, fit_peak = _run_watched([sys.executable, "-c", FIT, str(folder), str(tmp / f"out{mp}")], limit_gb)
    return {
        "size": f"{w}×{h}",
        "mp": w * h / 1e6,
        "simulate": sim,
        "simulate_sampled_gb": sim_peak,
        **fit,
        "sampled_peak_gb": fit_peak,
    }


def main(sizes=(12, 50), limit_gb: float = 9.5, work: str | None = None) -> list[dict]:
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for mp in sizes:
            r = measure(mp, Path(work or tmp), limit_gb)
            rows.append(r)
            print(json.dumps(r), flush=True)
    print(f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores (wall times grow with it)")
    print("capture     | load s | fit s (cold) | outputs s | total s | peak RSS GB | simulate s (peak GB)")
    for r in rows:
        print(
            f"{r['size']:>11} | {r['load_s']:6.1f} | {r['fit_s']:12.1f} | {r['outputs_s']:9.1f} | {r['total_s']:7.1f} |"
            f" {r['peak_rss_gb']:11.2f} | {r['simulate']['simulate_s']:.0f} ({r['simulate']['peak_rss_gb']:.2f})"
        )
        print(
            f"    αx {r['alpha_x']:.4f} αy {r['alpha_y']:.4f} ρs {r['rho_s']:.4f} binning {r['binning']}; "
            f"texture.json: {r['texture_region']}"
        )
    if len(rows) == 2:
        a, b = rows
        print(
            f"{b['mp'] / a['mp']:.1f}× the pixels: peak memory ×{b['peak_rss_gb'] / a['peak_rss_gb']:.2f}, "
            f"time ×{b['total_s'] / a['total_s']:.2f}"
        )
    return rows


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", default="12,50", help="megapixels, among 12 and 50")
    ap.add_argument("--limit-gb", type=float, default=9.5, help="kill a child whose RSS passes this")
    ap.add_argument("--work", default=None, help="folder for the captures, kept and reused [default: a temporary one]")
    a = ap.parse_args()
    main(tuple(int(s) for s in a.sizes.split(",")), a.limit_gb, a.work)
