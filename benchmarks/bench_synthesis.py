"""Texture analysis + synthesis: wardjax vs the same algorithm on pyrtools + NumPy.

Both sides run the same Heeger–Bergen algorithm on the same 1024² RGB ρd
texture: PCA decorrelation of RGB, periodic + smooth decomposition, steerable
pyramid of height 4 with 4 orientations, quantile tables (129 entries) of the
pixels and the 18 subbands per channel; then synthesis of a 1024² texture from
seeded noise with 5 iterations of histogram matching of every subband and
the pixels (wardjax twice: Heeger & Bergen's binned CDF + lookup matching, the
default, and the exact sort-based matching), the per-iteration KS distance of the subbands,
channel decorrelation and the clamp to [0, 1 − ρs].

The reference uses ``pyrtools.pyramids.SteerablePyramidFreq`` (build and
``recon_pyr``) and NumPy (``np.argsort``, ``np.interp``, FFTs) in float64, as
one would write it, with the same KS shortcut as wardjax (every
``n // 8192``-th order statistic). wardjax runs in float32: the pyramid in JAX
(rfft, one channel per XLA program). The binned matching runs every iteration
of a channel in one XLA program, each subband matched as it is built; the
exact rank step (pack value and position into 64-bit keys, sort, scatter the
targets) runs in NumPy threads on CPU, overlapped with XLA's work on another
channel. The analysis's exact quantiles come from a histogram selection on
both wardjax paths (the reference sorts). Times are wall clock of one
warm call (after a first call that compiles), best of ``REPEATS``, with the
process CPU time (all threads) beside it: on a shared machine the CPU time is
the steadier figure, and the load average is printed.

    python -m benchmarks.bench_synthesis            # 1024², the size the target is set at
    python -m benchmarks.bench_synthesis 256        # a quick run
"""

from __future__ import annotations

import os
import sys
import time
import warnings

import numpy as np

SIZE = 1024
ITERATIONS = 5
HEIGHT = 4
N_QUANTILES = 129
RHO_S = 0.04
REPEATS = 2


# ---------------------------------------------------------------- reference: pyrtools + NumPy


def _ref_periodic(u):
    """Moisan's periodic component (NumPy), the same formula as wardjax.periodic_smooth_decomposition."""
    n, m = u.shape
    v = np.zeros_like(u)
    v[0] += u[-1] - u[0]
    v[-1] -= u[-1] - u[0]
    v[:, 0] += u[:, -1] - u[:, 0]
    v[:, -1] -= u[:, -1] - u[:, 0]
    den = 2 * np.cos(2 * np.pi * np.fft.fftfreq(n))[:, None] + 2 * np.cos(2 * np.pi * np.fft.fftfreq(m))[None] - 4
    den[0, 0] = 1.0
    s_hat = np.fft.fft2(v) / den
    s_hat[0, 0] = 0.0
    return u - np.real(np.fft.ifft2(s_hat))


def _ref_keys(height):
    return ["residual_highpass", *[(lv, b) for lv in range(height) for b in range(4)], "residual_lowpass"]


def _ref_quantiles(x, probs):
    s = np.sort(x.ravel())
    return np.interp(probs * (s.size - 1), np.arange(s.size), s)


def _ref_match(x, table, probs):
    n = x.size
    order = np.argsort(x.ravel())
    out = np.empty(n)
    out[order] = np.interp((np.arange(n) + 0.5) / n, probs, table)
    return out.reshape(x.shape), x.ravel()[order]


def _ref_ks(sorted_vals, table, probs):
    """KS distance from every s-th order statistic, s = max(1, n // 8192), as wardjax computes it."""
    n = sorted_vals.size
    k = np.arange(0, n, max(1, n // 8192))
    v = sorted_vals[k]
    f = np.interp(v, table, probs) if np.all(np.diff(table) > 0) else _ref_cdf_ties(v, table, probs)
    return max(np.max(f - k / n), np.max((k + 1) / n - f))


def _ref_cdf_ties(v, table, probs):
    i = np.clip(np.searchsorted(table, v, side="right"), 1, len(table) - 1)
    lo, hi = table[i - 1], table[i]
    with np.errstate(invalid="ignore", divide="ignore"):
        frac = np.where(hi > lo, (v - lo) / (hi - lo), 1.0)
    f = probs[i - 1] + np.clip(frac, 0, 1) * (probs[i] - probs[i - 1])
    return np.where(v < table[0], 0.0, np.where(v >= table[-1], 1.0, f))


def _pyr(image, height):
    import pyrtools as pt

    return pt.pyramids.SteerablePyramidFreq(image, height=height, order=3)


def reference_analyze(rgb, height=HEIGHT, n_quantiles=N_QUANTILES):
    from wardjax.texture import quantile_probabilities

    probs = quantile_probabilities(n_quantiles)
    pixels = rgb.reshape(-1, 3)
    mean = pixels.mean(axis=0)
    evals, evecs = np.linalg.eigh(np.cov(pixels - mean, rowvar=False))
    basis = evecs[:, ::-1]
    d = ((pixels - mean) @ basis).T.reshape(3, *rgb.shape[:2])
    pix_q, band_q = [], []
    for c in range(3):
        pix_q.append(_ref_quantiles(d[c], probs))
        pyr = _pyr(_ref_periodic(d[c]), height)
        full = d[c].size  # store size-independent values (pyrtools' level-l bands grow by H W / (H_l W_l))
        band_q.append(
            [_ref_quantiles(pyr.pyr_coeffs[k], probs) * pyr.pyr_coeffs[k].size / full for k in _ref_keys(height)]
        )
    return {
        "mean": mean,
        "basis": basis,
        "probs": probs,
        "pix": np.array(pix_q),
        "bands": np.array(band_q),
        "height": height,
    }


def reference_synthesize(model, shape, seed=0, iterations=ITERATIONS, rho_s=RHO_S):
    rng = np.random.default_rng(seed)
    probs, height = model["probs"], model["height"]
    keys = _ref_keys(height)
    scale = {}  # back to pyrtools' convention for this output size
    channels, dist = [], np.zeros((iterations, 3))
    for c in range(3):
        im, _ = _ref_match(rng.standard_normal(shape), model["pix"][c], probs)
        for it in range(iterations + 1):
            pyr = _pyr(im, height)
            if not scale:
                full = shape[0] * shape[1]
                scale = {k: full / np.prod(pyr.pyr_coeffs[k].shape) for k in keys}
            ks = 0.0
            for j, k in enumerate(keys):
                table = model["bands"][c, j] * scale[k]
                matched, sorted_vals = _ref_match(pyr.pyr_coeffs[k], table, probs)
                ks = max(ks, _ref_ks(sorted_vals, table, probs))
                pyr.pyr_coeffs[k] = matched
            if it > 0:
                dist[it - 1, c] = ks
            if it == iterations:
                break
            im, _ = _ref_match(pyr.recon_pyr(), model["pix"][c], probs)
        channels.append(im)
    d = np.stack(channels).reshape(3, -1)
    mu = d.mean(axis=1, keepdims=True)
    x = d - mu
    s = x @ x.T / x.shape[1]
    evals, evecs = np.linalg.eigh(s)
    d = (np.sqrt(np.diag(s))[:, None] * ((evecs / np.sqrt(evals)) @ evecs.T)) @ x + mu
    rgb = np.einsum("kc,chw->hwk", model["basis"], d.reshape(3, *shape)) + model["mean"]
    return np.clip(rgb, 0.0, 1.0 - rho_s), dist.max(axis=1)


# ---------------------------------------------------------------- the benchmark


def _best_of(fn, repeats):
    """Best wall time of ``repeats`` calls, the process CPU time (all threads) of that call, and its result."""
    best, cpu, out = np.inf, np.inf, None
    for _ in range(repeats):
        t0, c0 = time.perf_counter(), time.process_time()
        out = fn()
        wall = time.perf_counter() - t0
        if wall < best:
            best, cpu = wall, time.process_time() - c0
    return best, cpu, out


def main(size: int | None = None) -> None:
    import jax

    import wardjax as wj
    from wardjax.simulate import procedural_texture

    if size is None:
        size = int(sys.argv[1]) if len(sys.argv) > 1 and sys.argv[1].isdigit() else SIZE
    shape = (size, size)
    src = procedural_texture("marble", shape, seed=0, rho_s=RHO_S)

    def ours(match="binned"):
        model = wj.analyze_texture(src, height=HEIGHT, n_quantiles=N_QUANTILES, rho_s=RHO_S)
        return wj.synthesize_texture(model, shape, seed=0, iterations=ITERATIONS, match=match)

    def ref():
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            model = reference_analyze(src)
            return reference_synthesize(model, shape, seed=0)

    t0 = time.perf_counter()
    ours()  # compile
    t_compile = time.perf_counter() - t0
    ours("exact")
    load = os.getloadavg()
    t_ours, c_ours, res = _best_of(ours, REPEATS)
    t_exact, c_exact, res_exact = _best_of(lambda: ours("exact"), REPEATS)
    t_ref, c_ref, (img_ref, dist_ref) = _best_of(ref, 1 if size >= 1024 else REPEATS)
    load = tuple(max(a, b) for a, b in zip(load, os.getloadavg()))

    print(
        f"texture analysis + synthesis, {size}x{size} RGB, height {HEIGHT}, {ITERATIONS} iterations "
        f"({jax.default_backend()}, {os.cpu_count()} cores, load average up to "
        f"{load[0]:.2f} {load[1]:.2f} {load[2]:.2f})"
    )
    print(f"{'':24s}{'wall time':>12s}{'CPU time':>11s}{'final KS':>10s}{'var ratio':>11s}")
    for name, t, c, dist, img in (
        ("pyrtools + NumPy", t_ref, c_ref, dist_ref[-1], img_ref),
        ("wardjax binned", t_ours, c_ours, res.distance[-1], res.image),
        ("wardjax exact", t_exact, c_exact, res_exact.distance[-1], res_exact.image),
    ):
        var = float(np.mean(img.var(axis=(0, 1)) / src.var(axis=(0, 1))))
        print(f"{name:24s}{t:11.2f}s{c:10.2f}s{dist:10.3f}{var:11.3f}")
    for name, t, c in (("binned", t_ours, c_ours), ("exact", t_exact, c_exact)):
        print(f"{'ratio reference / ' + name:24s}{t_ref / t:11.1f}x{c_ref / c:10.1f}x")
    print(f"(target >= 10x; wardjax compile: {t_compile - t_ours:.1f} s once per shape)")


if __name__ == "__main__":
    main()
