"""ρd maps in and out: read a linear map, write a synthesised tile."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from .._files import check_regular_file, npy_header, srgb8, write_image
from .._rules import RuleError, check_count, check_memory, check_rho_d_map, one_line, shorten


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


def _declared(path: Path, suffix: str) -> tuple[tuple[int, ...], np.dtype]:
    """The shape and dtype the file's header declares, before its data are read (``ValueError`` if unreadable)."""
    if suffix == ".npy":
        return npy_header(path)
    import logging

    import tifffile

    log = logging.getLogger("tifffile")
    level = log.level
    log.setLevel(logging.CRITICAL)  # its warnings about a corrupt file become the one line below
    try:
        with tifffile.TiffFile(path) as tif:
            series = tif.series[0]
            return tuple(int(k) for k in series.shape), np.dtype(series.dtype)
    except Exception as e:  # a corrupt header: tifffile raises many kinds, or finds no image
        reason = shorten(one_line((str(e).strip().splitlines() or [type(e).__name__])[0]), 120)
        raise ValueError(f"{path}: not a readable TIFF ({reason or 'no image in it'})") from None
    finally:
        log.setLevel(level)


def read_rho_d(path) -> np.ndarray:
    """Read a linear ρd map (``.tif``/``.tiff`` or ``.npy``) as float64 ``(H, W)`` or ``(H, W, C)``.

    Only a regular file is read (a FIFO or a device is named as such); its header's size is held to
    :data:`wardjax.capture.LIMITS` and the memory available before the data are read. Integer images
    (codes, not reflectances), complex values and maps outside [0, 1] beyond noise are refused with a
    note on how to convert them (:func:`wardjax.capture.check_rho_d_map`).
    """
    path = Path(path)
    check_regular_file(path, "ρd file (.tif, .tiff or .npy)")
    suffix = path.suffix.lower()
    if suffix not in (".tif", ".tiff", ".npy"):
        raise ValueError(f"{path}: unknown ρd file type {path.suffix!r}, expected .tif, .tiff or .npy (linear ρd)")
    shape, dtype = _declared(path, suffix)
    try:
        check_count(str(path), math.prod(shape[:2]), "pixels", "pixels")
        check_memory(str(path), shape, max(dtype.itemsize, 8), copies=2)
    except RuleError as e:
        raise ValueError(str(e)) from None
    if dtype.kind == "c":  # refused before it is read: no ComplexWarning on the way
        check_rho_d_map(str(path), np.empty(0, dtype))
    try:
        if suffix == ".npy":
            a = np.load(path, allow_pickle=False)
        else:
            import tifffile

            a = tifffile.imread(path)
    except (OSError, ValueError) as e:
        if str(path) in str(e):
            raise
        raise ValueError(f"{path}: cannot read ({shorten(one_line(str(e)), 160)})") from None
    if a.ndim not in (2, 3) or not np.issubdtype(a.dtype, np.number):
        raise ValueError(f"{path}: expected an (H, W) or (H, W, C) numeric image, got {a.dtype} {a.shape}")
    check_rho_d_map(str(path), a)  # RuleError names the path
    return a.astype(np.float64)
