"""Effects hidden by *editing the image files* of a capture ``wardjax simulate`` wrote, then diagnosed blind.

Independence from the fitter
    The edits act on the decoded lit frame (``wardjax._files`` reads, decodes,
    encodes and writes the images; nothing of :mod:`wardjax.effects` is used to
    make them), in the image's own coordinates, as a user's changed camera or
    rig would:

    - ``response``: the encoded codes raised to a power ``c ↦ c^k`` (a tone
      curve; in linear light not the library's ``f^{1+ε}`` about the standard);
    - ``offset``: a constant added to the lit frame's linear values (ambient
      light present only in the lit frame);
    - ``gradient``: the lit frame multiplied by ``1 + g (u − u₀)/W`` across the
      image columns (a lamp off the symmetry plane, seen in image position);
    - ``saturation``: the lit frame's exposure raised by ``k`` and clipped at
      full scale (the highlight clips);
    - ``gradient_y``: the same ramp along the image rows (even about the
      stripline: cancels from ``v/v_std``, a null case that is not detectable);
    - ``blur``: the lit frame blurred by a Gaussian of SD ``σ`` px (a defocus
      or a soft lens, outside the library);
    - ``cast``: the lit frame's channels scaled by ``(1 + c, 1, 1 − c)`` (a
      colour cast of the lamp absent when the standard was calibrated; on the
      ratio a per-channel factor).

    The image is re-quantised to the capture's bit depth, by nearest or by
    stochastic rounding (``rounding``). Nearest rounding after a map from codes
    to codes makes the rounding error a fixed function of the original code:
    neighbouring pixels and channels with the same codes share it (banding,
    ``benchmarks/requantisation.py``), which no camera does — its response acts
    on the signal before its one quantisation, and the signal's noise makes
    that quantisation's error white. Stochastic rounding (``⌊x + U⌋``, ``U``
    uniform on [0, 1), drawn from ``seed``) is unbiased and independent from
    pixel to pixel and channel to channel: the edit then adds white noise of
    variance ≤ 1/4 code², which the capture's noise estimate measures, and no
    pattern of its own.

Run ``python -m benchmarks.edited_captures [--texture wood|marble|none ...] [--size W H]``.
"""

from __future__ import annotations

import argparse
import shutil
import tempfile
import time
from pathlib import Path

import numpy as np

from wardjax._files import decode_image, encode_values, read_image, write_image

__all__ = ["EDITS", "ROUNDINGS", "edit_capture", "make_capture", "diagnose_folder", "requantise"]

CONFIGS = {"old": {"texture": False, "stop_within_noise": False}, "new": {"texture": True}}
EDITS = {
    "none": None,
    "response": ("response", 1.12),
    "offset": ("offset", 0.01),
    "gradient": ("gradient", 0.25),
    "gradient_y": ("gradient_y", 0.25),
    "saturation": ("saturation", 2.5),
}


def make_capture(
    folder: Path, *, texture: str = "wood", size=(320, 240), seed: int = 0, alpha: float = 0.12, eta: float = 0.0, **kw
):
    """A capture ``wardjax simulate`` writes: isotropic (nothing hidden in the material) unless ``eta``
    makes it anisotropic, ``αx, αy = α e^{±η}`` along the tangent (1, 0)."""
    from wardjax.simulate import simulate_capture
    from wardjax.ward import WardParams

    ax, ay = alpha * float(np.exp(eta)), alpha * float(np.exp(-eta))
    p = WardParams(rho_d=(0.6, 0.5, 0.4), rho_s=0.04, alpha_x=ax, alpha_y=ay)
    return simulate_capture(p, folder, seed=seed, image_size=tuple(size), texture=texture, **kw)


ROUNDINGS = ("nearest", "stochastic")


def requantise(x: np.ndarray, full: float, dtype, rounding: str = "nearest", seed: int | list[int] = 0) -> np.ndarray:
    """Codes from unrounded codes ``x`` (any shape, in ``[0, full]``), rounded to nearest or stochastically.

    ``seed``: an int or a list of ints (:func:`numpy.random.default_rng`), for the stochastic draw.
    """
    if rounding == "nearest":
        q = np.rint(x)
    elif rounding == "stochastic":
        q = np.floor(x + np.random.default_rng(seed).random(np.shape(x)))
    else:
        raise ValueError(f"rounding must be one of {ROUNDINGS}, not {rounding!r}")
    return np.clip(q, 0.0, full).astype(dtype)


def edit_capture(
    src: Path, dst: Path, kind: str | None, amount: float = 0.0, *, rounding: str = "nearest", seed: int | list[int] = 0
) -> Path:
    """Copy the capture folder ``src`` to ``dst`` with the lit frame edited (see the module docstring).

    ``rounding``: how the edited frame is re-quantised, ``"nearest"`` or ``"stochastic"`` (drawn from ``seed``).
    """
    import tomllib

    if rounding not in ROUNDINGS:
        raise ValueError(f"rounding must be one of {ROUNDINGS}, not {rounding!r}")

    shutil.copytree(src, dst, dirs_exist_ok=True)
    if kind is None:
        return dst
    cfg = tomllib.loads((src / "capture.toml").read_text())
    enc, bits = cfg["images"]["encoding"], int(cfg["images"]["bit_depth"])
    lit = dst / cfg["images"]["lit"]
    codes = read_image(lit)
    full = float(2**bits - 1)
    if kind == "response":
        write_image(lit, requantise(full * (codes / full) ** amount, full, codes.dtype, rounding, seed))
        return dst
    v = decode_image(codes, enc, bits).astype(np.float64)
    h, w = v.shape[:2]
    u = (np.arange(w) - (w - 1) / 2) / w
    r = (np.arange(h) - (h - 1) / 2) / h
    if kind == "offset":
        v = v + amount
    elif kind == "gradient":
        v = v * (1.0 + amount * u)[None, :, None]
    elif kind == "gradient_y":
        v = v * (1.0 + amount * r)[:, None, None]
    elif kind == "saturation":
        v = v * amount
    elif kind == "blur":
        from scipy.ndimage import gaussian_filter

        v = gaussian_filter(v, sigma=(amount, amount, 0.0), mode="nearest")
    elif kind == "cast":
        v = v * np.array([1.0 + amount, 1.0, 1.0 - amount])
    else:
        raise ValueError(f"unknown edit {kind!r}")
    x = encode_values(np.clip(v, 0.0, 1.0), enc) * full
    write_image(lit, requantise(x, full, codes.dtype, rounding, seed))
    return dst


def diagnose_folder(folder: Path, **kw):
    """What ``wardjax diagnose`` runs: the capture's scanline data and ``discover`` on them."""
    from wardjax.capture import load_capture
    from wardjax.effects import ScanlineModel, discover
    from wardjax.effects._capture import capture_data

    cap = load_capture(folder)
    data = capture_data(cap)
    return discover(ScanlineModel(cap.config.fit.normalization), data, keep_plot_data=False, **kw)


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--texture", nargs="+", default=["wood", "none"])
    ap.add_argument("--edits", nargs="+", default=list(EDITS))
    ap.add_argument("--size", nargs=2, type=int, default=(320, 240))
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument(
        "--configs",
        nargs="+",
        default=["new"],
        choices=list(CONFIGS),
        help="old: one ρd per scanline, no stop rule (the issue's figures); new: texture model and stop rule",
    )
    a = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        for tex in a.texture:
            base = Path(tmp) / f"base_{tex}"
            make_capture(base, texture=tex, size=a.size, seed=a.seed)
            for name in a.edits:
                spec = EDITS[name]
                d = edit_capture(base, Path(tmp) / f"{tex}_{name}", *(spec or (None,)))
                for conf in a.configs:
                    t0 = time.perf_counter()
                    rep = diagnose_folder(d, **CONFIGS[conf])
                    gaps = " → ".join(f"{g:.3f}" for g in rep.gap)
                    print(
                        f"{conf:4s} {tex:6s} {name:11s} found {rep.found or '-'}  gap {gaps}  "
                        f"partial {rep.partial or '-'}  texture {rep.settings.get('texture')}  "
                        f"({time.perf_counter() - t0:.1f} s)",
                        flush=True,
                    )


if __name__ == "__main__":
    main()
