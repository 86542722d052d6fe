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
import secrets
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
    "check_regular_file",
    "check_writable_dir",
    "check_writable_file",
    "COMMIT_JOURNAL",
    "commit_folder",
    "decode_image",
    "decode_lut",
    "decode_values",
    "encode_image",
    "encode_values",
    "file_problem",
    "as_rgb",
    "jsonable",
    "npy_header",
    "read_image",
    "recover_commit",
    "remove_temporaries",
    "sha256",
    "srgb8",
    "staged_folder",
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


def _name_too_long(path: Path) -> str | None:
    from ._rules import RuleError, check_path_name

    try:
        check_path_name(path)
    except RuleError as e:
        return e.message
    return None


def check_writable_dir(path) -> None:
    """Raise ``ValueError`` (one line naming ``path`` and the reason) if files cannot be written under folder ``path``.

    Checked before any long computation: a parent that is a file, a read-only
    folder, a full disk (less than 1 MiB free).
    """
    path = Path(path)
    reason = _name_too_long(path) or _writable_folder_reason(path)
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
    if (reason := _name_too_long(path)) is not None:
        raise ValueError(f"{path}: cannot write here: {reason}")
    if path.is_dir():
        raise ValueError(f"{path}: cannot write here: is a folder, expected a file name")
    try:
        check_writable_dir(path.parent)
    except ValueError as e:
        raise ValueError(f"{path}: cannot write here: {str(e).split(': cannot write here: ', 1)[1]}") from None


@contextlib.contextmanager
def staged_folder(dest) -> Iterator[Path]:
    """Yield a hidden staging folder beside ``dest``; when the block succeeds, move its files into ``dest``.

    ``dest`` is made if missing and its files of the same names are replaced; if the block
    raises, the staging folder is removed and ``dest`` is left as it was.
    """
    dest = Path(dest)
    staging = dest.parent / f".{dest.name}.{secrets.token_hex(4)}.partial"
    staging.mkdir(parents=True)
    try:
        yield staging
        dest.mkdir(parents=True, exist_ok=True)
        for f in sorted(staging.iterdir()):
            os.replace(f, dest / f.name)
    finally:
        shutil.rmtree(staging, ignore_errors=True)


# The journal :func:`commit_folder` keeps in its destination while it moves files in.
COMMIT_JOURNAL = ".wardjax-commit.json"


def commit_folder(staging, dest, *, last: str) -> None:
    """Move the files of the flat folder ``staging`` into ``dest`` (made if missing), ``last`` last; drop ``staging``.

    A batch writes a capture's outputs into a staging folder and commits them
    only once all are written, so that a fit failing mid-way leaves ``dest``
    as it was; ``last`` (``params.json``) marks the capture finished. A file in
    ``dest`` is replaced only if ``dest`` holds an earlier fit (a ``last`` that
    wardjax wrote); otherwise it is not ours, and ``ValueError`` names it
    before anything is moved.

    While the files move, ``dest`` holds a journal (:data:`COMMIT_JOURNAL`: the
    names being moved, the digest of ``last``), written atomically before the
    first move and removed after the last. A process killed between the two
    leaves it behind, and :func:`recover_commit` (called here first, and by a
    batch before it looks at ``dest``) reads from it what the half-done move
    left: the names it lists are wardjax's, so they are removed, never refused
    as someone else's files.
    """
    staging, dest = Path(staging), Path(dest)
    recover_commit(dest)
    names = sorted(p.name for p in staging.iterdir() if p.is_file())
    ours = _wardjax_folder(dest / last)  # an earlier fit's outputs, replaced by this one's
    for name in names:
        target = dest / name
        if (target.exists() or target.is_symlink()) and not ours:
            raise ValueError(
                f"{target}: exists and was not written by wardjax; refusing to replace it "
                "(choose an output folder of its own)"
            )
    dest.mkdir(parents=True, exist_ok=True)
    digest = sha256(staging / last) if last in names else None
    write_json_atomic(dest / COMMIT_JOURNAL, {"names": names, "last": last, "last_sha256": digest})
    for name in sorted(names, key=lambda n: n == last):
        os.replace(staging / name, dest / name)
    os.unlink(dest / COMMIT_JOURNAL)
    shutil.rmtree(staging)


def recover_commit(dest) -> bool:
    """Settle a :func:`commit_folder` that was killed while it moved files into ``dest``; ``True`` if there was one.

    With ``last`` in ``dest`` and its digest the journal's, every file had
    moved: only the journal is removed. Otherwise the move stopped part way,
    and ``dest`` mixes the new files with the old (or holds only some of the
    new): every file the journal names is removed with it, so that ``dest``
    holds no finished result and the next run writes it afresh. The names
    were checked to be wardjax's own before the journal was written.
    """
    dest = Path(dest)
    journal = dest / COMMIT_JOURNAL
    if not journal.is_file():
        return False
    try:
        doc = json.loads(journal.read_text())
        names, last, digest = list(doc["names"]), str(doc["last"]), doc["last_sha256"]
    except (OSError, ValueError, KeyError, TypeError):  # written atomically: only a foreign file reads wrong
        names, last, digest = [], "", None
    done = digest is not None and (dest / last).is_file() and sha256(dest / last) == digest
    if not done:
        for name in names:
            target = dest / str(name)
            if target.parent == dest and (target.is_file() or target.is_symlink()):
                target.unlink()
    journal.unlink()
    return True


def _wardjax_folder(record: Path) -> bool:
    """``record`` is a ``params.json`` wardjax wrote: its folder holds a finished fit's outputs."""
    try:
        doc = json.loads(record.read_text())
        return doc.get("software", {}).get("name") == "wardjax"
    except (OSError, ValueError, AttributeError):
        return False


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


# --------------------------------------------------------------------------- input files


def file_problem(path) -> str | None:
    """Why ``path`` is not a regular file to read (a FIFO, a device, a folder, missing), or ``None``."""
    import stat

    path = Path(path)
    if any(len(os.fsencode(part)) > 255 for part in path.parts):
        return "has a path component longer than the 255 bytes file systems allow"
    try:
        mode = path.stat().st_mode  # follows links: a link to /dev/urandom is a character device
    except FileNotFoundError:
        return "is a broken link (its target does not exist)" if path.is_symlink() else "no such file"
    except OSError as e:
        return f"cannot be opened ({e.strerror or type(e).__name__})"
    if stat.S_ISREG(mode):
        return None
    target = f" (a link to {os.path.realpath(path)})" if path.is_symlink() else ""
    for test, what in (
        (stat.S_ISDIR, "a folder"),
        (stat.S_ISFIFO, "a FIFO (named pipe)"),
        (stat.S_ISCHR, "a character device"),
        (stat.S_ISBLK, "a block device"),
        (stat.S_ISSOCK, "a socket"),
    ):
        if test(mode):
            return f"is {what}{target}, not a regular file"
    return f"is not a regular file{target}"


def check_regular_file(path, what: str = "file") -> None:
    """Raise ``ValueError`` (one line naming ``path``) unless it is a regular file: say what it is instead.

    A FIFO, a device such as ``/dev/urandom`` or a folder would hang a reader or feed it without
    end; a name too long for the file system is refused before any system call fails on it.
    """
    from ._rules import RuleError, check_path_name

    path = Path(path)
    try:
        check_path_name(path)
    except RuleError as e:
        raise ValueError(str(e)) from None
    reason = file_problem(path)
    if reason is not None:
        expected = "" if reason == "no such file" else f"; expected a {what}"
        raise ValueError(f"{path}: {reason}{expected}")


def npy_header(path) -> tuple[tuple[int, ...], np.dtype]:
    """The shape and dtype a ``.npy`` file declares, read from its header alone (no data read).

    Raises ``ValueError`` naming the file if the header cannot be read. With
    :func:`wardjax.capture.check_memory` a header claiming 10¹² values is refused before
    ``np.load`` tries to allocate them.
    """
    try:
        with open(path, "rb") as fh:
            version = np.lib.format.read_magic(fh)
            if version == (1, 0):
                shape, _, dtype = np.lib.format.read_array_header_1_0(fh)
            else:
                shape, _, dtype = np.lib.format.read_array_header_2_0(fh)
    except (ValueError, OSError, EOFError, SyntaxError) as e:
        first = (str(e).strip().splitlines() or [type(e).__name__])[0][:160]
        raise ValueError(f"{path}: not a readable .npy file ({first})") from None
    return tuple(int(k) for k in shape), np.dtype(dtype)


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

        with tifffile.TiffFile(io.BytesIO(data)) as tif:
            page = tif.pages[0]
            _check_pixels(path, page.shape[-3:-1] if page.planarconfig == 2 else page.shape[:2])  # pyright: ignore
            img = np.asarray(tif.asarray())
            if page.planarconfig == 2 and img.ndim == 3 and img.shape[0] in (3, 4):  # pyright: ignore
                img = np.moveaxis(img, 0, -1)  # planar configuration: one plane per channel, read as (H, W, C)
            return img
    if suffix == ".png":
        import imagecodecs  # Pillow (imageio's default) reduces 16-bit RGB PNG to 8 bits

        if data[12:16] == b"IHDR":  # width and height, big-endian, before anything is decoded
            _check_pixels(path, (int.from_bytes(data[20:24], "big"), int.from_bytes(data[16:20], "big")))
        return np.asarray(imagecodecs.png_decode(data))
    import imageio.v3 as iio
    from PIL import Image

    try:
        with Image.open(io.BytesIO(data)) as im:  # the header only
            size = im.size
    except Exception:  # the reader below says why the file cannot be read
        size = None
    if size is not None:
        _check_pixels(path, size[::-1])

    # Pillow alone: imageio would otherwise try every plugin it knows on a file Pillow cannot read.
    return np.asarray(iio.imread(data, plugin="pillow"))


class _TooLarge(ValueError):
    """An image whose header declares more pixels than :data:`wardjax.capture.LIMITS` allows."""


def _check_pixels(path: Path, hw) -> None:
    """Refuse, from its header, an image of more pixels than ``LIMITS["pixels"]`` (before decoding it)."""
    from ._rules import LIMITS

    h, w = (int(k) for k in hw)
    if h * w > LIMITS["pixels"]:
        raise _TooLarge(f"{w}×{h} pixels is more than the {LIMITS['pixels']:,} allowed")


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
