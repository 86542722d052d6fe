"""Screenshots of two ``wardjax report`` pages in headless Chromium: a demo batch and the smartphone example.

    python -m benchmarks.report_screenshots --out report-shots        # needs `chromium` on PATH
    python -m benchmarks.report_screenshots --out report-shots --docs docs/img   # + the manual's copies

1. ``wardjax demo --out OUT/demo`` (skipped when ``OUT/demo/fits`` exists): the
   desk and marble of the image-based paper's Table 1, simulated and fitted,
   and the shipped smartphone example;
2. ``wardjax diagnose`` on the desk, written beside its fit
   (``OUT/demo/fits/desk/diagnose/``, skipped when there), so that the report
   shows a missing-effect gap chart;
3. ``wardjax fit examples/smartphone --out OUT/phone``: the smartphone example
   alone (a real ColorChecker photo, its colour correction, three thresholds);
4. ``wardjax report`` on each → ``OUT/demo.html``, ``OUT/phone.html``;
5. ``chromium --headless --screenshot`` of each page at 1280 px wide, the
   blank bottom cropped → ``OUT/demo.png``, ``OUT/phone.png``, and the same
   cut into 1600 px high tiles (``OUT/demo-1.png`` …) for reading;
6. with ``--docs DIR``: the copies the manual shows (``docs/report.md``),
   each part of a page printed on its own, scaled to 960 px wide and reduced
   to a 256-colour palette: ``report-batch.png`` (the demo's batch table and
   figure), ``report-desk.png`` (a scanline capture's section, gap chart
   included) and ``report-phone.png`` (the smartphone example's section).

Install Chromium with ``apt-get install -y chromium`` (Debian). The HTML the
screenshots show is checked in the test suite (``tests/test_report.py``:
units, intervals, correlations); the screenshots themselves are for a reader.
"""

from __future__ import annotations

import argparse
import io
import re
import shutil
import subprocess
import sys
from pathlib import Path

import imageio.v3 as iio
import numpy as np

from wardjax._files import write_bytes_atomic

ROOT = Path(__file__).resolve().parents[1]
WIDTH, MAX_HEIGHT, TILE = 1280, 16000, 1600
DOCS_WIDTH = 960  # the manual's copies: narrower than the page, still legible


def _run(*args: str) -> None:
    print("$", " ".join(args), flush=True)
    subprocess.run(args, check=True)


def _wardjax() -> str:
    exe = Path(sys.executable).with_name("wardjax")
    return str(exe) if exe.is_file() else "wardjax"


def screenshot(html: Path, png: Path, browser: str, *, tiles: bool = True) -> list[Path]:
    """Screenshot ``html`` (1280 px wide), crop the blank bottom, write it (and its tiles); return their paths."""
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
    for i, y in enumerate(range(0, img.shape[0], TILE) if tiles else (), start=1):
        tile = png.with_name(f"{png.stem}-{i}.png")
        _write_png(tile, img[y : y + TILE])
        out.append(tile)
    return out


def _write_png(path: Path, img: np.ndarray) -> None:
    buf = io.BytesIO()
    iio.imwrite(buf, img, extension=".png")
    write_bytes_atomic(path, buf.getvalue())


# The manual's copies: (file, page, part), part "batch" or a capture's name.
DOCS_PARTS = (
    ("report-batch.png", "demo", "batch"),
    ("report-desk.png", "demo", "desk"),
    ("report-phone.png", "phone", "colorchecker-red"),
)


def part_html(page: str, part: str) -> str:
    """The report page cut to one part: ``"batch"`` (all before the first capture) or one capture's section.

    The page's head (its styles) is kept; the body holds only the part, each cut
    made at the start of the output block that holds a capture's heading (so the
    heading keeps the block's styles). A cut through nested ``<div>``s is closed
    by the browser.
    """
    body = re.search(r"<body[^>]*>", page)
    block = '<div class="jp-OutputArea-child">'
    heads = [page.rindex(block, 0, m.start()) for m in re.finditer(r"<h2 id=[\"']capture-", page)]
    if body is None or not heads:
        raise ValueError("not a wardjax report page")
    if part == "batch":
        start, end = body.end(), heads[0]
    else:
        m = re.search(rf"<h2 id=[\"']capture-{re.escape(part)}[\"']", page)
        if m is None:
            raise ValueError(f"no section for capture {part!r}")
        start = page.rindex(block, 0, m.start())
        end = next((h for h in heads if h > start), page.rindex("</body>"))
    return page[: body.end()] + page[start:end] + "</body></html>"


def docs_copy(png: Path, dest: Path) -> Path:
    """``png`` scaled to `DOCS_WIDTH` px wide, as a 256-colour PNG (optimised): the manual's copy."""
    from PIL import Image

    with Image.open(png) as im:
        rgb = im.convert("RGB")
        h = round(rgb.height * DOCS_WIDTH / rgb.width)
        small = rgb.resize((DOCS_WIDTH, h), Image.Resampling.LANCZOS)
        small = small.quantize(colors=256, method=Image.Quantize.MEDIANCUT, dither=Image.Dither.NONE)
        buf = io.BytesIO()
        small.save(buf, format="PNG", optimize=True)
    write_bytes_atomic(dest, buf.getvalue())
    return dest


def docs_copies(out: Path, docs: Path, browser: str) -> None:
    """Each of `DOCS_PARTS` printed alone and reduced for the manual (``docs_copy``)."""
    docs.mkdir(parents=True, exist_ok=True)
    for fname, page, part in DOCS_PARTS:
        html = out / f"{page}-{part}.html"
        write_bytes_atomic(html, part_html((out / f"{page}.html").read_text(encoding="utf-8"), part).encode())
        shot = screenshot(html, out / f"{page}-{part}.png", browser, tiles=False)[0]
        print("wrote", docs_copy(shot, docs / fname))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=Path("report-shots"))
    ap.add_argument("--docs", type=Path, default=None, help="also write the manual's copies of the tiles here")
    args = ap.parse_args(argv)
    browser = shutil.which("chromium") or shutil.which("chromium-browser") or shutil.which("google-chrome")
    if browser is None:
        print("no chromium on PATH: apt-get install -y chromium", file=sys.stderr)
        return 2
    out = args.out
    wj = _wardjax()
    if not (out / "demo" / "fits").is_dir():
        _run(wj, "demo", "--out", str(out / "demo"))
    diagnosed = out / "demo" / "fits" / "desk" / "diagnose"
    if not (diagnosed / "report.json").is_file():
        _run(wj, "diagnose", str(out / "demo" / "captures" / "desk"), "--out", str(diagnosed))
    _run(wj, "fit", str(ROOT / "examples" / "smartphone"), "--out", str(out / "phone"))
    for name, fits in (("demo", out / "demo" / "fits"), ("phone", out / "phone")):
        html = out / f"{name}.html"
        _run(wj, "report", str(fits), "-o", str(html))
        for p in screenshot(html, out / f"{name}.png", browser):
            print("wrote", p)
    if args.docs is not None:
        docs_copies(out, args.docs, browser)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
