"""The engine and texture benchmarks on a GPU: ``make bench-gpu`` (``python -m benchmarks.gpu``).

Scanline fits per second at 10³–10⁶ scanlines (float64 and float32, data on
the host and data already on the device, beside SciPy on ≤ 200 scanlines), the
time of each stage of one chunk, fits per second at a larger chunk, host-fed
against device-resident rates at 10⁶ scanlines (``--feed``) and 10⁶ problems of
9 samples (``--tiny``) with the copy alone beside them, Ward
evaluations per second (beside NumPy), and the texture analysis + synthesis at
1024² (beside pyrtools + NumPy on the host). Without a GPU it says so and exits
0: the test suite and CI never need one (``--cpu`` runs it anyway, to check the
script with small ``--sizes``).
"""

from __future__ import annotations

import argparse
import sys
import time

import numpy as np


def _best(fn, k=3):
    import jax

    best = float("inf")
    for _ in range(k):
        t0 = time.perf_counter()
        jax.block_until_ready(fn())
        best = min(best, time.perf_counter() - t0)
    return best


def stages(n: int) -> None:
    """Seconds of each compiled stage of the fast fit on one chunk of ``n`` scanlines already on the device."""
    import jax

    from benchmarks.bench_fit import make_data
    from wardjax.fit import _data, _scanline

    _, d = make_data(n, seed=n)
    print(f"\nstages of one chunk of {n:,} scanlines × 256 samples, data on the device (best of 3):")
    for dt in (np.float64, np.float32):
        dt = np.dtype(dt)
        rtol = 0.0 if dt == np.float64 else 64 * float(np.finfo(dt).eps)
        with jax.enable_x64(True):
            f, wi, wo, w = (jax.device_put(np.asarray(a, dt)) for a in (d.f_r, d.wi, d.wo, 1 / d.sigma**2))
            geo = lambda: _scanline._geometry_chunk(f, wi, wo, None, w, normalization="ward1992", dtype=dt)
            parts = jax.block_until_ready(geo())
            mom = lambda: _data.moments_chunk(*parts, None, iso=True)
            prep = jax.block_until_ready(mom())
            search = lambda: _scanline._search_chunk(prep, iso=True, rtol=rtol, check=True)
            jax.block_until_ready(search())
            t = [_best(s) for s in (geo, mom, search)]
        print(
            f"  {dt.name}: geometry {t[0] * 1e3:.1f} ms, moments {t[1] * 1e3:.1f} ms, search {t[2] * 1e3:.1f} ms "
            f"-> {n / sum(t):,.0f} fits/s for the three stages alone"
        )


def _rates(arrays, weighted: bool, dt, n: int, label: str) -> None:
    """One row per (placement, errors): fits/s with the data from host memory (NumPy) and already on the device."""
    import jax

    import wardjax as wj
    from wardjax.fit import _data, _feed

    host = [np.ascontiguousarray(a, dt) for a in arrays]
    if not weighted:
        host[3] = None
    t_check = _best(lambda: _data.validate(*host[:3], None, host[3]) and 0)
    t_copy = _best(lambda: [jax.device_put(a) for a in host if a is not None])
    t_fed = _best(lambda: _fed_copy(host))
    with jax.enable_x64(True):
        dev = jax.block_until_ready([None if a is None else jax.device_put(a) for a in host])
    gb = sum(a.nbytes for a in host if a is not None) / 1e9
    print(
        f"  {label} {dt.name}, {'1/σ²' if weighted else 'no weights'}: {gb:.2f} GB; boundary checks {t_check:.3f} s,"
        f" the copy alone (device_put) {t_copy:.3f} s = {gb / t_copy:.1f} GB/s = {n / t_copy:,.0f} scanlines/s;"
        f" in chunks from {_feed.WORKERS} threads as the fit feeds them {t_fed:.3f} s = {gb / t_fed:.1f} GB/s"
    )
    for errors in ("gauss_newton", "auto"):
        row = []
        for where, a in (("host", host), ("device", dev)):
            fit = lambda a=a, errors=errors: wj.fit_scanlines(a[0], a[1], a[2], weights=a[3], dtype=dt, errors=errors)
            res = fit()  # compile
            row.append((where, n / _best(fit), float(np.mean(res.ok))))
        cells = "   ".join(f"{w} {r:>12,.0f} fits/s" for w, r, _ in row)
        print(f"    {errors:>12}: {cells}   (converged {row[0][2]:.2%})", flush=True)


def _fed_copy(host) -> list:
    """The host arrays placed on the default device in fit-sized chunks by the fit's threaded feed."""
    import jax

    from wardjax.fit import _feed, _scanline

    device = jax.devices()[0]
    rows = _scanline._default_chunk(host[0].dtype, [device])
    n = host[0].shape[0]
    spans = [(i, min(i + rows, n), rows) for i in range(0, n, rows)]
    return list(_feed.chunks(host, spans, lambda a: jax.device_put(a, device), threaded=True))


def feed(n: int, f64: bool = False) -> None:
    """fits/s at ``n`` scanlines × 256 samples from host memory and on the device, by dtype, weights and errors."""
    from benchmarks.bench_fit import make_data

    _, d = make_data(n, seed=n)
    print(f"\n{n:,} scanlines × 256 samples: host-fed (NumPy) vs device-resident (jax.Array), best of 3:", flush=True)
    arrays = (d.f_r, d.wi, d.wo, 1 / d.sigma**2)
    _rates(arrays, True, np.dtype(np.float32), n, "f32 data")
    _rates(arrays, False, np.dtype(np.float32), n, "f32 data")
    if f64:
        _rates(arrays, True, np.dtype(np.float64), n, "f64 data")


def tiny(n: int, k: int = 9) -> None:
    """fits/s of ``n`` independent problems of ``k`` RGB samples (pixels seen in ``k`` photos), no weights."""
    from benchmarks.bench_fit import draw_scanlines
    from benchmarks.bench_tiny import SPAN

    d = draw_scanlines(n, (0.03, 0.3), n=k, span=SPAN, seed=7)
    print(f"\n{n:,} problems × {k} samples (no weights), best of 3:", flush=True)
    arrays = (d.f_r, d.wi, d.wo, np.ones_like(d.f_r))
    for dt in (np.float32, np.float64):
        _rates(arrays, False, np.dtype(dt), n, f"{k} samples")


def chunks(n: int, sizes: list[int]) -> None:
    """fits/s at ``n`` scanlines on the device by chunk size (GPU default: 131,072 with ≥ 32 GB, else 32,768)."""
    from benchmarks.bench_fit import make_data

    _, d = make_data(n, seed=n)
    print(f"\n{n:,} scanlines on the device, fits/s by chunk size (best of 3):")
    for dt in (np.float64, np.float32):
        _chunk_rates(d, np.dtype(dt), n, sizes)


def _chunk_rates(d, dt, n, sizes) -> None:
    import jax

    import wardjax as wj

    with jax.enable_x64(True):
        arrays = [jax.device_put(np.asarray(a, dt)) for a in (d.f_r, d.wi, d.wo, 1 / d.sigma**2)]
    f, wi, wo, w = jax.block_until_ready(arrays)
    for c in sizes:
        res = wj.fit_scanlines(f, wi, wo, weights=w, dtype=dt, chunk_size=c)
        rate = n / _best(lambda c=c: wj.fit_scanlines(f, wi, wo, weights=w, dtype=dt, chunk_size=c))
        print(f"  {dt.name} chunk {c:>7,}: {rate:>12,.0f} fits/s   ({int(np.sum(res.ok))} converged)")


def main(argv=None) -> int:
    import jax

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", default="1000,10000,100000,1000000", help="scanline counts (default 10³–10⁶)")
    ap.add_argument("--chunks", default="32768,131072", help="chunk sizes tried at the largest size")
    ap.add_argument("--synthesis", type=int, default=1024, help="texture side for bench_synthesis (0: skip)")
    ap.add_argument("--cpu", action="store_true", help="run without a GPU (to check this script)")
    ap.add_argument("--only", default="", help="comma-separated sections: fit, stages, chunks, feed, tiny, synthesis")
    ap.add_argument("--feed", type=int, default=1_000_000, help="scanlines of the host-fed vs device table")
    ap.add_argument("--feed-f64", action="store_true", help="also float64 data in that table (24 GB at 10⁶)")
    ap.add_argument("--tiny", type=int, default=1_000_000, help="problems of the 9-sample table")
    args = ap.parse_args(argv)
    backend = jax.default_backend()
    if backend not in ("gpu", "cuda", "rocm") and not args.cpu:
        print(f"bench-gpu: no GPU found (JAX backend {backend!r}); skipped.")
        return 0
    from benchmarks import bench_fit, bench_synthesis

    sizes = [int(s) for s in args.sizes.split(",")]
    print(f"JAX {jax.__version__}, devices: {', '.join(d.device_kind for d in jax.devices())}", flush=True)
    only = set(filter(None, args.only.split(","))) or {"fit", "stages", "chunks", "feed", "tiny", "synthesis"}
    if "fit" in only:
        bench_fit.main(["--n", str(sizes[-1]), "--scipy", "200", "--ward-samples", "20000000"])
    if "stages" in only:
        stages(min(32768, sizes[-1]))
    if "chunks" in only:
        chunks(sizes[-1], [int(c) for c in args.chunks.split(",")])
    if "tiny" in only:
        tiny(args.tiny)
    if "feed" in only:
        feed(args.feed, args.feed_f64)
    sys.stdout.flush()
    if args.synthesis and "synthesis" in only:
        bench_synthesis.main(args.synthesis)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
