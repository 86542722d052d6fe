"""ρd maps in and out: read a linear map, write a synthesised tile."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .._files import srgb8, write_image
from ..capture import check_rho_d_map


def write_texture_image(path, image) -> Path:
    """Write a synthesised ρd: ``.tif``/``.tiff`` linear float32, ``.png`` an 8-bit sRGB view; atomically."""
    path = Path(path)
    img = np.asarray(image, np.float32)
    if img.ndim == 3 and img.shape[-1] == 1:
        img = img[..., 0]
    suffix = path.suffix.lower()
    if suffix in (".tif", ".tiff"):
        return write_image(path, img)
    if suffix == ".png":
        return write_image(path, srgb8(img))
    raise ValueError(f"{path}: unknown image type {path.suffix!r}, expected .tif, .tiff or .png")


def read_rho_d(path) -> np.ndarray:
    """Read a linear ρd map (``.tif``/``.tiff`` or ``.npy``) as float64 ``(H, W)`` or ``(H, W, C)``.

    Integer images (codes, not reflectances) and maps with values far outside [0, 1] are refused
    with a note on how to convert them (:func:`wardjax.capture._rules.check_rho_d_map`).
    """
    path = Path(path)
    if path.is_dir():
        raise ValueError(f"{path}: is a folder, expected a ρd file (.tif, .tiff or .npy)")
    if not path.is_file():
        raise ValueError(f"{path}: no such file")
    suffix = path.suffix.lower()
    try:
        if suffix in (".tif", ".tiff"):
            import tifffile

            a = tifffile.imread(path)
        elif suffix == ".npy":
            a = np.load(path, allow_pickle=False)
        else:
            raise ValueError(f"{path}: unknown ρd file type {path.suffix!r}, expected .tif, .tiff or .npy (linear ρd)")
    except (OSError, ValueError) as e:
        if str(path) in str(e):
            raise
        raise ValueError(f"{path}: cannot read ({e})") from None
    if a.ndim not in (2, 3) or not np.issubdtype(a.dtype, np.number):
        raise ValueError(f"{path}: expected an (H, W) or (H, W, C) numeric image, got {a.dtype} {a.shape}")
    check_rho_d_map(str(path), a)  # RuleError names the path
    return a.astype(np.float64)
