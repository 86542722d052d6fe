"""The bench's figures from its CSV rows: rates by kind, the gap after the true effect, z, the confusion matrix."""

from __future__ import annotations

import csv
import os
import tempfile
from collections import Counter
from pathlib import Path

import numpy as np

from ._bench import robust_sd
from ._cases import CASES


def figures(rows: list[dict]) -> dict:
    """Counts and rates over ``rows``.

    ``in_first``: captures with a library effect (one or two) whose first name is a
    true effect; ``out_named``: captures with an effect outside the library that
    name a library effect; ``null_false``: nulls naming an effect not truly
    present; ``null_clean_iso``: isotropic nulls whose verdict says nothing was
    needed; ``band``: the gap after the true effect's step within 0.9–1.1;
    ``z``: robust SD of z of ρs and α over all rows and over the nulls.
    """
    by = {k: [r for r in rows if r["kind"] in k] for k in (("in", "two"), ("out",), ("null",))}
    iso = [r for r in by[("null",)] if r["expected"] == "-"]
    gaps = [float(r["gap_true"]) for r in rows if r["gap_true"] != "-"]
    z = {k: np.array([float(r[f"z_{k}"]) for r in rows]) for k in ("rho_s", "alpha")}
    zn = {k: np.array([float(r[f"z_{k}"]) for r in by[("null",)]]) for k in ("rho_s", "alpha")}
    return {
        "n": len(rows),
        "in": (sum(r["outcome"] == "right first" for r in by[("in", "two")]), len(by[("in", "two")])),
        "out": (sum(r["outcome"] == "named" for r in by[("out",)]), len(by[("out",)])),
        "null": (sum(r["outcome"] == "false name" for r in by[("null",)]), len(by[("null",)])),
        "null_clean_iso": (sum(r["verdict"].startswith("nothing needed") for r in iso), len(iso)),
        "band": (sum(0.9 <= g <= 1.1 for g in gaps), len(gaps), gaps),
        "z": {k: (robust_sd(v), float(np.median(v)) if v.size else float("nan")) for k, v in z.items()},
        "z_null": {k: (robust_sd(v), float(np.median(v)) if v.size else float("nan")) for k, v in zn.items()},
    }


def confusion(rows: list[dict]) -> tuple[list[str], list[str], dict]:
    """Rows: the cases (in the bench's order); columns: what was named first; counts."""
    cases = [c for c in CASES if any(r["case"] == c for r in rows)]
    firsts = sorted({r["first"] for r in rows}, key=lambda f: (f in ("nothing", "unexplained"), f))
    return cases, firsts, Counter((r["case"], r["first"]) for r in rows)


def write_confusion(path: Path, rows: list[dict]) -> None:
    """The confusion matrix as CSV (one row per case, one column per first name), written atomically."""
    cases, firsts, n = confusion(rows)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", dir=path.parent)
    with os.fdopen(fd, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["case", "kind", *firsts])
        for c in cases:
            w.writerow([c, CASES[c].kind, *(n[(c, f)] for f in firsts)])
    os.replace(tmp, path)


def _pct(a: int, b: int) -> str:
    return f"{a} of {b} ({100 * a / b:.0f} %)" if b else "none run"


def summary(rows: list[dict]) -> str:
    """The figures and the confusion matrix as Markdown."""
    if not rows:
        return "no rows"
    f = figures(rows)
    zs, za = f["z"]["rho_s"], f["z"]["alpha"]
    ns, na = f["z_null"]["rho_s"], f["z_null"]["alpha"]
    lo, hi = (min(f["band"][2]), max(f["band"][2])) if f["band"][2] else (float("nan"),) * 2
    loads = [float(r["load"]) for r in rows]
    lines = [
        f"- {f['n']} captures; load {min(loads):.0f}–{max(loads):.0f}",
        f"- in-library effects named first: {_pct(*f['in'])}",
        f"- out-of-library effects named as a library effect: {_pct(*f['out'])}",
        f"- nulls naming an effect not present: {_pct(*f['null'])}; isotropic nulls reading "
        f"'nothing needed': {_pct(*f['null_clean_iso'])}",
        f"- gap after the true effect within 0.9–1.1: {_pct(*f['band'][:2])} (range {lo:.3f}–{hi:.3f})",
        f"- z robust SD (median), all captures: ρs {zs[0]:.2f} ({zs[1]:+.2f}), α {za[0]:.2f} ({za[1]:+.2f}); "
        f"nulls: ρs {ns[0]:.2f} ({ns[1]:+.2f}), α {na[0]:.2f} ({na[1]:+.2f})",
        "",
    ]
    cases, firsts, n = confusion(rows)
    lines += ["| case | kind | " + " | ".join(firsts) + " |", "|---|---|" + "---:|" * len(firsts)]
    for c in cases:
        lines.append(f"| {c} | {CASES[c].kind} | " + " | ".join(str(n[(c, x)] or "") for x in firsts) + " |")
    return "\n".join(lines)


def table(rows: list[dict]) -> str:
    """One line per capture: truth, names, gaps, z, verdict."""
    out = ["| case | material | texture | seed | found | gap before → true → after | z ρs | z α | verdict |",
           "|---|---|---|---|---|---|---|---|---|"]  # fmt: skip
    for r in rows:
        out.append(
            f"| {r['case']} | {r['material']} | {r['texture']} | {r['seed']} | {r['found']} | "
            f"{r['gap_before']} → {r['gap_true']} → {r['gap_after']} | {float(r['z_rho_s']):+.1f} | "
            f"{float(r['z_alpha']):+.1f} | {r['verdict']} |"
        )
    return "\n".join(out)
