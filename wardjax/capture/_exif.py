"""EXIF of a photograph: exposure time, aperture, ISO and focal length, read with Pillow.

Pillow's :meth:`PIL.Image.Image.getexif` reads the EXIF block of JPEG, PNG
(``eXIf`` chunk), TIFF and WebP files; the exposure settings sit in its Exif
sub-IFD (tag ``0x8769``). A raw file's EXIF is not read (its settings are
given in ``capture.toml``).

The relative exposure of a photo puts photos taken with different settings
on one scale (APEX: the sensor's exposure H ∝ t / N², the gain ∝ ISO)::

    exposure = t · (ISO / 100) / N²          t in s, N the f-number

Only ratios of exposures matter: a dark frame at a shorter exposure is
scaled by ``exposure_lit / exposure_dark`` before it is subtracted, and a
reflectance standard photographed apart calibrates the light power per
unit of this exposure.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import NamedTuple

__all__ = ["Exif", "EXPOSURE_TOLERANCE", "read_exif", "relative_exposure"]

# Relative difference within which a value in capture.toml and the photo's EXIF agree (EXIF rationals are rounded).
EXPOSURE_TOLERANCE = 0.02

_EXIF_IFD = 0x8769
_TAGS = {
    "exposure_time": 0x829A,  # ExposureTime, s
    "f_number": 0x829D,  # FNumber
    "iso": 0x8827,  # ISOSpeedRatings / PhotographicSensitivity
    "focal_mm": 0x920A,  # FocalLength, mm
    "focal_35mm": 0xA405,  # FocalLengthIn35mmFilm, mm
}


class Exif(NamedTuple):
    """The exposure settings of a photo as its EXIF gives them; ``None`` where absent.

    Attributes
    ----------
    exposure_time
        Shutter time, s.
    f_number
        Aperture, N.
    iso
        Sensitivity (ISO speed).
    focal_mm
        Lens focal length, mm.
    focal_35mm
        Focal length of the lens with the same field of view on 35 mm film (36 × 24 mm, diagonal 43.27 mm).
    """

    exposure_time: float | None = None
    f_number: float | None = None
    iso: float | None = None
    focal_mm: float | None = None
    focal_35mm: float | None = None


def _number(v) -> float | None:
    if isinstance(v, (tuple, list)):
        v = v[0] if v else None
    try:
        x = float(v)  # pyright: ignore[reportArgumentType]
    except (TypeError, ValueError, ZeroDivisionError):
        return None
    return x if math.isfinite(x) and x > 0 else None


def read_exif(path) -> Exif:
    """The :class:`Exif` of the image file at ``path`` (all ``None`` for a file without EXIF or a raw file)."""
    from PIL import Image, UnidentifiedImageError

    try:
        with Image.open(Path(path)) as im:
            exif = im.getexif()
            sub = exif.get_ifd(_EXIF_IFD)
    except (UnidentifiedImageError, OSError, ValueError, SyntaxError):
        return Exif()
    values = {k: _number(sub.get(tag, exif.get(tag))) for k, tag in _TAGS.items()}
    return Exif(**values)


def relative_exposure(exposure_time: float, f_number: float, iso: float) -> float:
    """``t · (ISO / 100) / N²``: the photo's exposure on the scale that all photos of a capture share."""
    return exposure_time * (iso / 100.0) / f_number**2
