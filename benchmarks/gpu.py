"""The engine and texture benchmarks on a GPU: ``make bench-gpu`` (``python -m benchmarks.gpu``).

Scanline fits per second at 10³–10⁶ scanlines (float64 and float32, beside
SciPy on ≤ 200 scanlines), Ward evaluations per second (beside NumPy), and the
texture analysis + synthesis at 1024² (beside pyrtools + NumPy on the host).
Without a GPU it says so and exits 0: the test suite and CI never need one.
"""

from __future__ import annotations

import sys


def main(argv=None) -> int:
    import jax

    backend = jax.default_backend()
    if backend not in ("gpu", "cuda", "rocm"):
        print(f"bench-gpu: no GPU found (JAX backend {backend!r}); skipped.")
        return 0
    from benchmarks import bench_fit, bench_synthesis

    print(f"JAX {jax.__version__}, devices: {', '.join(d.device_kind for d in jax.devices())}")
    bench_fit.main(["--sizes", "1000,10000,100000,1000000", "--scipy-max", "200", "--ward-samples", "20000000"])
    bench_synthesis.main(1024)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
