"""Benchmark: big 16-bit captures (12 MP and 50 MP) as ``wardjax fit`` runs them: peak memory and time.

Run with ``.venv/bin/python -m benchmarks.big_capture [--sizes 12,50] [--limit-gb 9.5]``.
The 12 MP capture (desk of the paper's Table 1, wood texture, 16-bit
linear TIFF) is simulated in a child process; the 50 MP one (8192 × 6144) is
made from it by :func:`upscale_capture` (the same scene through a longer lens,
written strip by strip; ``--simulate`` renders it instead: minutes and ~7 GB).
Each is then fitted in a fresh child process exactly as a batch does it (:func:`wardjax.run.fit_one`: load,
reconstruct in bands, bin, fit, ρd texture band by band, outputs: tiled
``rho_d.tif``, ``rho_d.png``, ``texture.json``, …). The parent samples each
child's resident memory (psutil, every 20 ms) and kills it past
``--limit-gb`` (the machine is shared); the child reports its own peak
(``ru_maxrss``) and the time of each phase. The 12 MP run is the reference
the 50 MP one is compared with. Target: 50 MP in ≤ 8 GB. The images are
read in bands (``read_in_bands`` in the output; ``--tiles`` makes the 50 MP
TIFFs compressed and tiled, read tile by tile, instead of plain strips).
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
read_in_bands = []
def load(path, _load=timed("load_s", batch.load_capture)):
    cap = _load(path)
    read_in_bands.append(bool(getattr(getattr(cap, "images", None), "banded", False)))  # before banding: False
    return cap
batch.load_capture = load
_fit_capture_timed = timed("fit_s", fit_capture)
batch.FITTERS["scanline"] = lambda cap, out, created: timed("outputs_s", write)(_fit_capture_timed(cap), out, created=created)
t1 = time.perf_counter()
item, tb = fit_one(Path(sys.argv[1]), "big", Path(sys.argv[2]), time.strftime("%Y-%m-%dT%H:%M:%SZ"), force=True)
t2 = time.perf_counter()
assert item.status == "ok", (item.error, tb)
p = item.params["params"]
print(json.dumps({**phases, "import_s": t1 - t0, "total_s": t2 - t1,
                  "peak_rss_gb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20,
                  "rho_s": p["rho_s"], "alpha_x": p["alpha_x"], "alpha_y": p["alpha_y"],
                  "binning": item.params["fit"]["diagnostics"]["binning"], "read_in_bands": all(read_in_bands),
                  "texture_region": json.loads((Path(sys.argv[2]) / "big" / "texture.json").read_text())["region_source"]}))
"""


def upscale_capture(src: Path, dst: Path, width: int, height: int, rows: int = 256, tiles: bool = False) -> dict:
    """Make a ``width × height`` capture from ``src`` cheaply: its images enlarged by pixel replication.

    The same scene seen by a camera of ``s = width / W`` times the focal length
    (in pixels) and resolution: ``focal_px`` and the principal point scale by
    ``s`` (pixel centres: ``c' = (c + ½) s − ½``), each pixel of the new
    image takes the value of the source pixel it falls in. Written strip by
    strip (tifffile, ``rows`` rows at a time), so no whole image is ever in
    memory: a 50 MP capture costs seconds, where simulating one costs minutes
    and ~7 GB. The images are the source's (texture, noise) seen larger, not a
    new rendering; the fit still recovers the material (it is the same).
    ``tiles`` writes zlib-compressed 256 × 256 tiles instead of plain strips
    (the fit then decodes the tiles each band overlaps, not positioned reads).
    """
    import numpy as np
    import tifffile
    import tomlkit

    t = time.perf_counter()
    doc = tomlkit.parse((src / "capture.toml").read_text())
    cam = doc["camera"]
    w0, h0 = (int(v) for v in cam["image_size"])
    s = width / w0
    if abs(height / h0 - s) > 1e-9:
        raise ValueError(f"{width}×{height} is not {w0}×{h0} scaled")
    cam["image_size"] = [width, height]
    cam["focal_px"] = float(cam["focal_px"]) * s
    cam["principal_point"] = [(float(c) + 0.5) * s - 0.5 for c in cam["principal_point"]]
    dst.mkdir(parents=True, exist_ok=True)
    (dst / "capture.toml").write_text(tomlkit.dumps(doc))
    src_rows = np.minimum((np.arange(height) / s).astype(np.int64), h0 - 1)
    src_cols = np.minimum((np.arange(width) / s).astype(np.int64), w0 - 1)
    for name in (doc["images"]["lit"], doc["images"]["dark"]):
        image = tifffile.memmap(src / name, mode="r")  # uncompressed: read only the rows needed

        def strips(image=image):
            for r0 in range(0, height, rows):
                yield np.ascontiguousarray(image[src_rows[r0 : r0 + rows]][:, src_cols])

        def tile_rows(image=image, t=256):
            for r0 in range(0, height, t):
                band = image[src_rows[r0 : r0 + t]][:, src_cols]
                for c0 in range(0, width, t):
                    tile = np.zeros((t, t, 3), image.dtype)
                    part = band[:, c0 : c0 + t]
                    tile[: part.shape[0], : part.shape[1]] = part
                    yield tile

        layout = {"tile": (256, 256), "compression": "zlib"} if tiles else {"rowsperstrip": rows}
        data = tile_rows() if tiles else strips()
        tifffile.imwrite(dst / name, data, shape=(height, width, 3), dtype=image.dtype, photometric="rgb", **layout)
        del image
    return {"upscale_s": time.perf_counter() - t, "from": f"{w0}×{h0}"}


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


def measure(mp: int, tmp: Path, limit_gb: float, upscale: bool = True, tiles: bool = False) -> dict:
    """Simulate and fit one capture of ``mp`` megapixels; the figures of both children."""
    w, h = SIZES[mp]
    folder = tmp / (f"cap{mp}" + ("-tiles" if tiles and mp != 12 else ""))
    sim, sim_peak = {"simulate_s": float("nan"), "peak_rss_gb": float("nan")}, float("nan")
    if (folder / "capture.toml").exists():  # --work: a capture made by an earlier run is reused
        pass
    elif mp != 12 and upscale and (tmp / "cap12" / "capture.toml").exists():
        sim = upscale_capture(tmp / "cap12", folder, w, h, tiles=tiles)
    else:
        sim, sim_peak = _run_watched([sys.executable, "-c", SIMULATE, str(folder), str(w), str(h)], limit_gb)
    fit, fit_peak = _run_watched([sys.executable, "-c", FIT, str(folder), str(tmp / f"out{mp}")], limit_gb)
    return {
        "size": f"{w}×{h}" + (" tiles" if tiles and mp != 12 else ""),
        "mp": w * h / 1e6,
        "simulate": sim,
        "simulate_sampled_gb": sim_peak,
        **fit,
        "sampled_peak_gb": fit_peak,
    }


def main(
    sizes=(12, 50), limit_gb: float = 9.5, work: str | None = None, upscale: bool = True, tiles: bool = False
) -> list[dict]:
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for mp in sizes:
            r = measure(mp, Path(work or tmp), limit_gb, upscale, tiles)
            rows.append(r)
            print(json.dumps(r), flush=True)
    print(f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores (wall times grow with it)")
    print("capture     | load s | fit s (cold) | outputs s | total s | peak RSS GB | made by")
    for r in rows:
        print(
            f"{r['size']:>11} | {r['load_s']:6.1f} | {r['fit_s']:12.1f} | {r['outputs_s']:9.1f} | {r['total_s']:7.1f} |"
            f" {r['peak_rss_gb']:11.2f} | {json.dumps(r['simulate'])}"
        )
        print(
            f"    αx {r['alpha_x']:.4f} αy {r['alpha_y']:.4f} ρs {r['rho_s']:.4f} binning {r['binning']}; "
            f"texture.json: {r['texture_region']}; images read in bands: {r.get('read_in_bands', False)}"
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
    ap.add_argument(
        "--simulate",
        action="store_true",
        help="simulate the 50 MP capture (minutes, ~7 GB) instead of enlarging the 12 MP one (upscale_capture)",
    )
    ap.add_argument(
        "--tiles",
        action="store_true",
        help="write the enlarged captures as zlib-compressed 256² tiles (read tile by tile) instead of plain strips",
    )
    a = ap.parse_args()
    main(tuple(int(s) for s in a.sizes.split(",")), a.limit_gb, a.work, not a.simulate, a.tiles)
