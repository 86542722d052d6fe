"""The reference standard's smoothing on a large standard: ours beside SciPy's Gaussian mean and the whole-image plane.

``fit.smooth_standard_px`` smooths the standard's image within its mask before the probe's mirror points
sample it (:func:`wardjax.reconstruct._smooth.smooth_on`). Three ways side by side, best of ``--repeat``:

- *SciPy Gaussian mean*: ``gaussian_filter(m·I) / gaussian_filter(m)`` per channel (the peer; order 0, so
  one-sided and biased by about σ·∇I at the mask's edge);
- *whole-image plane*: the first-order (local plane) fit computed on every pixel;
- *wardjax*: the Gaussian mean over the image, the plane only on tiles along the mask's edge (the same
  values as the whole-image plane inside the mask, to float32 rounding).

Run: ``python -m benchmarks.bench_smooth [--size 3000 2000] [--sigma 1.5] [--repeat 3] [--specks 0.001]``.
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np


def _standard(width: int, height: int, specks: float) -> tuple[np.ndarray, np.ndarray]:
    """A standard's image with an irradiance ramp and noise, and its mask: a box, with a fraction ``specks`` of its
    pixels clipped (punched out of the mask)."""
    rng = np.random.default_rng(0)
    y, x = np.mgrid[0:height, 0:width].astype(np.float32)
    level = 0.4 * (1 + 1e-4 * x - 5e-5 * y)
    img = level[..., None] * np.array([1.0, 0.9, 0.8], np.float32) + 0.01 * rng.standard_normal((height, width, 3))
    mask = (x >= 10) & (x <= width - 11) & (y >= 10) & (y <= height - 11) & (rng.random((height, width)) >= specks)
    return img.astype(np.float32), mask


def _best(fn, repeat: int) -> tuple[float, np.ndarray]:
    times, out = [], None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    assert out is not None
    return min(times), out


def main() -> None:
    from scipy.ndimage import gaussian_filter

    from wardjax.reconstruct._smooth import _kernels, _plane_levels, smooth_on

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", type=int, nargs=2, default=(3000, 2000), metavar=("W", "H"))
    ap.add_argument("--sigma", type=float, default=1.5)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--specks", type=float, default=0.0, help="fraction of the standard's pixels clipped")
    args = ap.parse_args()
    img, mask = _standard(*args.size, args.specks)
    s = args.sigma

    def scipy_mean():
        m = mask.astype(np.float32)
        norm = np.maximum(gaussian_filter(m, s, mode="constant"), 1e-12)
        return np.stack([gaussian_filter(img[..., c] * m, s, mode="constant") / norm for c in range(3)], -1)

    t_peer, _ = _best(scipy_mean, args.repeat)
    t_whole, whole = _best(lambda: _plane_levels(img, mask, s, _kernels(s)), args.repeat)
    t_ours, ours = _best(lambda: smooth_on(img, mask, s), args.repeat)
    w, h = args.size
    print(f"standard {w} × {h} ({w * h / 1e6:.1f} MP), {args.specks:.1%} clipped, σ {s} px, best of {args.repeat}")
    print(f"  (1-minute load average {os.getloadavg()[0]:.1f})")
    print(f"  SciPy Gaussian mean  {t_peer:7.2f} s")
    print(f"  whole-image plane    {t_whole:7.2f} s")
    print(f"  wardjax (edge tiles) {t_ours:7.2f} s")
    print(f"  ratios: × {t_peer / t_ours:.2f} the peer's rate, × {t_whole / t_ours:.2f} the whole-image plane's")
    print(f"  wardjax − whole-image plane, max |Δ| inside the mask: {np.abs(ours - whole)[mask].max():.1e}")


if __name__ == "__main__":
    main()
