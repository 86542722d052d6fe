"""Small problems: a pixel seen in a few photographs, ``fit_scanlines`` on ``(P, K, 3)`` against SciPy.

Each problem is one of :func:`benchmarks.bench_fit.draw_scanlines`' scanlines with ``K`` samples
(default 9) spanning ±1.5…4 α in half-vector slope around the highlight (as the photographs of a
flash or multi-view capture see one pixel's lobe), RGB, 1 % multiplicative noise, α 0.03–0.3,
no weights. Printed side by side in one run: ``fit_scanlines`` with its defaults
(``errors="auto"``: HC3 sandwich, the curvature check, profiles where it fails) and with
``errors="gauss_newton"`` (best of three after compiling), SciPy ``least_squares(method="lm")``
with the analytic Jacobian on the first ``--scipy`` problems, the ratios, the time 10⁶ problems
would take at the measured rate, and the robust SD of (fit − truth)/σ of α and ρs.

Run: ``python -m benchmarks.bench_tiny [--n 100000] [--k 9] [--scipy 300]`` (under a minute on
two cores).
"""

from __future__ import annotations

import argparse
import time

import jax
import numpy as np

import wardjax as wj

from .bench_fit import REPEATS, _best_of, draw_scanlines, scipy_fit, z_sd

SPAN = (1.5, 4.0)  # half-width of the samples around the highlight, in α (half-vector slope)


def bench_tiny(n: int, k: int, scipy_n: int) -> None:
    d = draw_scanlines(n, (0.03, 0.3), n=k, span=SPAN, seed=7)
    print(f"{n:,} problems of {k} RGB samples (1 % multiplicative noise, no weights); SciPy on the first {scipy_n}")
    print("| errors | fits/s | 10⁶ fits | × SciPy analytic | σ reported | z-SD α / ρs | converged |")
    print("| --- | --- | --- | --- | --- | --- | --- |")
    m = min(scipy_n, n)
    t0 = time.perf_counter()
    for i in range(m):
        scipy_fit(d.f_r[i], d.wi[i], d.wo[i], None, analytic=True)
    scipy_rate = m / (time.perf_counter() - t0)
    for errors in ("auto", "gauss_newton"):
        fit = lambda errors=errors: wj.fit_scanlines(d.f_r, d.wi, d.wo, errors=errors)
        fit()  # compile
        el, res = _best_of(REPEATS, fit)
        kinds, counts = np.unique(res.errors[res.ok], return_counts=True)
        used = ", ".join(f"{a} {c / max(res.ok.sum(), 1):.0%}" for a, c in zip(kinds, counts))
        za, zs = z_sd(res, d)
        rate = n / el
        print(
            f"| {errors} | {rate:,.0f} | {1e6 / rate:.2f} s | {rate / scipy_rate:,.0f} | {used} | "
            f"{za:.2f} / {zs:.2f} | {res.ok.mean():.1%} |",
            flush=True,
        )
    print(f"| SciPy LM, analytic Jacobian | {scipy_rate:,.0f} | {1e6 / scipy_rate:,.0f} s | 1 | | | |")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=100_000, help="problems (pixels)")
    ap.add_argument("--k", type=int, default=9, help="samples per problem (photographs)")
    ap.add_argument("--scipy", type=int, default=300, help="problems SciPy fits")
    args = ap.parse_args(argv if argv is not None else [])
    print(f"JAX {jax.__version__} on {jax.devices()[0].platform}")
    bench_tiny(args.n, args.k, args.scipy)


if __name__ == "__main__":
    import sys

    main(sys.argv[1:])
