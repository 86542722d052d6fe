"""Import the rectified layout of multi-view flash datasets into a ``method = "multiview"`` capture folder.

The layout (MaterialGAN's real captures, Guo et al. 2020, and the renders
of :mod:`wardjax.render` use it)::

    SRC/
      0.png … K-1.png     rectified images of the sample plane (8 or 16 bit), all the same size;
                          00.png … also accepted
      camera_pos.txt      K lines "x y z" (or "x,y,z"): camera centres, sample frame
      light_pos.txt       K lines "x y z"; optional — absent means the light is at the camera (flash)
      light_power.txt     one number, or three (r g b): P in pixel units with distances in the
                          layout's unit (linear v = P · f_r · cos θi / d²)
      image_size.txt      one number: physical width of the rectified images

The sample frame: origin at the image centre, x along columns (right), y
along rows upwards, z out of the sample; pixel ``(r, c)`` of a ``W``-wide
image of width ``S`` lies at ``x = ((c + ½)/W − ½)·S``, ``y = −((r + ½)/H − ½)·H·S/W``
(MaterialGAN's ``Microfacet.pos``). Lengths are in centimetres by default
(``units``); the capture stores millimetres, and ``P`` is rescaled with the
square of the length unit. MaterialGAN's images are gamma-2.2 encoded
(``encoding="gamma2.2"``), not sRGB; wardjax's renders are sRGB.
"""

from __future__ import annotations

import json
import re
import shutil
import tempfile
from pathlib import Path

import numpy as np

from .._files import commit_folder, recover_commit, write_bytes_atomic
from ._errors import CAPTURE_FILE, CaptureError
from ._photo import PhotoCapture

__all__ = ["LAYOUTS", "MM_PER_UNIT", "import_capture"]

LAYOUTS = ("rectified",)
MM_PER_UNIT = {"mm": 1.0, "cm": 10.0, "m": 1000.0}
_ENCODINGS = ("srgb", "gamma2.2", "linear")


def _numbers(path: Path, per_line: int | None) -> list[list[float]]:
    """The numeric lines of a text file (commas or blanks between numbers), each checked for its count."""
    rows = []
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as e:
        raise CaptureError(path.name, None, f"cannot be read ({type(e).__name__})") from None
    for i, line in enumerate(text.splitlines(), 1):
        parts = [p for p in re.split(r"[,\s]+", line.strip()) if p]
        if not parts:
            continue
        try:
            vals = [float(p) for p in parts]
        except ValueError:
            raise CaptureError(path.name, f"line {i}", f"expected numbers, got {line.strip()[:60]!r}") from None
        if not all(np.isfinite(vals)):
            raise CaptureError(path.name, f"line {i}", f"holds a value that is not finite: {line.strip()[:60]!r}")
        if per_line is not None and len(vals) != per_line:
            raise CaptureError(path.name, f"line {i}", f"expected {per_line} numbers 'x y z', got {len(vals)}")
        rows.append(vals)
    if not rows:
        raise CaptureError(path.name, None, "holds no numbers")
    return rows


def _images(src: Path) -> list[Path]:
    found = []
    for k in range(100000):
        for name in (f"{k}.png", f"{k:02d}.png"):
            if (src / name).is_file():
                found.append(src / name)
                break
        else:
            break
    if not found:
        raise CaptureError(str(src), None, "holds no rectified images 0.png, 1.png, … (or 00.png, 01.png, …)")
    return found


def _toml_vec(v) -> str:
    return "[" + ", ".join(f"{float(x):.9g}" for x in v) + "]"


def import_capture(
    src, out, *, layout: str = "rectified", encoding: str = "srgb", units: str = "cm", name=None
) -> PhotoCapture:
    """Write a ``method = "multiview"`` capture folder ``out`` from a dataset folder ``src`` and load it.

    Parameters
    ----------
    src
        The dataset folder (layout above).
    out
        The capture folder to write: must not exist or be empty. Nothing is
        written when ``src`` is refused.
    layout
        ``"rectified"`` (the only layout so far).
    encoding
        The images' encoding: ``"srgb"`` (default), ``"gamma2.2"`` (MaterialGAN) or ``"linear"``.
    units
        The length unit of the text files: ``"cm"`` (default), ``"mm"`` or ``"m"``.
    name
        The capture's name (default: ``out``'s folder name).

    Returns
    -------
    PhotoCapture
        The capture as :func:`wardjax.load_capture` reads it from ``out``.

    Raises
    ------
    CaptureError
        One line naming the dataset file and the line or value at fault.
    """
    from ._load import load_capture

    src, out = Path(src), Path(out)
    if layout not in LAYOUTS:
        raise ValueError(f"layout={layout!r}: expected one of {', '.join(LAYOUTS)}")
    if encoding not in _ENCODINGS:
        raise ValueError(f"encoding={encoding!r}: expected one of {', '.join(_ENCODINGS)}")
    if units not in MM_PER_UNIT:
        raise ValueError(f"units={units!r}: expected one of {', '.join(MM_PER_UNIT)}")
    if not src.is_dir():
        raise CaptureError(str(src), None, "not a folder")
    if out.is_dir():
        recover_commit(out)  # an import killed while it moved its files in: they go, and it runs again
    if out.exists() and (not out.is_dir() or any(out.iterdir())):
        raise CaptureError(str(out), None, "exists and is not an empty folder; choose another --out")
    images = _images(src)
    k = len(images)
    for fname in ("camera_pos.txt", "light_power.txt", "image_size.txt"):
        if not (src / fname).is_file():
            raise CaptureError(fname, None, f"missing from {src} (the rectified layout needs it)")
    mm = MM_PER_UNIT[units]
    cams = np.asarray(_numbers(src / "camera_pos.txt", 3)) * mm
    lights = np.asarray(_numbers(src / "light_pos.txt", 3)) * mm if (src / "light_pos.txt").is_file() else cams
    for fname, arr in (("camera_pos.txt", cams), ("light_pos.txt", lights)):
        if len(arr) != k:
            raise CaptureError(fname, None, f"has {len(arr)} lines but {src} holds {k} images (one line each)")
    power = [v for row in _numbers(src / "light_power.txt", None) for v in row]
    if len(power) not in (1, 3) or min(power) <= 0:
        raise CaptureError("light_power.txt", None, f"expected one positive number or three (r g b), got {power}")
    size = [v for row in _numbers(src / "image_size.txt", None) for v in row]
    if len(size) != 1 or size[0] <= 0:
        raise CaptureError("image_size.txt", None, f"expected one positive number (the width), got {size}")
    p_mm = [p * mm**2 for p in power]  # v = P f cos / d²: P scales with the square of the length unit
    lines = [
        'method = "multiview"',
        f"name = {json.dumps(name or out.resolve().name)}",
        f'encoding = "{encoding}"',
        f"width = {size[0] * mm:.9g}  # mm: physical width of the rectified images (image_size.txt)",
        "",
        "[light]",
        f"power = {_toml_vec(p_mm) if len(p_mm) == 3 else f'{p_mm[0]:.9g}'}  # light_power.txt, distances in mm",
    ]
    for i, img in enumerate(images):
        lines += ["", "[[photos]]", f'file = "{img.name}"', f"camera = {_toml_vec(cams[i])}"]
        lines.append(f"light = {_toml_vec(lights[i])}")
    staging = Path(tempfile.mkdtemp(prefix=f".{out.name}.", suffix=".import", dir=out.parent.resolve()))
    try:
        for img in images:
            write_bytes_atomic(staging / img.name, img.read_bytes())
        write_bytes_atomic(staging / CAPTURE_FILE, ("\n".join(lines) + "\n").encode())
        load_capture(staging)  # refused here: nothing is left at ``out``
        commit_folder(staging, out, last=CAPTURE_FILE)
    finally:
        if staging.exists():
            shutil.rmtree(staging)
    cap = load_capture(out)
    assert isinstance(cap, PhotoCapture)  # capture.toml above says method = "multiview"
    return cap
