"""The engine against SciPy: ``fit_scanlines`` with its defaults vs ``least_squares(method="lm")``.

The scanlines are drawn by this file's own NumPy code (:func:`draw_scanlines`), not by
:mod:`wardjax.simulate`: lamp and camera in the plane x = 0 (the image-based paper's rig),
the scanline along y through the highlight at an offset across it, RGB, 256 samples, Ward
(1992) isotropic with 1 % multiplicative Gaussian noise. Four regimes: broad lobes
(α 0.03–0.3) and narrow lobes (α 0.01–0.05), each weighted (``1/σ²`` from the true noise)
and unweighted (no weights: the default a user without a noise model gets).

Per regime, side by side in one run: ``fit_scanlines`` with its defaults (``errors="auto"``)
and with ``errors="gauss_newton"`` (best of five interleaved runs after compiling, and the spread of
the paired CPU ratios over the runs), SciPy LM with
2-point finite differences and with the analytic Jacobian from a generic start (ρd 0.5,
ρs 0.05, α 0.1) on the first ``--scipy`` scanlines, the ratios, which σ the defaults
reported, and the robust SD of (fit − truth)/σ for α and ρs (1 is honest). Then Ward
evaluations per second against NumPy (the exp floor of every fit).

Run alone: ``python -m benchmarks.bench_fit [--n 20000] [--scipy 200]`` (about 2–3 min on
two cores).
"""

from __future__ import annotations

import argparse
import functools
import time
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from scipy.optimize import least_squares

import wardjax as wj
from wardjax.simulate import x_offset_for_slope

_SIMULATED = 100_000
MAD = 1.4826
NOISE = 0.01  # multiplicative: σ = 1 % of the true value
REGIMES = {"broad": (0.03, 0.3), "narrow": (0.01, 0.05)}


class Drawn(NamedTuple):
    """Scanlines drawn by :func:`draw_scanlines`: truth ``(S,)``/``(S, 3)``, data ``(S, N, 3)``."""

    rho_d: np.ndarray
    rho_s: np.ndarray
    alpha: np.ndarray
    f_r: np.ndarray
    wi: np.ndarray
    wo: np.ndarray
    sigma: np.ndarray


def _unit(a):
    return a / np.linalg.norm(a, axis=-1, keepdims=True)


def draw_scanlines(
    s: int, alpha_range, *, n: int = 256, noise: float = NOISE, seed: int = 0, span=(3.0, 40.0)
) -> Drawn:
    """``s`` scanlines of random Ward materials, each in its own rig, by plain NumPy.

    Lamp at elevation 20–60° on the +y side and camera at 20–60° on the −y side, both at
    x = 0 and 400–900 mm from the sample's origin; the scanline runs along y over
    ``±span·α`` (default 3…40, log-uniform) in half-vector slope around the highlight, at an offset
    across it that tilts the half vector by up to ``±1.5 α``. Values are Ward 1992,
    ``ρd/π + ρs exp(−tan²δ/α²) / (4πα² √(cos θi cos θo))``, times ``1 + noise·ε``.
    """
    rng = np.random.default_rng(seed)
    alpha = rng.uniform(*alpha_range, s)
    rho_s = rng.uniform(0.01, 0.1, s)
    rho_d = rng.uniform(0.05, 0.8, (s, 3))
    el_l, el_c = np.deg2rad(rng.uniform(20, 60, (2, s)))
    d_l, d_c = rng.uniform(400, 900, (2, s))
    lamp = np.stack([np.zeros(s), d_l * np.cos(el_l), d_l * np.sin(el_l)], -1)
    cam = np.stack([np.zeros(s), -d_c * np.cos(el_c), d_c * np.sin(el_c)], -1)
    # The mirror point on y = 0's line x = 0: where the path lamp → sample → camera reflects.
    y_m = (lamp[:, 1] * cam[:, 2] + cam[:, 1] * lamp[:, 2]) / (lamp[:, 2] + cam[:, 2])

    # Half-vector slopes per mm along y and across (x) at the mirror point: tan δ ≈ |h_xy| / h_z.
    def slopes(x, y):
        p = np.stack([x, y, np.zeros_like(x)], -1)
        h = _unit(lamp - p) + _unit(cam - p)
        return h[:, 0] / h[:, 2], h[:, 1] / h[:, 2]

    step = 1e-3
    zero = np.zeros(s)
    dy = (slopes(zero, y_m + step)[1] - slopes(zero, y_m - step)[1]) / (2 * step)
    dx = (slopes(zero + step, y_m)[0] - slopes(zero - step, y_m)[0]) / (2 * step)
    half = np.exp(rng.uniform(np.log(span[0]), np.log(span[1]), s)) * alpha / np.abs(dy)
    x0 = rng.uniform(-1.5, 1.5, s) * alpha / np.abs(dx)
    y = y_m[:, None] + np.linspace(-1.0, 1.0, n)[None, :] * half[:, None]
    p = np.stack([np.broadcast_to(x0[:, None], y.shape), y, np.zeros_like(y)], -1)
    wi, wo = _unit(lamp[:, None] - p), _unit(cam[:, None] - p)
    h = wi + wo
    tan2 = (h[..., 0] ** 2 + h[..., 1] ** 2) / h[..., 2] ** 2
    a2 = alpha[:, None] ** 2
    spec = rho_s[:, None] * np.exp(-tan2 / a2) / (4 * np.pi * a2 * np.sqrt(wi[..., 2] * wo[..., 2]))
    f = rho_d[:, None, :] / np.pi + spec[..., None]
    sigma = noise * f
    return Drawn(rho_d, rho_s, alpha, f + sigma * rng.standard_normal(f.shape), wi, wo, sigma)


@functools.lru_cache(maxsize=2)
def make_data(n: int, seed: int = 0):
    """``(truth, ScanlineData)`` from :func:`wardjax.simulate_scanlines` (the GPU benchmark's stage timings)."""
    if n > _SIMULATED:
        truth, d = make_data(_SIMULATED, seed)
        k = -(-n // _SIMULATED)
        rep = lambda a: np.concatenate([a] * k)[:n]
        fitted = {k: rep(getattr(d, k)) for k in ("f_r", "wi", "wo", "sigma")}
        return jax.tree_util.tree_map(rep, truth), d._replace(f_true=None, points=None, **fitted)
    rng = np.random.default_rng(seed)
    a = rng.uniform(0.03, 0.3, n)
    truth = wj.WardParams(rho_d=rng.uniform(0.05, 0.8, (n, 3)), rho_s=rng.uniform(0.01, 0.1, n), alpha_x=a, alpha_y=a)
    rig = wj.ScanlineRig.random(n, rng)
    x0 = x_offset_for_slope(rig, rng.uniform(-1.5, 1.5, n) * a)
    return truth, wj.simulate_scanlines(truth, x_offsets=x0, rig=rig, seed=rng)


def scipy_fit(f, wi, wo, sigma, analytic: bool):
    """One scanline by SciPy's LM (MINPACK) from a generic start; ``sigma=None``: unweighted."""
    h = wi + wo
    t = (h[:, 0] ** 2 + h[:, 1] ** 2) / h[:, 2] ** 2
    g = 1.0 / (4 * np.pi * np.sqrt(wi[:, 2] * wo[:, 2]))
    inv_s = np.ones_like(f) if sigma is None else 1.0 / sigma

    def model(p):
        e = np.exp(-t / p[4] ** 2)
        return p[:3][None, :] / np.pi + (p[3] * g * e / p[4] ** 2)[:, None]

    def resid(p):
        return ((model(p) - f) * inv_s).ravel()

    def jac(p):
        a = p[4]
        spec = g * np.exp(-t / a**2) / a**2
        j = np.zeros((t.size, 3, 5))
        for c in range(3):
            j[:, c, c] = 1 / np.pi
        j[:, :, 3] = spec[:, None]
        j[:, :, 4] = (p[3] * spec * (2 * t / a**3 - 2 / a))[:, None]
        return (j * inv_s[..., None]).reshape(-1, 5)

    x0 = np.array([0.5, 0.5, 0.5, 0.05, 0.1])
    r = least_squares(resid, x0, jac=jac if analytic else "2-point", method="lm")
    return r.x


REPEATS = 5  # wardjax timings: best of 5 runs (as timeit does), so a busy machine skews less


def _best_of(k, fn):
    best, out = float("inf"), None
    for _ in range(k):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
    return best, out


def robust_sd(z) -> float:
    z = np.asarray(z)
    z = z[np.isfinite(z)]
    return float(MAD * np.median(np.abs(z - np.median(z)))) if z.size else float("nan")


def z_sd(res, d: Drawn) -> tuple[float, float]:
    """Robust SD of (fit − truth)/σ over the converged fits: α, ρs."""
    ok = res.ok
    za = (res.params.alpha_x - d.alpha) / res.stderr.alpha_x
    zs = (res.params.rho_s - d.rho_s) / res.stderr.rho_s
    return robust_sd(za[ok]), robust_sd(zs[ok])


def bench_regime(d: Drawn, weighted: bool, scipy_n: int) -> dict:
    w = 1.0 / d.sigma**2 if weighted else None
    out: dict = {}
    fits = {e: (lambda e=e: wj.fit_scanlines(d.f_r, d.wi, d.wo, weights=w, errors=e)) for e in ("gauss_newton", "auto")}
    for fit in fits.values():
        fit()  # compile
    # Interleaved, so that a change in the machine's load falls on both; wall and process CPU time.
    best = {e: [np.inf, np.inf] for e in fits}
    paired = []  # per repeat: Gauss–Newton's CPU time over the default's, the two runs back to back
    for _ in range(REPEATS):
        cpu = {}
        for e, fit in fits.items():
            t0, c0 = time.perf_counter(), time.process_time()
            res = fit()
            cpu[e] = time.process_time() - c0
            best[e] = [min(best[e][0], time.perf_counter() - t0), min(best[e][1], cpu[e])]
            out[e] = (len(d.alpha) / best[e][0], res)
        paired.append(cpu["gauss_newton"] / cpu["auto"])
    out["cpu_ratio"] = best["gauss_newton"][1] / best["auto"][1]
    out["cpu_spread"] = (float(np.median(paired)), min(paired), max(paired))
    m = min(scipy_n, len(d.alpha))
    for analytic in (False, True):
        sig = (lambda i: d.sigma[i]) if weighted else (lambda i: None)
        t0 = time.perf_counter()
        xs = np.array([scipy_fit(d.f_r[i], d.wi[i], d.wo[i], sig(i), analytic) for i in range(m)])
        out["jac" if analytic else "fd"] = (m / (time.perf_counter() - t0), xs)
    return out


def report_regime(name: str, weighted: bool, d: Drawn, out: dict) -> None:
    gn_rate, gn = out["gauss_newton"]
    rate, res = out["auto"]
    fd, jac = out["fd"][0], out["jac"][0]
    kinds, counts = np.unique(res.errors[res.ok], return_counts=True)
    used = ", ".join(f"{k} {c / max(res.ok.sum(), 1):.0%}" for k, c in zip(kinds, counts))
    za, zs = z_sd(res, d)
    ga, gs = z_sd(gn, d)
    print(
        f"| {name} | {'1/σ²' if weighted else 'none'} | {rate:,.0f} | {gn_rate:,.0f} | {rate / gn_rate:.2f} | "
        f"{out['cpu_ratio']:.2f} | {spread(out['cpu_spread'])} | "
        f"{fd:,.0f} | {jac:,.0f} | {rate / fd:,.0f} | {rate / jac:,.0f} | {used} | "
        f"{za:.2f} / {zs:.2f} | {ga:.2f} / {gs:.2f} | {res.ok.mean():.1%} |",
        flush=True,
    )


def spread(m: tuple[float, float, float]) -> str:
    """``median (min–max)`` of the paired ratios."""
    return f"{m[0]:.2f} ({m[1]:.2f}–{m[2]:.2f})"


def bench_fits(n: int, scipy_n: int) -> None:
    print(
        f"{n:,} scanlines per regime (RGB, 256 samples, 1 % multiplicative noise); wardjax fits/s best of "
        f"{REPEATS} after compiling, default and gauss_newton interleaved (CPU: the ratio of best process CPU "
        "times, which a busy machine distorts less; paired: the median and range over the repeats of the ratio of "
        f"two runs back to back, the spread one ratio carries); SciPy LM on the first {scipy_n}. "
        "z-SD: robust SD of (fit − truth)/σ, α / ρs."
    )
    print(
        "| lobes | weights | default fits/s | gauss_newton fits/s | default / GN | default / GN (CPU) | paired (CPU) | "
        "SciPy FD | SciPy jac | × FD | × jac | σ reported | z-SD default | z-SD GN | converged |"
    )
    print("| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |")
    for k, (name, alpha_range) in enumerate(REGIMES.items()):
        d = draw_scanlines(n, alpha_range, seed=k)
        for weighted in (True, False):
            report_regime(name, weighted, d, bench_regime(d, weighted, scipy_n))


def bench_ward(n=10_000_000):
    rng = np.random.default_rng(0)
    th_i, th_o = rng.uniform(0, 1.4, n), rng.uniform(0, 1.4, n)
    ph_i, ph_o = rng.uniform(0, 2 * np.pi, n), rng.uniform(0, 2 * np.pi, n)
    d = lambda t, p: np.stack([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)], -1)
    wi, wo = d(th_i, ph_i), d(th_o, ph_o)
    p = wj.WardParams(rho_d=(0.5, 0.4, 0.3), rho_s=0.05, alpha_x=0.1, alpha_y=0.2)

    def numpy_ward(wi, wo):
        h = wi + wo
        e = np.exp(-((h[:, 0] / 0.1) ** 2 + (h[:, 1] / 0.2) ** 2) / h[:, 2] ** 2)
        spec = 0.05 * e / (4 * np.pi * 0.1 * 0.2 * np.sqrt(wi[:, 2] * wo[:, 2]))
        return np.array([0.5, 0.4, 0.3]) / np.pi + spec[:, None]

    t0 = time.perf_counter()
    ref = numpy_ward(wi, wo)
    t_np = time.perf_counter() - t0
    out = {}
    for dt in (jnp.float64, jnp.float32):
        with jax.enable_x64(True):
            f = jax.jit(lambda a, b: wj.ward_brdf(p, a, b))
            a, b = jnp.asarray(wi, dt), jnp.asarray(wo, dt)
            f(a, b).block_until_ready()
            t0 = time.perf_counter()
            got = f(a, b).block_until_ready()
            out[np.dtype(dt).name] = (time.perf_counter() - t0, float(np.max(np.abs(np.asarray(got) / ref - 1))))
    print(f"\nWard evaluations, {n:,} samples (RGB):")
    print(f"  NumPy float64        {n / t_np:>14,.0f} /s")
    for k, (t, err) in out.items():
        print(f"  wardjax jit {k:<8} {n / t:>14,.0f} /s   ×{t_np / t:.1f} NumPy   max rel. diff {err:.1e}")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=20_000, help="scanlines per regime")
    ap.add_argument("--scipy", type=int, default=200, help="scanlines SciPy fits per regime")
    ap.add_argument("--ward-samples", type=int, default=10_000_000)
    args = ap.parse_args(argv if argv is not None else [])
    print(f"JAX {jax.__version__} on {jax.devices()[0].platform}")
    bench_fits(args.n, args.scipy)
    bench_ward(args.ward_samples)


if __name__ == "__main__":
    import sys

    main(sys.argv[1:])
