"""Cost of honest σ: ``fit_scanlines`` with the curvature check and profiles vs Gauss–Newton only.

``errors="gauss_newton"`` runs the kernel as it was before the profile-likelihood
errors (no check, no profile); ``errors="auto"`` (the default) adds the curvature check
to every fit and profiles the fits that fail it; ``errors="profile"`` profiles every
fit (the upper bound). Data: the bench_fit problem (RGB, 256 samples, σ = 1 % of f), in
two regimes: broad lobes (α 0.03–0.3, scanlines through the highlight, ±1.5 α) and
narrow lobes seen in the lobe's tail (α 0.01–0.05, offsets up to ±3 α), where more
fits fail the check. Rates are the best of three runs after compiling, in one process,
float64 and float32; the ratio is to ``gauss_newton`` on the same data.

Run alone: ``python -m benchmarks.bench_profile [--n 20000]``.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

import wardjax as wj
from wardjax.simulate import x_offset_for_slope


def make_data(n: int, alpha_range, offset: float, seed: int = 0):
    rng = np.random.default_rng(seed)
    a = rng.uniform(*alpha_range, n)
    truth = wj.WardParams(rho_d=rng.uniform(0.05, 0.8, (n, 3)), rho_s=rng.uniform(0.01, 0.1, n), alpha_x=a, alpha_y=a)
    rig = wj.ScanlineRig.random(n, rng)
    x0 = x_offset_for_slope(rig, rng.uniform(-offset, offset, n) * a)
    return wj.simulate_scanlines(truth, x_offsets=x0, rig=rig, seed=rng)


def _rate(data, errors: str, dtype) -> tuple[float, float]:
    args = (data.f_r.astype(dtype), data.wi.astype(dtype), data.wo.astype(dtype))
    w = (1 / data.sigma**2).astype(dtype)
    res = wj.fit_scanlines(*args, weights=w, errors=errors, dtype=dtype)  # compile
    best = np.inf
    for _ in range(3):
        t0 = time.perf_counter()
        res = wj.fit_scanlines(*args, weights=w, errors=errors, dtype=dtype)
        best = min(best, time.perf_counter() - t0)
    return len(res) / best, float(np.mean(res.errors == "profile"))


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=20000, help="scanlines per regime")
    args = ap.parse_args(argv)
    regimes = {
        "broad, through the highlight": ((0.03, 0.3), 1.5),
        "narrow, lobe tail": ((0.01, 0.05), 3.0),
    }
    print(f"{args.n} scanlines per regime; fits/s (best of 3); ratio = rate / gauss_newton rate")
    print("| regime | dtype | gauss_newton | auto | × | profiled | profile all | × |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- |")
    for name, (alpha_range, offset) in regimes.items():
        data = make_data(args.n, alpha_range, offset)
        for dtype in (np.float64, np.float32):
            base, _ = _rate(data, "gauss_newton", dtype)
            auto, frac = _rate(data, "auto", dtype)
            prof, _ = _rate(data, "profile", dtype)
            print(
                f"| {name} | {np.dtype(dtype).name} | {base:,.0f} | {auto:,.0f} | {auto / base:.2f} | "
                f"{100 * frac:.1f} % | {prof:,.0f} | {prof / base:.2f} |",
                flush=True,
            )


if __name__ == "__main__":
    main()
