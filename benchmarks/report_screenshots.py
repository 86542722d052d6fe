"""Screenshots of two ``wardjax report`` pages in headless Chromium: a demo batch and the smartphone example.

    python -m benchmarks.report_screenshots --out report-shots        # needs `chromium` on PATH

1. ``wardjax demo --out OUT/demo`` (skipped when ``OUT/demo/fits`` exists): the
   desk and marble of the image-based paper's Table 1, simulated and fitted,
   and the shipped smartphone example;
2. ``wardjax fit examples/smartphone --out OUT/phone``: the smartphone example
   alone (a real ColorChecker photo, its colour correction, three thresholds);
3. ``wardjax report`` on each → ``OUT/demo.html``, ``OUT/phone.html``;
4. ``chromium --headless --screenshot`` of each page at 1280 px wide, the
   blank bottom cropped → ``OUT/demo.png``, ``OUT/phone.png``, and the same
   cut into 1600 px high tiles (``OUT/demo-1.png`` …) for reading.

Install Chromium with ``apt-get install -y chromium`` (Debian). The HTML the
screenshots show is checked in the test suite (``tests/test_report.py``:
units, intervals, correlations); the screenshots themselves are for a reader.
"""

from __future__ import annotations

import argparse
import io
import shutil
import subprocess
import sys
from pathlib import Path

import imageio.v3 as iio
import numpy as np

from wardjax._files import write_bytes_atomic

ROOT = Path(__file__).resolve().parents[1]
WIDTH, MAX_HEIGHT, TILE = 1280, 16000, 1600


def _run(*args: str) -> None:
    print("$", " ".join(args), flush=True)
    subprocess.run(args, check=True)


def _wardjax() -> str:
    exe = Path(sys.executable).with_name("wardjax")
    return str(exe) if exe.is_file() else "wardjax"


def screenshot(html: Path, png: Path, browser: str) -> list[Path]:
    """Screenshot ``html`` (1280 px wide), crop the blank bottom, write it and its tiles; return their paths."""
    raw = png.with_suffix(".raw.png")
    _run(
        browser,
        "--headless",
        "--no-sandbox",
        "--disable-gpu",
        "--hide-scrollbars",
        f"--window-size={WIDTH},{MAX_HEIGHT}",
        f"--screenshot={raw}",
        html.resolve().as_uri(),
    )
    img = iio.imread(raw)[..., :3]
    raw.unlink()
    rows = np.flatnonzero(np.any(img < 250, axis=(1, 2)))
    img = img[: (rows[-1] + 20 if rows.size else img.shape[0])]
    out = [png]
    _write_png(png, img)
    for i, y in enumerate(range(0, img.shape[0], TILE), start=1):
        tile = png.with_name(f"{png.stem}-{i}.png")
        _write_png(tile, img[y : y + TILE])
        out.append(tile)
    return out


def _write_png(path: Path, img: np.ndarray) -> None:
    buf = io.BytesIO()
    iio.imwrite(buf, img, extension=".png")
    write_bytes_atomic(path, buf.getvalue())


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=Path("report-shots"))
    args = ap.parse_args(argv)
    browser = shutil.which("chromium") or shutil.which("chromium-browser") or shutil.which("google-chrome")
    if browser is None:
        print("no chromium on PATH: apt-get install -y chromium", file=sys.stderr)
        return 2
    out = args.out
    wj = _wardjax()
    if not (out / "demo" / "fits").is_dir():
        _run(wj, "demo", "--out", str(out / "demo"))
    _run(wj, "fit", str(ROOT / "examples" / "smartphone"), "--out", str(out / "phone"))
    for name, fits in (("demo", out / "demo" / "fits"), ("phone", out / "phone")):
        html = out / f"{name}.html"
        _run(wj, "report", str(fits), "-o", str(html))
        for p in screenshot(html, out / f"{name}.png", browser):
            print("wrote", p)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
