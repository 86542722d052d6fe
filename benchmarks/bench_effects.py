"""Missing-effect discovery: hidden-effect bench, real data, and a capture-sized timing.

1. Hidden-effect bench (:mod:`benchmarks.hidden_effects`): each detectable library
   effect hidden at a random strength (RMS change 3–10 σ) in ``--draws``
   simulated cases (8 scanlines × 256 samples × RGB = 6,144 residuals), null
   data in ``--null`` cases, the out-of-library effect (orange peel) and the
   two effects that cancel by the rig's symmetry; ``discover`` runs blind.
   Prints the confusion matrix (hidden → first effect named), the
   false-addition rate on null data and the gap before → after.
2. Table 1 of the smartphone paper and a handful of CUReT samples.
3. One ``discover`` run with the full library on all scanlines of a 12 MP
   capture (4000 image columns, each binned to ``--capture-rows`` samples the
   way :func:`wardjax.fit_capture` bins, RGB).

Run alone: ``python -m benchmarks.bench_effects [--draws 10 --null 100]``.
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np

from benchmarks import hidden_effects as eb
from wardjax.effects import ScanlineModel, ThresholdModel, discover
from wardjax.effects._real import curet_data, table1_threshold_data


def capture_sized(n_scan: int = 4000, n_rows: int = 48, seed: int = 0):
    """Simulated scanlines the size of a 12 MP capture's columns (binned along the column)."""
    return eb.simulate_case(None, seed, n_scanlines=n_scan, n_samples=n_rows).data


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(prog="python -m benchmarks.bench_effects")
    ap.add_argument("--draws", type=int, default=10, help="hidden-effect draws per detectable effect")
    ap.add_argument(
        "--gamma-draws",
        type=int,
        default=20,
        help="draws of the γ mismatch (its signature is mostly absorbed by the baseline)",
    )
    ap.add_argument("--null", type=int, default=100, help="null draws")
    ap.add_argument("--ool", type=int, default=10, help="out-of-library (orange peel) draws")
    ap.add_argument("--cancelled", type=int, default=3, help="draws per effect that cancels by symmetry")
    ap.add_argument("--capture-scanlines", type=int, default=4000)
    ap.add_argument("--capture-rows", type=int, default=48)
    ap.add_argument("--skip-capture", action="store_true")
    ap.add_argument("--json", default=None, help="write the summary here")
    a = ap.parse_args(argv)
    out: dict = {}

    t0 = time.perf_counter()

    def progress(i, n, row):
        print(
            f"  [{i + 1}/{n}] hidden={row['hidden']:<22} found={row['found']} gap {row['gap_before']:.2f} → "
            f"{row['gap_after']:.3f} ({row['seconds']:.1f} s)",
            flush=True,
        )

    s = eb.run_bench(
        a.draws,
        a.null,
        out_of_library=a.ool,
        cancelled=a.cancelled,
        progress=progress,
        draws={"gamma": max(a.draws, a.gamma_draws)},
    )
    print("\nConfusion matrix (rows: hidden effect; columns: first effect named)\n")
    print(eb.bench_table(s))
    ool = [r for r in s["rows"] if r["hidden"] == eb.OUT_OF_LIBRARY]
    canc = [r for r in s["rows"] if r["hidden"] in eb.CANCELLED]
    print(
        f"\nnamed first (detectable, all draws): {100 * s['named_first_all']:.1f} %; per effect: "
        + ", ".join(f"{k} {100 * v:.0f} %" for k, v in s["named_first"].items())
    )
    print(f"null data: an effect added in {100 * s['null_false_rate']:.1f} % of {s['n_null']} draws")
    print(f"largest gap after discovery (correctly named): {s['gap_after_max_detectable']:.3f}")
    band = s["gap_band"]
    print(
        f"gap after the true effect within 1 ± 2√(2/dof): {band['within']} of {band['n']} "
        f"({band['below']} below, {band['above']} above)"
    )
    zsd = s["z_robust_sd"]
    print(f"z after discovery (model-averaged σ), robust SD: ρs {zsd['rho_s']:.2f}, α {zsd['alpha']:.2f}")
    if ool:
        print(
            f"out-of-library ({eb.OUT_OF_LIBRARY}): unexplained reported in "
            f"{sum(r['unexplained'] for r in ool)}/{len(ool)}, a name added in {sum(bool(r['found']) for r in ool)}"
        )
    if canc:
        print(f"cancelled by symmetry: a name added in {sum(bool(r['found']) for r in canc)}/{len(canc)}")
    print(f"(bench: {time.perf_counter() - t0:.0f} s)")
    out["bench"] = {k: v for k, v in s.items() if k != "rows"}
    out["bench_rows"] = s["rows"]

    rep = discover(ThresholdModel(), table1_threshold_data())
    print(f"\nTable 1 (smartphone paper): found {rep.found}; gap {' → '.join(f'{g:.3f}' for g in rep.gap)}")
    if rep.steps:
        st = rep.steps[0]
        print(
            f"  contrast-gloss c = {st.params['c']:.3f} ± {st.stderr['c']:.3f}; ΔBIC {st.evidence.delta_bic:.1f}, "
            f"LR p {st.evidence.p_value:.2g}"
        )
    out["table1"] = {"found": rep.found, "gap": rep.gap}

    print("\nCUReT samples:")
    cu = []
    for i in (0, 1, 4, 9, 14, 27, 40, 55):
        d, rel, sid = curet_data(i)
        r = discover(ScanlineModel(), d)
        cu.append({"sample": sid, "noise_rel": rel, "found": r.found, "gap": r.gap, "unexplained": len(r.unexplained)})
        print(
            f"  sample {sid:>2}: σ/f {rel:.3f}; found {r.found}; gap {' → '.join(f'{g:.2f}' for g in r.gap)}"
            f"{'; unexplained structure left' if r.unexplained else ''}"
        )
    out["curet"] = cu

    if not a.skip_capture:
        data = capture_sized(a.capture_scanlines, a.capture_rows)
        n = int(np.sum(data.mask))
        t1, c1 = time.perf_counter(), time.process_time()
        r = discover(ScanlineModel(), data, keep_plot_data=False)  # large data: each fit solved alone
        dt, dc = time.perf_counter() - t1, time.process_time() - c1
        print(
            f"\nCapture-sized discover ({a.capture_scanlines} scanlines × {a.capture_rows} binned samples × RGB = "
            f"{n:,} residuals, full library): {dt:.1f} s wall, {dc:.1f} s CPU (found {r.found}, gap {r.gap})"
        )
        out["capture_sized"] = {"residuals": n, "seconds": dt, "cpu_seconds": dc, "found": r.found}
    if a.json:
        with open(a.json, "w") as fh:
            json.dump(out, fh, indent=1, default=float)
    return out


if __name__ == "__main__":
    main()
