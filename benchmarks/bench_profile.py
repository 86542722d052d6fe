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


ROUNDS = 40  # interleaved rounds of the stage timings


def _interleaved(fns: dict, rounds: int = ROUNDS) -> dict:
    """CPU (process) ms of each ``fns[k]()`` over ``rounds`` rounds, the functions taking turns within each
    round (after one call each to compile), so that a change in the machine's state falls on all of them."""
    for fn in fns.values():
        jax.block_until_ready(fn())
    ts = {k: [] for k in fns}
    for _ in range(rounds):
        for k, fn in fns.items():
            t0 = time.process_time()
            jax.block_until_ready(fn())
            ts[k].append(1e3 * (time.process_time() - t0))
    return {k: np.asarray(v) for k, v in ts.items()}


def _paired(a, b) -> str:
    """Median and quartiles of the paired differences ``a − b`` (ms): ``+m (q1–q3)``."""
    q1, m, q3 = np.percentile(np.asarray(a) - np.asarray(b), [25, 50, 75])
    return f"+{m:.1f} ({q1:.1f}–{q3:.1f})"


def stages(rows: int = 1024) -> None:
    """CPU time per stage of the default float64 path (unweighted: the sandwich is on) on one chunk.

    Each stage's cost beside the search is the median of paired differences over interleaved rounds: the
    difference of two independent best times swung by more than the stage costs on a shared machine.
    """
    from benchmarks.bench_fit import draw_scanlines
    from wardjax.fit import _data, _profile, _scanline

    print(
        f"CPU ms per chunk of {rows:,} scanlines, float64, no weights: medians over {ROUNDS} interleaved rounds; "
        "each '+' column the median (quartiles) of the paired differences to the column before it"
    )
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
            geometry = lambda: _scanline._geometry_chunk(*args, normalization="ward1992", dtype=f64)
            parts = jax.block_until_ready(geometry())
            small = _scanline._small_programs(_scanline._sample_bucket(n), jax.devices())  # as fit_scanlines picks
            moments = lambda: _data.moments_chunk.pick(small)(*parts, None, iso=True)
            prep = jax.block_until_ready(moments())
            lanes = _scanline._profile_lanes(rows, n)
            search = lambda check, raw=None, lanes=0: _scanline._search_chunk.pick(small)(
                prep, raw, iso=True, rtol=0.0, check=check, lanes=lanes
            )
            sol = search(True)
            done = int(np.sum(np.asarray(search(True, parts, lanes).nonlinear) == _profile.PROFILED))
            fit = (sol.alpha[:, 0], sol.rho_s, sol.chi2, sol.cov_gn, sol.chi2 / sol.dof)
            x = jnp.asarray(np.random.default_rng(0).uniform(0, 1, (rows, n)))
            exp = jax.jit(jnp.exp)
            t = _interleaved(
                {
                    "geometry": geometry,
                    "moments": moments,
                    "gn": lambda: search(False),
                    "check": lambda: search(True),
                    "sandwich": lambda: search(True, parts),
                    "lanes": lambda: search(True, parts, lanes),
                    "profile": lambda: _profile.profile_chunk.pick(small)(prep, *fit),
                    "floor": lambda: exp(x),
                }
            )
        med = {k: float(np.median(v)) for k, v in t.items()}
        print(
            f"| {n} | {med['geometry']:.1f} | {med['moments']:.1f} | {med['gn']:.1f} | "
            f"{_paired(t['check'], t['gn'])} | {_paired(t['sandwich'], t['check'])} | "
            f"{_paired(t['lanes'], t['sandwich'])} ({done}) | {med['profile']:.1f} | {med['floor']:.2f} |",
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
