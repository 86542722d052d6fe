"""The one set of rules every entry point applies: CLI options, ``capture.toml`` and the Python API.

Each rule raises :class:`RuleError` naming the field and what is allowed; the
caller turns the field into its own spelling (``--rho-d`` on the command line,
``capture.toml: rig.lamp`` in a capture). The ranges:

* Ward parameters (image-based paper, eq. 1): ρd in [0, 1] with 1 or 3
  channels, ρs ≥ 0 with 1 or 3 channels, ρd + ρs ≤ 1 per channel (energy
  conservation of the normalised lobe), αx, αy > 0; all finite.
* Geometry: positions finite and within :data:`MAX_DISTANCE_MM` of the
  sample; a focal length in pixels that gives a horizontal field of view
  between :data:`MIN_FOV_DEG` and :data:`MAX_FOV_DEG`, ``f = (w / 2) / tan(fov / 2)``.
* Images: lit and dark of one size, channel count, bit depth and kind of file;
  a lit image that is not black everywhere and not one value everywhere.
* A smartphone region that is not mostly black or saturated in any channel,
  so that ρd is measured, not the clip level.
"""

from __future__ import annotations

import math
import unicodedata
from collections.abc import Sequence

import numpy as np

__all__ = [
    "MAX_DISTANCE_MM",
    "MAX_FOV_DEG",
    "MAX_CLIPPED_FRACTION",
    "MIN_FOV_DEG",
    "RuleError",
    "check_focal_px",
    "check_image_pair",
    "check_lit_exposure",
    "check_photo_region",
    "check_position",
    "check_rho_d_map",
    "check_ward_params",
    "one_line",
]

# The farthest a lamp, camera or target may sit from the sample (100 m): beyond
# it the scene is not a desk-top capture and the numbers only lose precision.
MAX_DISTANCE_MM = 1.0e5
# Horizontal fields of view a real lens covers: a 1° super-telephoto to a 170° fisheye.
MIN_FOV_DEG = 1.0
MAX_FOV_DEG = 170.0
# More than this fraction of pixels at the clip level in a channel: the value measured is the clip, not the surface.
MAX_CLIPPED_FRACTION = 0.5


def one_line(text: str) -> str:
    """``text`` with every line break and control character written as its escape (``\\n``, ``\\x00``).

    A refusal is one line; a file or field name read from the input (a TOML key,
    an image path) may hold any character, and is shown escaped rather than
    breaking the line.
    """
    if text.isprintable():
        return text
    return "".join(
        ch.encode("unicode_escape").decode("ascii") if unicodedata.category(ch) in ("Cc", "Zl", "Zp") else ch
        for ch in text
    )


class RuleError(ValueError):
    """An input outside its allowed range: ``field`` and a ``message`` saying what is allowed, on one line."""

    def __init__(self, field: str, message: str):
        self.field = one_line(field)
        self.message = one_line(message)
        super().__init__(f"{self.field}: {self.message}")


def _finite_values(field: str, value, channels: tuple[int, ...]) -> np.ndarray:
    if isinstance(value, bool) or (isinstance(value, Sequence) and any(isinstance(v, bool) for v in value)):
        raise RuleError(field, f"expected a number, got the boolean {value!r}")
    try:
        a = np.asarray(value, dtype=np.float64).reshape(-1)
    except (TypeError, ValueError):
        raise RuleError(field, f"expected a number or {max(channels)} numbers, got {value!r}") from None
    if a.size not in channels:
        want = " or ".join(str(c) for c in channels)
        raise RuleError(field, f"expected {want} value(s), got {a.size}")
    if not np.all(np.isfinite(a)):
        raise RuleError(field, f"must be finite, got {a.tolist()}")
    return a


def check_ward_params(rho_d, rho_s, alpha_x, alpha_y) -> None:
    """Refuse Ward parameters outside the model's physical range.

    Parameters
    ----------
    rho_d
        Diffuse reflectance, 1 value (grey) or 3 (RGB), each in [0, 1].
    rho_s
        Specular reflectance, 1 or 3 values, each ≥ 0.
    alpha_x, alpha_y
        Slope standard deviations, > 0.

    Raises
    ------
    RuleError
        Naming ``rho_d``, ``rho_s``, ``alpha_x`` or ``alpha_y`` and the allowed range. The sum
        ``ρd + ρs ≤ 1`` per channel (energy conservation, image-based paper eq. 1) is reported on ``rho_s``.
    """
    d = _finite_values("rho_d", rho_d, (1, 3))
    if np.any(d < 0) or np.any(d > 1):
        raise RuleError("rho_d", f"each value must lie in [0, 1], got {d.tolist()}")
    s = _finite_values("rho_s", rho_s, (1, 3))
    if np.any(s < 0):
        raise RuleError("rho_s", f"must be ≥ 0, got {s.tolist()}")
    total = d + s if d.size == s.size or 1 in (d.size, s.size) else None
    if total is not None and np.any(total > 1 + 1e-12):
        raise RuleError(
            "rho_s", f"rho_d + rho_s must be ≤ 1 in every channel (energy conservation), got {total.tolist()}"
        )
    for name, v in (("alpha_x", alpha_x), ("alpha_y", alpha_y)):
        a = _finite_values(name, v, (1,))
        if a[0] <= 0:
            raise RuleError(name, f"must be > 0 (a slope standard deviation), got {a[0]}")


def check_position(field: str, xyz) -> None:
    """Refuse a position (mm) that is not finite or lies farther than :data:`MAX_DISTANCE_MM` from the sample."""
    a = _finite_values(field, xyz, (3,))
    dist = math.hypot(*a)  # no overflow (nor warning) for coordinates near the largest float
    if dist > MAX_DISTANCE_MM:
        raise RuleError(field, f"{a.tolist()} lies {dist:.3g} mm from the sample; at most {MAX_DISTANCE_MM:.0e} mm")


def check_focal_px(field: str, focal_px: float, extent_px: int) -> None:
    """Refuse a focal length (pixels) no lens has for an image ``extent_px`` wide.

    The field of view ``2 atan(extent / (2 f))`` must lie in [:data:`MIN_FOV_DEG`, :data:`MAX_FOV_DEG`].
    """
    lo = extent_px / 2 / math.tan(math.radians(MAX_FOV_DEG) / 2)
    hi = extent_px / 2 / math.tan(math.radians(MIN_FOV_DEG) / 2)
    if not (lo <= focal_px <= hi):
        raise RuleError(
            field,
            f"{focal_px:g} px gives a field of view outside {MIN_FOV_DEG:g}°–{MAX_FOV_DEG:g}° for an image "
            f"{extent_px} px across; expected {lo:.3g} to {hi:.4g} px",
        )


_KINDS = {".jpg": "JPEG", ".jpeg": "JPEG"}


def _kind(name: str) -> str:
    suffix = "." + name.rsplit(".", 1)[-1].lower() if "." in name else ""
    if suffix in (".png", ".tif", ".tiff"):
        return "lossless"
    if suffix in _KINDS:
        return _KINDS[suffix]
    return "raw"


def check_image_pair(lit_name: str, lit: tuple[int, int, int], dark_name: str, dark: tuple[int, int, int]) -> None:
    """Refuse a lit and a dark image that were not taken alike: size, channel count, kind of file.

    ``lit`` and ``dark`` are ``(height, width, channels as stored)``; the bit depth of both is
    checked against ``images.bit_depth`` as each is read.

    Raises
    ------
    RuleError
        With ``field`` the dark image's file name.
    """
    if lit[:2] != dark[:2]:
        raise RuleError(dark_name, f"is {dark[1]}×{dark[0]} pixels but {lit_name} is {lit[1]}×{lit[0]}")
    if lit[2] != dark[2]:
        raise RuleError(dark_name, f"has {dark[2]} channel(s) but {lit_name} has {lit[2]}")
    if _kind(lit_name) != _kind(dark_name):
        raise RuleError(dark_name, f"is a {_kind(dark_name)} file but {lit_name} is {_kind(lit_name)}; take both alike")


def check_lit_exposure(name: str, codes: np.ndarray, linear_max: float, floor: float) -> None:
    """Refuse a lit image with nothing to measure: black everywhere (below ``floor``) or one value everywhere.

    ``codes`` is the image's codes, or only its smallest and largest (what
    :func:`~wardjax.load_capture` gathers band by band); ``linear_max`` the
    brightest linear value.
    """
    if linear_max <= floor:
        raise RuleError(
            name, f"is black: its brightest value {linear_max:.3g} is at or below the noise floor {floor:g}"
        )
    if codes.size and codes.min() == codes.max():
        raise RuleError(name, f"holds the single value {codes.flat[0]} everywhere; nothing to measure")


def check_photo_region(name: str, values: np.ndarray, top: float) -> None:
    """Refuse a photo region that is mostly black (≤ 0) or clipped (≥ ``top``) in some channel.

    ``values`` are the region's codes (``top`` the largest code) or floats (``top`` 1). Such a
    channel's ρd would be exactly 0 or 1 with a spread of 0: the clip level, not a measurement.
    """
    for c, cname in enumerate("RGB"[: values.shape[-1]]):
        v = values[..., c]
        for frac, what in (
            (float(np.mean(v <= 0)), "black (0)"),
            (float(np.mean(v >= top)), f"saturated ({top:g})"),
        ):
            if frac > MAX_CLIPPED_FRACTION:
                raise RuleError(
                    name,
                    f"{frac:.0%} of the region's {cname} values are {what}; ρd would be the clip level, "
                    "not a measurement: retake the photo with another exposure",
                )


def check_rho_d_map(name: str, a: np.ndarray) -> None:
    """Refuse a ρd map that holds integer codes or values far outside [0, 1] (not linear ρd)."""
    if np.issubdtype(a.dtype, np.integer) or a.dtype == np.bool_:
        bits = 8 * a.dtype.itemsize
        article = "an" if bits == 8 else "a"
        raise RuleError(
            name,
            f"holds {a.dtype} codes, not linear ρd; convert it first "
            f"(decode to linear light and divide by {(1 << bits) - 1} for {article} {bits}-bit image) "
            "and save it as a float .tif or .npy",
        )
    finite = a[np.isfinite(a)]
    if finite.size and (finite.min() < -0.5 or finite.max() > 1.5):
        raise RuleError(
            name,
            f"values run from {finite.min():.3g} to {finite.max():.3g}, far outside ρd's [0, 1]; "
            "scale it to linear reflectance first",
        )
