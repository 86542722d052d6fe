"""Files in and out: the one atomic writer, image codecs and the value encodings.

Every file wardjax writes goes through :func:`atomic_path`: the data go to a
temporary file beside the target (named ``.<stem>.<random><suffix>.tmp``, so
that :func:`remove_temporaries` finds any an interrupted run left), which is
given the mode an ordinary file gets under the user's umask and then renamed
onto the target. A reader never sees a half-written file.

Encodings of stored values (``capture.toml`` ``images.encoding``):

* ``"srgb"``: IEC 61966-2-1, through colour-science's ``eotf_inverse_sRGB`` /
  ``eotf_sRGB``;
* ``"gamma2.2"``: ``c = x^(1/2.2)``;
* ``"linear"``: ``c = x``.
"""

from __future__ import annotations

import contextlib
import hashlib
import io
import json
import math
import os
import shutil
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

__all__ = [
    "ENCODINGS",
    "RAW_SUFFIXES",
    "atomic_path",
    "check_writable_dir",
    "check_writable_file",
    "commit_folder",
    "decode_image",
    "decode_lut",
    "decode_values",
    "encode_image",
    "encode_values",
    "as_rgb",
    "jsonable",
    "read_image",
    "remove_temporaries",
    "sha256",
    "srgb8",
    "write_bytes_atomic",
    "write_image",
    "write_json_atomic",
]

ENCODINGS = ("srgb", "gamma2.2", "linear")
RAW_SUFFIXES = (".dng", ".cr2", ".cr3", ".nef", ".arw", ".orf", ".rw2", ".raf")
_TMP_SUFFIX = ".tmp"


# --------------------------------------------------------------------------- atomic files


def _file_mode() -> int:
    """The mode a new ordinary file gets under the process umask (0644 under umask 022)."""
    mask = os.umask(0)
    os.umask(mask)
    return 0o666 & ~mask


@contextlib.contextmanager
def atomic_path(path) -> Iterator[Path]:
    """Yield a temporary path beside ``path`` (same suffix); on success rename it onto ``path``.

    The temporary file is removed if the block raises (or the process is
    interrupted by an exception); the renamed file has the umask's mode.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.stem}.", suffix=f"{path.suffix}{_TMP_SUFFIX}")
    os.close(fd)
    try:
        yield Path(tmp)
        os.chmod(tmp, _file_mode())  # mkstemp makes 0600
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)


def remove_temporaries(folder) -> None:
    """Delete the temporary files an interrupted :func:`atomic_path` left in ``folder``."""
    folder = Path(folder)
    if folder.is_dir():
        for tmp in folder.glob(f".*{_TMP_SUFFIX}"):
            tmp.unlink(missing_ok=True)


def _writable_folder_reason(folder: Path) -> str | None:
    """Why files cannot be created in ``folder`` (made if missing), or ``None``: the first existing ancestor decides."""
    probe = folder
    while not probe.exists():
        if probe.parent == probe:
            return "no existing parent folder"
        probe = probe.parent
    if not probe.is_dir():
        return f"{probe} is a file, not a folder" if probe != folder else "is a file, not a folder"
    if not os.access(probe, os.W_OK | os.X_OK):
        return f"{probe} is not writable" if probe != folder else "the folder is not writable"
    return None


def check_writable_dir(path) -> None:
    """Raise ``ValueError`` (one line naming ``path`` and the reason) if files cannot be written under folder ``path``.

    Checked before any long computation: a parent that is a file, a read-only
    folder, a full disk (less than 1 MiB free).
    """
    path = Path(path)
    reason = _writable_folder_reason(path)
    if reason is None:
        probe = path
        while not probe.exists():
            probe = probe.parent
        if shutil.disk_usage(probe).free < 1 << 20:
            reason = "the disk is full"
    if reason is not None:
        raise ValueError(f"{path}: cannot write here: {reason}")


def check_writable_file(path) -> None:
    """Raise ``ValueError`` naming ``path`` if it cannot be written: a folder, or a folder that cannot hold it."""
    path = Path(path)
    if path.is_dir():
        raise ValueError(f"{path}: cannot write here: is a folder, expected a file name")
    try:
        check_writable_dir(path.parent)
    except ValueError as e:
        raise ValueError(f"{path}: cannot write here: {str(e).split(': cannot write here: ', 1)[1]}") from None


def commit_folder(staging, dest, *, last: str) -> None:
    """Move the files of the flat folder ``staging`` into ``dest`` (made if missing), ``last`` last; drop ``staging``.

    A batch writes a capture's outputs into a staging folder and commits them
    only once all are written, so that a fit failing mid-way leaves ``dest``
    as it was; ``last`` (``params.json``) marks the capture finished.
    """
    staging, dest = Path(staging), Path(dest)
    dest.mkdir(parents=True, exist_ok=True)
    names = sorted(p.name for p in staging.iterdir() if p.is_file())
    for name in sorted(names, key=lambda n: n == last):
        os.replace(staging / name, dest / name)
    shutil.rmtree(staging)


def write_bytes_atomic(path, data: bytes | bytearray) -> None:
    """Write ``data`` to ``path`` atomically."""
    with atomic_path(path) as tmp:
        tmp.write_bytes(data)


def jsonable(x) -> Any:
    """``x`` with NumPy scalars and arrays as plain Python, non-finite floats as ``None``."""
    if isinstance(x, dict):
        return {str(k): jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [jsonable(v) for v in x]
    if isinstance(x, np.ndarray):
        return jsonable(x.tolist())
    if isinstance(x, (np.floating, float)):
        x = float(x)
        return x if math.isfinite(x) else None
    if isinstance(x, np.integer):
        return int(x)
    if isinstance(x, np.bool_):
        return bool(x)
    return x


def write_json_atomic(path, obj, *, compact: bool = False) -> None:
    """Write JSON (NaN/inf as ``null``) so that a reader never sees a half-written file."""
    text = (
        json.dumps(jsonable(obj), separators=(",", ":"))
        if compact
        else json.dumps(jsonable(obj), indent=2, ensure_ascii=False)
    )
    write_bytes_atomic(path, (text + "\n").encode())


def sha256(path) -> str:
    """``"sha256:<hex>"`` of a file's bytes."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return "sha256:" + h.hexdigest()


# --------------------------------------------------------------------------- encodings


def decode_values(c, encoding: str) -> np.ndarray | np.floating:
    """Encoded values in [0, 1] → linear, for ``"srgb"`` (IEC 61966-2-1), ``"gamma2.2"``, ``"linear"``."""
    c = np.asarray(c, np.float64)
    if encoding == "srgb":
        import colour

        return np.asarray(colour.models.eotf_sRGB(c), np.float64)
    if encoding == "gamma2.2":
        return c**2.2
    if encoding == "linear":
        return c
    raise ValueError(f"encoding={encoding!r} is not one of 'srgb', 'gamma2.2', 'linear'")


def encode_values(x, encoding: str) -> np.ndarray | np.floating:
    """Linear values in [0, 1] (clipped) → encoded, the inverse of :func:`decode_values`."""
    x = np.clip(np.asarray(x, np.float64), 0.0, 1.0)
    if encoding == "srgb":
        import colour

        return np.asarray(colour.models.eotf_inverse_sRGB(x), np.float64)
    if encoding == "gamma2.2":
        return x ** (1 / 2.2)
    if encoding == "linear":
        return x
    raise ValueError(f"encoding={encoding!r} is not one of 'srgb', 'gamma2.2', 'linear'")


def decode_lut(encoding: str, bit_depth: int) -> np.ndarray:
    """The linear float32 value of every ``bit_depth``-bit code in ``encoding``."""
    n = 1 << bit_depth
    c = np.arange(n, dtype=np.float64) / (n - 1)
    return np.asarray(decode_values(c, encoding), np.float32)  # c is an array: so is the result


def decode_image(codes: np.ndarray, encoding: str, bit_depth: int) -> np.ndarray:
    """Integer codes → linear float32 (full scale 1), by table look-up."""
    return decode_lut(encoding, bit_depth)[codes]


def encode_image(linear: np.ndarray, encoding: str, bit_depth: int) -> np.ndarray:
    """Linear values (clipped to [0, 1]) → integer codes of ``bit_depth`` bits, rounded."""
    top = (1 << bit_depth) - 1
    codes = np.rint(encode_values(linear, encoding) * top)
    return codes.astype(np.uint8 if bit_depth == 8 else np.uint16)


def srgb8(linear) -> np.ndarray:
    """An 8-bit sRGB view of linear values (NaN shown black)."""
    return encode_image(np.nan_to_num(np.asarray(linear, np.float64), nan=0.0), "srgb", 8)


# --------------------------------------------------------------------------- image files


def read_image(path, *, rgb: bool = True) -> np.ndarray:
    """Read an image file as stored: ``(H, W, 3)`` uint8/uint16 (raw files: linear uint16).

    Grey images are repeated over RGB and an alpha channel is dropped (see
    :func:`as_rgb`); ``rgb=False`` returns the channels as stored. A file that
    cannot be opened raises ``OSError``; one that cannot be decoded (truncated,
    garbled, not an image) raises ``ValueError`` with the reader's first line,
    whatever the reader raised (decoders of corrupt data raise a zoo of errors:
    ``struct.error``, ``IndexError``, ``EOFError``, ``zlib.error``…).
    """
    path = Path(path)
    suffix = path.suffix.lower()
    data = None if suffix in RAW_SUFFIXES else path.read_bytes()  # OSError: the file, not its contents
    try:
        img = _decode(path, suffix, data)
    except Exception as e:  # any decoder failure is a corrupt file to the user
        reason = (str(e).strip().splitlines() or [type(e).__name__])[0][:160]
        raise ValueError(reason) from None
    return as_rgb(img) if rgb else img


def _decode(path: Path, suffix: str, data: bytes | None) -> np.ndarray:
    if data is None:
        import rawpy

        with rawpy.imread(str(path)) as raw:
            return raw.postprocess(
                gamma=(1, 1), no_auto_bright=True, output_bps=16, use_camera_wb=True, output_color=rawpy.ColorSpace.sRGB
            )
    if suffix in (".tif", ".tiff"):
        import tifffile

        return np.asarray(tifffile.imread(io.BytesIO(data)))
    if suffix == ".png":
        import imagecodecs  # Pillow (imageio's default) reduces 16-bit RGB PNG to 8 bits

        return np.asarray(imagecodecs.png_decode(data))
    import imageio.v3 as iio

    # Pillow alone: imageio would otherwise try every plugin it knows on a file Pillow cannot read.
    return np.asarray(iio.imread(data, plugin="pillow"))


def as_rgb(img: np.ndarray) -> np.ndarray:
    """An image as read, made ``(H, W, 3)``: grey repeated over RGB, alpha dropped (``ValueError`` otherwise)."""
    if img.ndim == 3 and img.shape[-1] == 1:
        img = img[..., 0]
    if img.ndim == 2:
        img = np.repeat(img[..., None], 3, axis=-1)
    if img.ndim != 3 or img.shape[-1] not in (3, 4):
        raise ValueError(f"expected an RGB image, got array shape {img.shape}")
    return img[..., :3]


def write_image(path, array: np.ndarray, *, tile: int | None = None) -> Path:
    """Write an image atomically, by suffix.

    ``.png``: 8- or 16-bit codes (imagecodecs); ``.tif``/``.tiff``: the array
    as it is (float32 linear data or integer codes), in ``tile × tile`` tiles
    if ``tile`` is given (a multiple of 16); ``.jpg``/``.jpeg``: 8-bit codes,
    quality 95.
    """
    path = Path(path)
    array = np.asarray(array)
    suffix = path.suffix.lower()
    if suffix == ".png":
        import imagecodecs

        write_bytes_atomic(path, imagecodecs.png_encode(np.ascontiguousarray(array), level=6))
    elif suffix in (".tif", ".tiff"):
        import tifffile

        photometric = "rgb" if array.ndim == 3 and array.shape[-1] == 3 else "minisblack"
        with atomic_path(path) as tmp:
            tifffile.imwrite(tmp, array, photometric=photometric, tile=None if tile is None else (tile, tile))
    elif suffix in (".jpg", ".jpeg"):
        import imageio.v3 as iio

        with atomic_path(path) as tmp:
            iio.imwrite(tmp, array, extension=suffix, quality=95)
    else:
        raise ValueError(f"{path}: unknown image type {path.suffix!r}, expected .png, .tif, .tiff or .jpg")
    return path
