"""Cost of honest σ: ``fit_scanlines`` with the curvature check and profiles vs Gauss–Newton only.

``errors="gauss_newton"`` runs the kernel as it was before the profile-likelihood
errors (no check, no profile); ``errors="auto"`` (the default) adds the curvature check
to every fit and profiles the fits that fail it; ``errors="profile"`` profiles every
fit (the upper bound). Data: the bench_fit problem (RGB, 256 samples, σ = 1 % of f), in
two regimes: broad lobes (α 0.03–0.3, scanlines through the highlight, ±1.5 α) and
narrow lobes seen in the lobe's tail (α 0.01–0.05, offsets up to ±3 α), where more
fits fail the check. Rates are the best of three runs after compiling, in one process,
float64 and float32; the ratio is to ``gauss_newton`` on the same data.

Run alone: ``python -m benchmarks.bench_profile [--n 20000]``. With ``--stages``: instead, the CPU
time of each compiled stage of the default path on one chunk (1,024 scanlines of 256 samples, and
of 9), against the exp floor (one ``jnp.exp`` over the same number of samples).
"""

from __future__ import annotations

import argparse
import time

import jax
import jax.numpy as jnp
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


def _cpu_ms(fn, repeats: int = 7):
    """Best CPU (process) time of ``fn()`` in ms, after one call to compile; and its result."""
    out = jax.block_until_ready(fn())
    best = np.inf
    for _ in range(repeats):
        t0 = time.process_time()
        out = jax.block_until_ready(fn())
        best = min(best, time.process_time() - t0)
    return 1e3 * best, out


def stages(rows: int = 1024) -> None:
    """CPU time per stage of the default float64 path (unweighted: the sandwich is on) on one chunk."""
    from benchmarks.bench_fit import draw_scanlines
    from wardjax.fit import _data, _profile, _scanline

    print(f"CPU ms per chunk of {rows:,} scanlines (best of 7), float64, no weights")
    print(
        "| samples | geometry | moments | search | + check | + sandwich | + profiles in the program (rows) "
        "| profile of every row | exp floor |"
    )
    print("| --- | --- | --- | --- | --- | --- | --- | --- | --- |")
    for n, span in ((256, (3.0, 40.0)), (9, (1.5, 4.0))):
        d = draw_scanlines(rows, (0.03, 0.3), n=n, span=span)
        with jax.enable_x64(True):
            args = [jnp.asarray(a) for a in (d.f_r, d.wi, d.wo)] + [None, None]
            f64 = np.dtype(np.float64)
            geo, parts = _cpu_ms(lambda: _scanline._geometry_chunk(*args, normalization="ward1992", dtype=f64))
            mom, prep = _cpu_ms(lambda: _data.moments_chunk(*parts, None, iso=True))
            search = lambda check, raw=None: _scanline._search_chunk(prep, raw, iso=True, rtol=0.0, check=check)
            gn, _ = _cpu_ms(lambda: search(False))
            chk, sol = _cpu_ms(lambda: search(True))
            sw, _ = _cpu_ms(lambda: search(True, parts))
            lanes = _scanline._profile_lanes(rows, n)
            full, out = _cpu_ms(
                lambda: _scanline._search_chunk(prep, parts, iso=True, rtol=0.0, check=True, lanes=lanes)
            )
            done = int(np.sum(np.asarray(out.nonlinear) == _profile.PROFILED))
            fit = (sol.alpha[:, 0], sol.rho_s, sol.chi2, sol.cov_gn, sol.chi2 / sol.dof)
            prof, _ = _cpu_ms(lambda: _profile.profile_chunk(prep, *fit))
            x = jnp.asarray(np.random.default_rng(0).uniform(0, 1, (rows, n)))
            floor, _ = _cpu_ms(lambda: jax.jit(jnp.exp)(x))
        print(
            f"| {n} | {geo:.1f} | {mom:.1f} | {gn:.1f} | +{chk - gn:.1f} | +{sw - chk:.1f} | "
            f"+{full - sw:.1f} ({done}) | {prof:.1f} | {floor:.2f} |",
            flush=True,
        )


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=20000, help="scanlines per regime")
    ap.add_argument("--stages", action="store_true", help="CPU time per compiled stage instead")
    args = ap.parse_args(argv)
    if args.stages:
        stages()
        return
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
