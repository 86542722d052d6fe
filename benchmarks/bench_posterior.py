"""α posterior for one surface: emcee with the jit-compiled JAX log-probability vs plain NumPy.

One surface (three observers at 18/17/19 PPB, ρd = 0.8), 32 walkers, the chain run until it
is ≥ 50 integrated autocorrelation times long (the posterior's own convergence rule). Both
runs use the same sampler, moves and seed; only the log-probability differs (the JAX one is
vmapped over the half-ensemble and compiled once; the NumPy one is the reference
``log_prob_numpy``). Target: ≤ 2 s for the JAX run on this machine.

Run alone: ``.venv/bin/python -m benchmarks.bench_posterior``.
"""

from __future__ import annotations

import time

import numpy as np

TARGET_S = 2.0


def _time(fn, repeats: int = 3) -> tuple[float, object]:
    best, out = np.inf, None
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
    return best, out


def main() -> None:
    import wardjax as wj

    am = wj.AlphaModel.from_calibration()
    kwargs = dict(ppb=[18, 17, 19], rho_d=0.8, seed=0, n_walkers=32)
    t0 = time.perf_counter()
    am.posterior(**kwargs)  # compiles the two shapes once
    compile_s = time.perf_counter() - t0
    t_jax, post_jax = _time(lambda: am.posterior(**kwargs))
    t_np, post_np = _time(lambda: am.posterior(**kwargs, log_prob="numpy"))
    evals = post_jax.n_walkers * (post_jax.n_steps + post_jax.burn)
    print(
        f"alpha posterior, one surface, {post_jax.n_walkers} walkers, "
        f"{post_jax.n_steps} steps = {post_jax.n_steps / post_jax.tau_max:.0f} tau (tau = {post_jax.tau_max:.1f}),"
        f" {evals} log-prob evaluations"
    )
    print(f"{'log-probability':28s}{'time (s)':>10s}{'alpha median':>14s}{'95% interval':>22s}")
    for name, t, p in (("JAX (jit, vmapped)", t_jax, post_jax), ("NumPy (plain)", t_np, post_np)):
        lo, hi = p.interval(0.95)
        print(f"{name:28s}{t:10.3f}{p.median:14.4f}{f'[{lo:.4f}, {hi:.4f}]':>22s}")
    print(f"ratio NumPy / JAX: {t_np / t_jax:.2f}x   (first JAX call incl. compilation: {compile_s:.2f} s)")
    print(f"target <= {TARGET_S:.1f} s: {'met' if t_jax <= TARGET_S else 'NOT met'}")


if __name__ == "__main__":
    main()
