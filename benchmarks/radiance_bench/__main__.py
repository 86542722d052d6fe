"""``python -m benchmarks.radiance_bench``: the Radiance-physics bench, one command, resumable, with a progress bar."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from ._bench import key, read_rows, run_case, write_rows
from ._cases import CASES
from ._summary import summary, table, write_confusion

OUT = Path(__file__).resolve().parents[1] / "results" / "radiance_effects.csv"


def _size(text: str) -> tuple[int, int]:
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"--sizes: expected WIDTHxHEIGHT such as 160x120, got {text!r}") from None
    if w < 32 or h < 24:
        raise argparse.ArgumentTypeError(f"--sizes: at least 32x24, got {text!r}")
    return w, h


def plan(a: argparse.Namespace) -> list[tuple]:
    """Every capture of the run, seeds outermost (a short run covers every case once before repeating any)."""
    out = []
    for seed in a.seeds:
        for size in a.sizes:
            for case in a.cases:
                pairs = (
                    [(m, t) for m in a.materials for t in a.textures]
                    if case == "null"
                    else [(a.effect_material, a.effect_texture)]
                )
                out += [(case, m, t, seed, size, a.bits) for m, t in pairs]
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0].strip("`"))
    ap.add_argument("--cases", nargs="+", default=list(CASES), choices=list(CASES), metavar="CASE",
                    help=f"cases to draw (default all: {', '.join(CASES)})")  # fmt: skip
    ap.add_argument("--materials", nargs="+", default=["desk", "marble", "satin", "metal"],
                    choices=["desk", "marble", "satin", "metal"], help="the nulls' materials")  # fmt: skip
    ap.add_argument("--textures", nargs="+", default=["wood", "none"], choices=["wood", "none"],
                    help="the nulls' textures")  # fmt: skip
    ap.add_argument("--effect-material", default="satin", choices=["desk", "marble", "satin", "metal"])
    ap.add_argument("--effect-texture", default="none", choices=["wood", "none"])
    ap.add_argument("--seeds", nargs="+", type=int, default=[1, 2, 3])
    ap.add_argument("--sizes", nargs="+", type=_size, default=[(160, 120)], help="WIDTHxHEIGHT (default 160x120)")
    ap.add_argument("--bits", type=int, choices=[8, 16], default=8, help="8-bit sRGB or 16-bit linear PNGs")
    ap.add_argument("--out", type=Path, default=OUT, help="the CSV (rows already in it are skipped)")
    ap.add_argument("--keep", type=Path, default=None, help="keep the capture folders here")
    ap.add_argument("--summary", action="store_true", help="print the stored rows' figures and stop")
    ap.add_argument("--table", action="store_true", help="with --summary: one line per capture too")
    a = ap.parse_args(argv)
    rows = read_rows(a.out)
    if not a.summary:
        from tqdm import tqdm

        done = {key(r) for r in rows}
        todo = [p for p in plan(a) if (*map(str, p[:4]), f"{p[4][0]}x{p[4][1]}", str(p[5])) not in done]
        bar = tqdm(todo, unit="capture", file=sys.stderr, dynamic_ncols=True)
        for case, material, texture, seed, size, bits in bar:
            bar.set_description(f"{case} {material} {texture} seed {seed}")
            row = run_case(case, material, texture, seed, size, bits, keep=a.keep)
            rows.append(row)
            write_rows(a.out, rows)
            write_confusion(a.out.with_name(a.out.stem + "_confusion.csv"), rows)
            bar.write(f"{case} {material} {texture} seed {seed}: {row['outcome']}; found {row['found']}; gap "
                      f"{row['gap_before']} → {row['gap_after']}; {row['verdict']} ({row['seconds']} s)")  # fmt: skip
    print(summary(rows))
    if a.table:
        print("\n" + table(rows))
    return 0


if __name__ == "__main__":
    sys.exit(main())
