"""Small problems: a pixel seen in a few photographs, ``fit_scanlines`` on ``(P, K, 3)`` against SciPy.

Each problem is one of :func:`benchmarks.bench_fit.draw_scanlines`' scanlines with ``K`` samples
(default 9) spanning ±1.5…4 α in half-vector slope around the highlight (as the photographs of a
flash or multi-view capture see one pixel's lobe), RGB, 1 % multiplicative noise, α 0.03–0.3,
no weights. Printed side by side in one run: ``fit_scanlines`` with its defaults
(``errors="auto"``: HC3 sandwich, the curvature check, profiles where it fails) and with
``errors="gauss_newton"`` (best of five after compiling), SciPy ``least_squares(method="lm")``
with the analytic Jacobian on the first ``--scipy`` problems, the ratios, the time 10⁶ problems
would take at the measured rate, the process's CPU time per fit and its ratio to the wall time of
the same run (the cores in use: the chunks run on one execution stream per core), and the robust SD
of (fit − truth)/σ of α and ρs. Then where one chunk's time goes (a chunk of the default size): the
CPU time of each compiled stage (geometry, moments, the search alone, and with the curvature check,
the sandwich and the in-program profiles added).

Run: ``python -m benchmarks.bench_tiny [--n 100000] [--k 9] [--scipy 300]`` (under a minute on
two cores).
"""

from __future__ import annotations

import argparse
import os
import time

import jax
import jax.numpy as jnp
import numpy as np

import wardjax as wj
from wardjax.fit import _data, _feed, _scanline

from .bench_fit import REPEATS, draw_scanlines, scipy_fit, z_sd
from .bench_profile import ROUNDS, _interleaved
from .bench_synthesis import _best_of

SPAN = (1.5, 4.0)  # half-width of the samples around the highlight, in α (half-vector slope)


def bench_tiny(n: int, k: int, scipy_n: int) -> None:
    d = draw_scanlines(n, (0.03, 0.3), n=k, span=SPAN, seed=7)
    print(f"{n:,} problems of {k} RGB samples (1 % multiplicative noise, no weights); SciPy on the first {scipy_n}")
    rows = _scanline._default_chunk(np.float64, jax.devices(), _scanline._sample_bucket(k))
    print(f"chunks of {rows:,} rows on {_feed.streams(jax.devices())} execution stream(s)")
    print("| errors | fits/s | 10⁶ fits | CPU µs/fit | CPU/wall | × SciPy analytic | σ reported | z-SD α / ρs", end="")
    print(" | converged |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- | --- |")
    m = min(scipy_n, n)
    t0 = time.perf_counter()
    for i in range(m):
        scipy_fit(d.f_r[i], d.wi[i], d.wo[i], None, analytic=True)
    scipy_rate = m / (time.perf_counter() - t0)
    for errors in ("auto", "gauss_newton"):
        fit = lambda errors=errors: wj.fit_scanlines(d.f_r, d.wi, d.wo, errors=errors)
        fit()  # compile
        el, cpu, res = _best_of(fit, REPEATS)
        kinds, counts = np.unique(res.errors[res.ok], return_counts=True)
        used = ", ".join(f"{a} {c / max(res.ok.sum(), 1):.0%}" for a, c in zip(kinds, counts))
        za, zs = z_sd(res, d)
        rate = n / el
        print(
            f"| {errors} | {rate:,.0f} | {1e6 / rate:.2f} s | {1e6 * cpu / n:.2f} | {cpu / el:.2f} | "
            f"{rate / scipy_rate:,.0f} | {used} | "
            f"{za:.2f} / {zs:.2f} | {res.ok.mean():.1%} |",
            flush=True,
        )
    print(f"| SciPy LM, analytic Jacobian | {scipy_rate:,.0f} | {1e6 / scipy_rate:,.0f} s | | | 1 | | | |")


def stages(k: int, rows: int | None = None) -> None:
    """Where a chunk's time goes: CPU ms of each compiled stage of one chunk of ``rows`` problems (default:
    the rows of a chunk of ``fit_scanlines``)."""
    rows = rows or _scanline._default_chunk(np.float64, jax.devices(), _scanline._sample_bucket(k))
    d = draw_scanlines(rows, (0.03, 0.3), n=k, span=SPAN, seed=7)
    with jax.enable_x64(True):
        f64 = np.dtype(np.float64)
        geometry = lambda: _scanline._geometry_chunk(d.f_r, d.wi, d.wo, None, None, normalization="ward1992", dtype=f64)
        parts = geometry()
        n_pad = _scanline._sample_bucket(k)
        n = None if n_pad == k else jnp.asarray(k, jnp.int32)
        small = _scanline._small_programs(n_pad, jax.devices())  # the programs fit_scanlines runs
        moments = lambda: _data.moments_chunk.pick(small)(*parts, n, iso=True)
        prep = moments()
        lanes = _scanline._profile_lanes(rows, k)
        search = lambda raw=None, check=False, lanes=0: _scanline._search_chunk.pick(small)(
            prep, raw, iso=True, rtol=0.0, check=check, lanes=lanes
        )
        pending = float(np.mean(np.asarray(search(parts, True).nonlinear) != 0))
        runs = _interleaved(
            {
                "geometry": geometry,
                "moments": moments,
                "search (Gauss–Newton)": search,
                "search + curvature check": lambda: search(check=True),
                "search + sandwich": lambda: search(parts),
                "search + check + sandwich": lambda: search(parts, True),
                f"search + check + sandwich + profiles ({lanes} lanes)": lambda: search(parts, True, lanes),
            }
        )
        t = {name: float(np.median(ms)) for name, ms in runs.items()}
    print(
        f"\nOne chunk of {rows:,} problems of {k} samples, CPU ms per compiled stage (medians over {ROUNDS} "
        "rounds, the stages taking turns);"
    )
    print(f"the curvature check fails on {pending:.1%} of them (profiled in the search program)")
    print("| stage | CPU ms | µs per fit |")
    print("| --- | --- | --- |")
    for name, ms in t.items():
        print(f"| {name} | {ms:.2f} | {1e3 * ms / rows:.2f} |")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=100_000, help="problems (pixels)")
    ap.add_argument("--k", type=int, default=9, help="samples per problem (photographs)")
    ap.add_argument("--scipy", type=int, default=300, help="problems SciPy fits")
    ap.add_argument("--no-stages", action="store_true", help="skip the per-stage breakdown of one chunk")
    args = ap.parse_args(argv if argv is not None else [])
    print(f"JAX {jax.__version__} on {jax.devices()[0].platform} ({os.cpu_count()} cores)")
    bench_tiny(args.n, args.k, args.scipy)
    if not args.no_stages:
        stages(args.k)


if __name__ == "__main__":
    import sys

    main(sys.argv[1:])
