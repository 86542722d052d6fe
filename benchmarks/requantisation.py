"""What re-encoding an edited image file adds: the error of the written codes, and how well the library's γ fits.

The textured bench hides a camera response by editing the lit frame's codes,
``c ↦ c^k`` (:func:`benchmarks.edited_captures.edit_capture`), and writes
them back at the capture's bit depth. Rounding after a non-linear map is an
error of its own: it is a fixed function of the original code, so
neighbouring pixels and channels with the same codes share it (banding). A
camera whose response differs does not do this: its response acts before
the one quantisation. For each bit depth (and, on 8-bit files, each rounding:
nearest, and the stochastic rounding the textured bench uses by default,
:func:`benchmarks.edited_captures.requantise`) this prints

- the written value less the unrounded edit, in linear light: its SD, its
  correlation between neighbouring pixels (along rows and columns) and
  between channels (0 for white rounding noise);
- the reconstructed BRDF of the edited capture against that of the
  untouched one, ``log f₁ = a + b log f₀`` (the library's γ on the ratio,
  ``f_std (f/f_std)^{1+ε}``, has ``b = 1+ε``, ``a = −ε log f_std``): the
  RMS of what is left in units of the capture's noise σ (both captures have
  the same noise draw, so what is left is what the edit added beyond γ), and
  the same for the library's :class:`~wardjax.effects._library.GammaMismatch`
  at ``ε = b − 1`` (no free intercept).

Run ``python -m benchmarks.requantisation [--texture noise] [--amplitude 0.1] [--seed 1] [--k 1.12]``.
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import numpy as np

from benchmarks.edited_captures import edit_capture, make_capture
from wardjax._files import decode_values, read_image


def _corr(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.corrcoef(a, b)[0, 1])


def rounding_error(base: Path, edited: Path, k: float, bits: int) -> dict:
    """The written edit less the unrounded one, in linear light, where the lit frame is above 20/255 of full scale."""
    full = float(2**bits - 1)
    c0 = read_image(base / "lit.png").astype(np.float64)
    c1 = read_image(edited / "lit.png").astype(np.float64)
    err = decode_values(c1 / full, "srgb") - decode_values((c0 / full) ** k, "srgb")
    m = np.all(c0 > 20 / 255 * full, axis=-1)
    both_r, both_c = m[:, :-1] & m[:, 1:], m[:-1] & m[1:]
    e = err[m]
    return {
        "sd": float(np.mean(e.std(0))),
        "lag1_row": float(np.mean([_corr(err[:, :-1, c][both_r], err[:, 1:, c][both_r]) for c in range(3)])),
        "lag1_col": float(np.mean([_corr(err[:-1, :, c][both_c], err[1:, :, c][both_c]) for c in range(3)])),
        "channels": float(np.mean([_corr(e[:, i], e[:, j]) for i, j in ((0, 1), (0, 2), (1, 2))])),
    }


def gamma_residual(base: Path, edited: Path) -> dict:
    """``log f₁ = a + b log f₀`` by least squares over the probe's values; what is left, in units of σ."""
    import jax
    import jax.numpy as jnp

    from wardjax.capture import load_capture
    from wardjax.effects._capture import capture_data
    from wardjax.effects._library import GammaMismatch

    d0, d1 = capture_data(load_capture(base)), capture_data(load_capture(edited))
    f0, f1, s0 = np.asarray(d0.y), np.asarray(d1.y), np.asarray(d0.sigma)
    ok = np.asarray(d0.mask) & np.asarray(d1.mask) & (f0 > 0) & (f1 > 0)
    x, y = np.log(f0[ok]), np.log(f1[ok])
    (a, b), *_ = np.linalg.lstsq(np.c_[np.ones_like(x), x], y, rcond=None)
    rel = s0[ok] / f0[ok]
    left = (y - a - b * x) / rel
    # the library's γ itself (no free intercept: it bends about f_std), at ε = b − 1
    with jax.enable_x64(True):
        m = GammaMismatch().measure({"eps": b - 1.0}, jnp.asarray(f0[ok]), {"f_std": float(d0.f_std)})
    lib = (y - np.log(np.asarray(m))) / rel
    return {
        "b": float(b),
        "a_expected": float(-(b - 1.0) * np.log(float(d0.f_std))),
        "a": float(a),
        "rms_sigma": float(np.sqrt(np.mean(left**2))),
        "rms_sigma_library": float(np.sqrt(np.mean(lib**2))),
    }


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--texture", default="noise")
    ap.add_argument("--amplitude", type=float, default=0.1)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--k", type=float, default=1.12, help="the edit c ↦ c^k")
    ap.add_argument("--size", nargs=2, type=int, default=(160, 120))
    a = ap.parse_args(argv)
    print(f"{a.texture} {a.amplitude:.0%}, seed {a.seed}, codes^{a.k}, {a.size[0]}×{a.size[1]}")
    print(
        f"{'bits':>4s} {'rounding':>10s} {'err SD':>9s} {'lag-1 row':>9s} {'lag-1 col':>9s} {'channels':>9s} "
        f"{'b (1+ε)':>8s} {'a':>7s} {'a of γ':>7s} {'left/σ':>7s} {'γ left/σ':>8s}"
    )
    with tempfile.TemporaryDirectory() as tmp:
        for bits, rounding in ((8, "nearest"), (8, "stochastic"), (16, "nearest")):
            base, edited = Path(tmp) / f"b{bits}", Path(tmp) / f"e{bits}_{rounding}"
            if not base.exists():
                kw = {"texture_amplitude": a.amplitude, "bit_depth": bits}
                make_capture(base, texture=a.texture, size=tuple(a.size), seed=a.seed, **kw)
            edit_capture(base, edited, "response", a.k, rounding=rounding, seed=a.seed)
            q, g = rounding_error(base, edited, a.k, bits), gamma_residual(base, edited)
            print(
                f"{bits:4d} {rounding:>10s} {q['sd']:9.2e} {q['lag1_row']:9.2f} {q['lag1_col']:9.2f} "
                f"{q['channels']:9.2f} {g['b']:8.4f} {g['a']:7.4f} {g['a_expected']:7.4f} {g['rms_sigma']:7.3f}"
                f" {g['rms_sigma_library']:8.3f}"
            )


if __name__ == "__main__":
    main()
