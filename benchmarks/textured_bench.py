"""The textured hidden-effect bench: effects hidden by editing the image files of textured captures.

Every case is a capture ``wardjax simulate`` wrote (an isotropic Ward probe,
αx = αy = 0.12, except the anisotropy cases), with a procedural ρd texture
on the sample plane — ``noise`` (isotropic broadband), ``wood`` (rings and
grain), ``marble`` (veins) — at two amplitudes (4 % and 10 %), and one
effect hidden by an *edit of the lit image file*
(:func:`benchmarks.edited_captures.edit_capture`: decode, change, re-encode;
nothing of :mod:`wardjax.effects` makes the data). The library effect an
edit should be named as:

========================  ======================================  ======================
case                      edit (two strengths)                    expected first name
========================  ======================================  ======================
``response``              codes ``c ↦ c^k``, k = 1.06, 1.12       ``gamma``
``offset``                lit + 0.005, + 0.01 of full scale       ``ambient``
``gradient``              ramp ``1 + g s`` across the image,      ``illumination_gradient``
                          g = 0.12, 0.25
``saturation``            exposure × 1.4, × 1.7, clipped          ``saturation``
``anisotropy``            no edit: αx, αy = 0.12 e^{±η},          ``anisotropy``
                          η = 0.1, 0.2 (simulated)
``none``                  no edit                                 nothing (null)
``gradient_y``            ramp along the image rows (cancels)     nothing (null)
``blur``                  Gaussian blur of the lit frame,         outside the library
                          σ = 0.7, 1.5 px
``cast``                  lit frame × (1 + c, 1, 1 − c),          outside the library
                          c = 0.02, 0.05                          (a per-channel factor
                                                                  on the ratio: its
                                                                  specular part *is*
                                                                  ``coloured_specular``)
========================  ======================================  ======================

``discover`` runs as ``wardjax diagnose --texture`` does (texture term on,
stop rule on). One CSV row per case goes to
``benchmarks/results/textured_bench_stochastic.csv`` as soon as it is done (so a partial
run counts); ``--summary`` prints the confusion matrix (true effect × first
name), the null rate, the gap after discovery and the illumination ↔
anisotropy confusion, and writes them beside ``--out`` as ``*_confusion.csv``.

The cases run in rounds (strength × amplitude × seed), each round every
texture × case, so a run stopped early is still balanced across cases.

The captures' image files are 8-bit by default, as ``wardjax simulate``
writes them; ``--bit-depth 16`` writes 16-bit files, on which an edit's
re-encoding adds no banding of its own (``benchmarks/requantisation.py``:
on 8-bit files, rounded to nearest, the response edit's rounding is shared
by neighbouring pixels and channels). The edited frame is re-quantised by
stochastic rounding (``--rounding stochastic``, the default; drawn from the
case, so a rerun writes the same file): its error is white, as a camera's
own quantisation of a noisy signal is (``--rounding nearest`` rounds to
nearest; at 16 bits the two differ by 4·10⁻⁶ of full scale). Unedited
cases (``none``, ``anisotropy``) are the same under either rounding, and a
resumed run keeps their rows. The stored CSV is the current default run,
its first line the provenance (commit, machine, load, date); earlier runs
(rounded to nearest, 16-bit files, other covariances) are in the history of
``benchmarks/results/``.

Run ``python -m benchmarks.textured_bench [--size 160 120] [--seeds 0 1 2] [--bit-depth 8|16]
[--rounding stochastic|nearest] [--limit N] [--out CSV] [--append]`` or
``python -m benchmarks.textured_bench --summary [--out CSV]``.
"""

from __future__ import annotations

import argparse
import csv
import io
import itertools
import shutil
import tempfile
import time
from pathlib import Path

import numpy as np

from wardjax._files import write_bytes_atomic

from .edited_captures import ROUNDINGS, diagnose_folder, edit_capture, make_capture

__all__ = ["CASES", "EXPECTED", "cases", "run_case", "summarise"]

RESULTS = Path(__file__).parent / "results"
TEXTURES = ("noise", "wood", "marble")
AMPLITUDES = (0.04, 0.10)
# case → (edit kind or None, (weak, strong) amounts); anisotropy is simulated (η), not edited
CASES: dict[str, tuple[str | None, tuple[float, float]]] = {
    "gradient": ("gradient", (0.12, 0.25)),
    "anisotropy": (None, (0.1, 0.2)),
    "offset": ("offset", (0.005, 0.01)),
    "response": ("response", (1.06, 1.12)),
    "saturation": ("saturation", (1.4, 1.7)),  # × 2.5 clipped the standard too: those values are dropped
    "none": (None, (0.0, 0.0)),
    "gradient_y": ("gradient_y", (0.25, 0.25)),
    "blur": ("blur", (0.7, 1.5)),
    "cast": ("cast", (0.02, 0.05)),
}
EXPECTED = {
    "gradient": "illumination_gradient",
    "anisotropy": "anisotropy",
    "offset": "ambient",
    "response": "gamma",
    "saturation": "saturation",
    "none": "",
    "gradient_y": "",
    "blur": None,  # outside the library: no expected name
    "cast": None,
}
NULL = ("none", "gradient_y")
FIELDS = (
    "texture",
    "amplitude",
    "case",
    "strength",
    "amount",
    "seed",
    "size",
    "bits",
    "rounding",
    "expected",
    "found",
    "first",
    "ambiguous",
    "partial",
    "within_noise",
    "gap_before",
    "gap_after",
    "texture_read",
    "seconds",
)


def cases(seeds=(0,), strengths=("strong", "weak"), only=None):
    """Every bench case ``(seed, strength, amplitude, texture, case)``, in balanced rounds."""
    names = [c for c in CASES if only is None or c in only]
    for seed, strength, amp in itertools.product(seeds, strengths, AMPLITUDES):
        for tex, name in itertools.product(TEXTURES, names):
            yield seed, strength, amp, tex, name


def _base(tmp: Path, tex: str, amp: float, seed: int, size, eta: float = 0.0, bits: int = 8) -> Path:
    """The capture an edit starts from (made once per texture, amplitude, seed, η and bit depth)."""
    folder = tmp / f"base_{tex}_{amp}_{seed}_{eta}_{bits}"
    if not (folder / "capture.toml").exists():
        make_capture(folder, texture=tex, size=size, seed=seed, eta=eta, texture_amplitude=amp, bit_depth=bits)
    return folder


def run_case(
    tmp: Path,
    seed: int,
    strength: str,
    amp: float,
    tex: str,
    name: str,
    size,
    bits: int = 8,
    rounding: str = "stochastic",
) -> dict:
    """Make, edit and diagnose one case; the CSV row.

    ``rounding``: how the edited lit frame is re-quantised
    (:func:`benchmarks.edited_captures.requantise`); the stochastic draw is
    seeded by the case, so a rerun writes the same file.
    """
    kind, amounts = CASES[name]
    amount = amounts[0 if strength == "weak" else 1]
    eta = amount if name == "anisotropy" else 0.0
    # the null cases have no strength: their second round is another capture
    cap_seed = seed + 1000 if name in NULL and strength == "weak" else seed
    base = _base(tmp, tex, amp, cap_seed, size, eta, bits)
    folder = tmp / "case"
    if folder.exists():
        shutil.rmtree(folder)
    draw = [cap_seed, TEXTURES.index(tex), round(amp * 100), list(CASES).index(name), int(strength == "strong")]
    edit_capture(base, folder, kind, amount, rounding=rounding, seed=draw)
    t0 = time.perf_counter()
    rep = diagnose_folder(folder, texture=True)
    sec = time.perf_counter() - t0
    first = rep.found[0] if rep.found else ""
    tx = rep.settings.get("texture") or {}
    tx = {} if "refused" in tx else tx
    return {
        "texture": tex,
        "amplitude": amp,
        "case": name,
        "strength": strength,
        "amount": amount,
        "seed": seed,
        "size": f"{size[0]}x{size[1]}",
        "bits": bits,
        "rounding": rounding if kind else "",
        "expected": "(outside)" if EXPECTED[name] is None else EXPECTED[name],
        "found": "+".join(rep.found),
        "first": first,
        "ambiguous": "+".join(f"{a}|{b}" for a, b, _ in rep.ambiguous),
        "partial": "+".join(getattr(c, "effect", str(c)) for c in rep.partial),
        "within_noise": bool(getattr(rep, "within_noise", False)),
        "gap_before": round(float(rep.gap[0]), 4),
        "gap_after": round(float(rep.gap[-1]), 4),
        "texture_read": " ".join(f"{a:.3f}" for a in tx.get("amplitude", [])),
        "seconds": round(sec, 1),
    }


def _amount(name: str, strength: str) -> float:
    return CASES[name][1][0 if strength == "weak" else 1]


def _rounding(row: dict) -> str:
    """How a row's edit was re-quantised: ``""`` where nothing was edited (older rows: nearest)."""
    if CASES[row["case"]][0] is None:
        return ""
    return row.get("rounding") or "nearest"


def _key(case) -> tuple:
    """``(seed, strength, amplitude, texture, case)`` of a case tuple or a CSV row."""
    if isinstance(case, dict):
        case = (case["seed"], case["strength"], case["amplitude"], case["texture"], case["case"])
    seed, strength, amp, tex, name = case
    return int(seed), str(strength), float(amp), str(tex), str(name)


def provenance() -> str:
    """The ``# provenance:`` line a results file starts with: commit, machine, load, date."""
    import datetime
    import os
    import platform

    from .bench_diagnose import _commit

    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    return (
        f"# provenance: commit {_commit()}; machine {platform.system()} {platform.machine()}, "
        f"{os.cpu_count()} CPU cores; load average {load:.1f} at the last write; "
        f"date {datetime.date.today().isoformat()}\n"
    )


def _write(rows: list[dict], path: Path, header: str = "") -> None:
    buf = io.StringIO(header)
    buf.seek(0, io.SEEK_END)
    names = list(dict.fromkeys(k for r in rows for k in r)) if rows else list(FIELDS)  # rows of older runs: no bits
    w = csv.DictWriter(buf, fieldnames=names, restval="", lineterminator="\n")
    w.writeheader()
    w.writerows(rows)
    write_bytes_atomic(path, buf.getvalue().encode())


def _read(path: Path) -> list[dict]:
    with open(path, newline="") as fh:  # lines starting with '#' (the provenance) are not rows
        return list(csv.DictReader(line for line in fh if not line.startswith("#")))


def _named_as(row: dict) -> set[str]:
    """The names the first step gave: the winner and, where the report could not tell them apart, the runner-up."""
    names = {row["first"]} if row["first"] else set()
    for pair in filter(None, row["ambiguous"].split("+")):
        a, b = pair.split("|")
        if a == row["first"]:
            names.add(b)
    return names


def summarise(rows: list[dict]) -> tuple[str, list[dict]]:
    """Confusion matrix, null rate, gap after discovery, illumination ↔ anisotropy confusion (text and CSV rows)."""
    labels = sorted({r["first"] or "(nothing)" for r in rows})
    out = io.StringIO()
    table = []
    print(f"{len(rows)} cases", file=out)
    print("true case × first named (count)", file=out)
    print(f"{'case':12s} {'n':>3s} " + " ".join(f"{lab[:12]:>12s}" for lab in labels), file=out)
    for name in CASES:
        sub = [r for r in rows if r["case"] == name]
        if not sub:
            continue
        counts = {lab: sum((r["first"] or "(nothing)") == lab for r in sub) for lab in labels}
        print(f"{name:12s} {len(sub):3d} " + " ".join(f"{counts[lab]:12d}" for lab in labels), file=out)
        table.append({"case": name, "n": len(sub)} | counts)
    lib = [r for r in rows if r["expected"] not in ("", "(outside)")]
    ok = [r for r in lib if r["first"] == r["expected"]]
    ok_amb = [r for r in lib if r["expected"] in _named_as(r)]
    null = [r for r in rows if r["case"] in NULL]
    clean = [r for r in null if not r["found"]]
    gaps = np.array([float(r["gap_after"]) for r in lib]) if lib else np.zeros(0)
    ia = [r for r in rows if r["case"] in ("gradient", "anisotropy")]
    conf = [r for r in ia if r["first"] in ("illumination_gradient", "anisotropy") and r["first"] != r["expected"]]
    amb = [r for r in ia if len(_named_as(r) & {"illumination_gradient", "anisotropy"}) == 2]
    if lib:
        print(f"hidden library effect named first: {len(ok)}/{len(lib)} ({100 * len(ok) / len(lib):.0f} %)", file=out)
        print(f"  named first or as the ambiguous runner-up: {len(ok_amb)}/{len(lib)}", file=out)
        print(
            f"gap after discovery (library cases): median {np.median(gaps):.3f}, max {np.max(gaps):.3f}, "
            f"≤ 1.1 in {np.sum(gaps <= 1.1)}/{len(gaps)}",
            file=out,
        )
    if null:
        print(
            f"null cases with nothing added: {len(clean)}/{len(null)} ({100 * len(clean) / len(null):.0f} %)", file=out
        )
    if ia:
        print(
            f"illumination ↔ anisotropy confused (the other named first): {len(conf)}/{len(ia)}; "
            f"reported as not told apart: {len(amb)}/{len(ia)}",
            file=out,
        )
    for name in ("blur", "cast"):
        sub = [r for r in rows if r["case"] == name]
        if sub:
            names = ", ".join(sorted({r["found"] or "nothing" for r in sub}))
            print(f"{name}: named {names} (partial: {sum(bool(r['partial']) for r in sub)}/{len(sub)})", file=out)
    return out.getvalue(), table


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", nargs=2, type=int, default=(160, 120))
    ap.add_argument("--seeds", nargs="+", type=int, default=[0])
    ap.add_argument("--strengths", nargs="+", default=["strong", "weak"])
    ap.add_argument("--cases", nargs="+", default=None)
    ap.add_argument("--bit-depth", type=int, default=8, choices=(8, 16), help="of the captures' image files")
    ap.add_argument(
        "--rounding",
        default="stochastic",
        choices=ROUNDINGS,
        help="how an edited lit frame is re-quantised",
    )
    ap.add_argument("--limit", type=int, default=None, help="stop after this many cases")
    ap.add_argument("--out", type=Path, default=RESULTS / "textured_bench_stochastic.csv")
    ap.add_argument("--append", action="store_true", help="keep the rows already in --out")
    ap.add_argument("--summary", action="store_true", help="only summarise --out")
    a = ap.parse_args(argv)
    rows = _read(a.out) if (a.summary or a.append) and a.out.exists() else []
    if not a.summary:
        # stale edits, and rows of another bit depth or rounding (older rows: 8-bit, nearest), out
        rows = [
            r
            for r in rows
            if float(r["amount"]) == _amount(r["case"], r["strength"])
            and int(r.get("bits") or 8) == a.bit_depth
            and _rounding(r) in ("", a.rounding)
        ]
        done = {_key(r) for r in rows}
        todo = [c for c in cases(a.seeds, a.strengths, a.cases) if _key(c) not in done][: a.limit]
        with tempfile.TemporaryDirectory() as tmp:
            for i, (seed, strength, amp, tex, name) in enumerate(todo):
                row = run_case(Path(tmp), seed, strength, amp, tex, name, tuple(a.size), a.bit_depth, a.rounding)
                rows.append(row)
                _write(rows, a.out, provenance())
                print(
                    f"[{i + 1}/{len(todo)}] {tex:6s} {amp:.2f} {name:10s} {strength:6s} found {row['found'] or '-'}"
                    f" amb {row['ambiguous'] or '-'} gap {row['gap_before']} → {row['gap_after']} ({row['seconds']} s)",
                    flush=True,
                )
    text, table = summarise(rows)
    print(text)
    if table:
        _write(table, a.out.with_name(a.out.stem + "_confusion.csv"), provenance())


if __name__ == "__main__":
    main()
