"""The one set of rules every entry point applies: CLI options, ``capture.toml``, files read and the Python API.

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
  a lit image that is not black everywhere, not one value everywhere, and a
  picture rather than random noise: neighbouring pixels of a photographed scene
  are correlated (lag-1 correlation ≥ :data:`MIN_NEIGHBOUR_CORRELATION`).
* A probe that is seen and measured: some pixel sees it, at most
  :data:`MAX_CLIPPED_FRACTION` of its pixels are clipped, and some pixel's lamp
  signal clears the noise floor with its mirror point on the standard.
* A smartphone region that is not mostly black or saturated in any channel,
  so that ρd is measured, not the clip level, and that holds at least
  :data:`MIN_REGION_PIXELS` pixels, so that its σ can be estimated.
* ρd maps: real floats, nearly all within [0, 1] up to :data:`RHO_NOISE`;
  with a specular reflectance, ρd + ρs ≤ 1 for the map's median.
* Bounded work: every size or count that sets the work has a limit checked
  before the work starts (:data:`LIMITS`); memory is estimated before an
  array is allocated (:func:`check_memory`).
* A colour correction whose held-out ΔE*ab exceeds
  :data:`MAX_HELD_OUT_DELTA_E` did not work and is refused.
"""

from __future__ import annotations

import math
import os
import unicodedata
from collections.abc import Sequence
from pathlib import Path

import numpy as np

__all__ = [
    "LIMITS",
    "MAX_DISTANCE_MM",
    "MAX_HELD_OUT_DELTA_E",
    "MIN_REGION_PIXELS",
    "RHO_NOISE",
    "MAX_FOV_DEG",
    "MAX_CLIPPED_FRACTION",
    "MIN_FOV_DEG",
    "MIN_NEIGHBOUR_CORRELATION",
    "RuleError",
    "check_camera_correction",
    "check_count",
    "check_focal_px",
    "check_memory",
    "check_path_name",
    "check_rho_sum",
    "check_ward_arrays",
    "check_image_pair",
    "check_lit_exposure",
    "check_lit_picture",
    "check_photo_region",
    "check_position",
    "check_rho_d_map",
    "check_ward_params",
    "one_line",
    "shorten",
]

# The farthest a lamp, camera or target may sit from the sample (100 m): beyond
# it the scene is not a desk-top capture and the numbers only lose precision.
MAX_DISTANCE_MM = 1.0e5
# Horizontal fields of view a real lens covers: a 1° super-telephoto to a 170° fisheye.
MIN_FOV_DEG = 1.0
MAX_FOV_DEG = 170.0
# More than this fraction of pixels at the clip level in a channel: the value measured is the clip, not the surface.
MAX_CLIPPED_FRACTION = 0.5
# Below this lag-1 correlation between neighbouring pixels a lit image is noise, not a photographed scene: a
# scene's pixels share its surfaces and light (r ≈ 0.9 and more), independent random codes give r ≈ 0 (± 0.01).
MIN_NEIGHBOUR_CORRELATION = 0.2
# A photo region smaller than this (4 × 4 pixels) leaves its σ unestimated: ρd "± 0" is not a measurement.
MIN_REGION_PIXELS = 16
# How far outside [0, 1] a measured ρd may stray by noise alone (a pixel of a ρd map, a region mean).
RHO_NOISE = 0.05
# The fraction of a ρd map's pixels that may stray farther than RHO_NOISE (outliers, specks).
MAX_STRAY_FRACTION = 0.01
# A colour correction whose leave-one-out ΔE*ab (the median over patches) exceeds this did not work:
# a good chart fit holds out at 2–5; a uniform grey photo or a reversed patch layout at 40 and more.
MAX_HELD_OUT_DELTA_E = 10.0
# The longest line a refusal prints; a value echoed from the input is cut to fit.
MAX_MESSAGE_CHARS = 400

# Limits on every size or count that sets the work, checked before the work starts.
LIMITS: dict[str, int | float] = {
    # pixels of one image or map (a 16k × 16k image): larger is refused before it is decoded
    "pixels": 1 << 28,
    # bytes one array may take; also never more than the memory available
    "bytes": 1 << 34,
    # Gaussian σ (pixels) of a smoothing kernel: its width (8 σ + 1) sets the work per pixel
    "kernel_px": 64,
    # entries of a list read from a file (observers' thresholds, patches)
    "list": 1000,
    # bytes of one path component (the file systems' NAME_MAX)
    "name_bytes": 255,
}


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


def shorten(text: str, limit: int = MAX_MESSAGE_CHARS) -> str:
    """``text`` cut to at most ``limit`` characters, the cut marked with its length (a huge value echoed)."""
    if len(text) <= limit:
        return text
    return f"{text[: limit - 40]}… ({len(text):,} characters)"


class RuleError(ValueError):
    """An input outside its allowed range: ``field`` and a ``message`` saying what is allowed, on one line."""

    def __init__(self, field: str, message: str):
        self.field = shorten(one_line(field), 200)
        self.message = shorten(one_line(message))
        super().__init__(f"{self.field}: {self.message}")


def _finite_values(field: str, value, channels: tuple[int, ...]) -> np.ndarray:
    if isinstance(value, bool) or (isinstance(value, Sequence) and any(isinstance(v, bool) for v in value)):
        raise RuleError(field, f"expected a number, got the boolean {value!r}")
    try:
        a = np.asarray(value, dtype=np.float64).reshape(-1)
    except (TypeError, ValueError):
        got = shorten(repr(value), 80)
        raise RuleError(field, f"expected a number or {max(channels)} numbers, got {got}") from None
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


def check_lit_picture(name: str, correlation: float) -> None:
    """Refuse a lit image whose neighbouring pixels are uncorrelated: random noise, not a photograph of the rig.

    ``correlation`` is the larger of the horizontal and vertical lag-1 correlations of the image's
    codes (Pearson, pooled over the channels; NaN where the rows read hold one value). A photograph
    shares each surface and its lighting between neighbouring pixels; independent codes do not, and
    whatever a fit or a discovery would report from them (a ρd above 1, an "effect") is made of noise.
    """
    if math.isfinite(correlation) and correlation < MIN_NEIGHBOUR_CORRELATION:
        raise RuleError(
            name,
            f"holds no picture: neighbouring pixels are uncorrelated (r = {correlation:.2f}, a photograph gives "
            f"{MIN_NEIGHBOUR_CORRELATION:g} and more), as in random noise; nothing of the probe or the standard "
            "to measure",
        )


def check_photo_region(name: str, values: np.ndarray, top: float) -> None:
    """Refuse a photo region that is mostly black (≤ 0) or clipped (≥ ``top``) in some channel.

    ``values`` are the region's codes (``top`` the largest code) or floats (``top`` 1). Such a
    channel's ρd would be exactly 0 or 1 with a spread of 0: the clip level, not a measurement.
    A region of fewer than :data:`MIN_REGION_PIXELS` pixels is refused too: its σ cannot be estimated.
    """
    n = math.prod(values.shape[:-1])
    if n < MIN_REGION_PIXELS:
        raise RuleError(
            name,
            f"the region holds {n} pixel(s); at least {MIN_REGION_PIXELS} (4 × 4) are needed to measure ρd "
            "and estimate its σ",
        )
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
    """Refuse a ρd map that is not linear reflectance: integer codes, complex values, no finite value,
    or more than :data:`MAX_STRAY_FRACTION` of its values farther than :data:`RHO_NOISE` outside [0, 1]."""
    if np.issubdtype(a.dtype, np.integer) or a.dtype == np.bool_:
        bits = 8 * a.dtype.itemsize
        article = "an" if bits == 8 else "a"
        raise RuleError(
            name,
            f"holds {a.dtype} codes, not linear ρd; convert it first "
            f"(decode to linear light and divide by {(1 << bits) - 1} for {article} {bits}-bit image) "
            "and save it as a float .tif or .npy",
        )
    if np.iscomplexobj(a) or not np.issubdtype(a.dtype, np.floating):
        raise RuleError(name, f"holds {a.dtype} values; ρd is a real number, save it as float32 or float64")
    finite = a[np.isfinite(a)]
    if finite.size == 0:
        raise RuleError(name, "holds no finite value (all NaN or infinite): nothing to analyse")
    lo, hi = float(finite.min()), float(finite.max())
    if lo < -0.5 or hi > 1.5:
        raise RuleError(
            name,
            f"values run from {lo:.3g} to {hi:.3g}, far outside ρd's [0, 1]; scale it to linear reflectance first",
        )
    stray = float(np.mean((finite < -RHO_NOISE) | (finite > 1 + RHO_NOISE)))
    if stray > MAX_STRAY_FRACTION:
        raise RuleError(
            name,
            f"{stray:.0%} of its values lie more than {RHO_NOISE:g} outside ρd's [0, 1] (they run from "
            f"{lo:.3g} to {hi:.3g}); a reflectance map within noise of [0, 1] was expected",
        )


def _first_bad(values: np.ndarray | np.generic, bad: np.ndarray | np.generic) -> str:
    """``"got v (k of n values)"``: the first of ``values`` that is ``bad``, and how many are."""
    values, bad = np.asarray(values), np.asarray(bad)
    first = float(values[bad].reshape(-1)[0])
    if values.size == 1:
        return f"got {first:g}"
    return f"got {first:g} ({int(np.count_nonzero(bad))} of {values.size} values)"


def check_ward_arrays(rho_d, rho_s, alpha_x, alpha_y) -> None:
    """:func:`check_ward_params` for arrays of any batch shape (the rule :class:`~wardjax.WardParams` applies).

    Field by field, in the order of :func:`check_ward_params`: ρd finite and in [0, 1]; ρs finite
    and ≥ 0, and ρd + ρs ≤ 1 per channel (broadcast over the batch where the shapes allow); αx,
    αy finite and > 0. The message counts the values outside and shows the first.
    """

    def real(name: str, v) -> np.ndarray:
        a = np.asarray(v)
        if np.iscomplexobj(a) or a.dtype == np.bool_ or not np.issubdtype(a.dtype, np.number):
            raise RuleError(name, f"expected real numbers, got {a.dtype}")
        a = a.astype(np.float64, copy=False)
        if (bad := ~np.isfinite(a)).any():
            raise RuleError(name, f"must be finite: {_first_bad(a, bad)}")
        return a

    d = real("rho_d", rho_d)
    if (bad := (d < 0) | (d > 1)).any():
        raise RuleError("rho_d", f"must lie in [0, 1]: {_first_bad(d, bad)}")
    s = real("rho_s", rho_s)
    if (bad := s < 0).any():
        raise RuleError("rho_s", f"must be ≥ 0: {_first_bad(s, bad)}")
    s_rgb = s[..., None] if s.ndim < d.ndim else s
    try:
        total = d + s_rgb
    except ValueError:  # shapes that do not broadcast: the model will say so where it combines them
        total = None
    if total is not None and (bad := total > 1 + 1e-12).any():
        raise RuleError(
            "rho_s", f"rho_d + rho_s must be ≤ 1 in every channel (energy conservation): {_first_bad(total, bad)}"
        )
    for name, v in (("alpha_x", alpha_x), ("alpha_y", alpha_y)):
        a = real(name, v)
        if (bad := a <= 0).any():
            raise RuleError(name, f"must be > 0 (a slope standard deviation): {_first_bad(a, bad)}")


def check_rho_sum(name: str, rho_d: np.ndarray, rho_s) -> None:
    """Refuse a ρs that, with the median ρd of a map, breaks energy conservation: ``median(ρd) + ρs ≤ 1`` per channel.

    ``rho_d`` is ``(H, W)`` or ``(H, W, C)`` (NaN = no data); ``rho_s`` a scalar or one value per
    channel. The median of many pixels carries little noise, so the sum is held to 1 exactly.
    """
    a = np.asarray(rho_d, np.float64)
    flat = a.reshape(-1, a.shape[-1]) if a.ndim == 3 else a.reshape(-1, 1)
    ok = np.isfinite(flat).all(axis=1)
    if not ok.any():
        return
    med = np.median(flat[ok], axis=0)
    rs = np.asarray(rho_s, np.float64).reshape(-1)
    if np.any(med + rs > 1):
        rs_text = f"{rs[0]:g}" if rs.size == 1 else str(np.round(rs, 3).tolist())
        raise RuleError(
            name,
            f"median ρd {np.round(med, 3).tolist()} + ρs {rs_text} exceeds 1 (energy conservation): "
            f"ρs may be at most {max(0.0, 1 - float(med.max())):.3g} for this map",
        )


def check_count(field: str, n: int, limit_name: str, what: str) -> None:
    """Refuse a size or count ``n`` above :data:`LIMITS` ``[limit_name]``, before the work it sets starts."""
    limit = LIMITS[limit_name]
    if not n <= limit:
        raise RuleError(field, f"{n:,} {what} is more than the {limit:,} allowed")


def _available_bytes() -> int | None:
    """Memory this process may still allocate, or ``None`` where the system does not say."""
    try:
        return int(os.sysconf("SC_AVPHYS_PAGES")) * int(os.sysconf("SC_PAGE_SIZE"))
    except (ValueError, OSError, AttributeError):
        return None


def check_memory(field: str, shape: Sequence[int], itemsize: int, copies: int = 1) -> None:
    """Refuse an array of ``shape`` (× ``copies`` while it is worked on) that would not fit in memory.

    The estimate ``prod(shape) · itemsize · copies`` is checked against :data:`LIMITS` ``["bytes"]`` and
    the memory available, before anything is allocated.
    """
    n = math.prod(int(k) for k in shape)
    need = n * int(itemsize) * int(copies)
    avail = _available_bytes()
    cap = LIMITS["bytes"] if avail is None else min(LIMITS["bytes"], avail)
    if need > cap:
        dims = "×".join(str(int(k)) for k in shape)
        raise RuleError(
            field, f"an array of {dims} values needs {need / 2**30:,.3g} GiB; {cap / 2**30:,.3g} GiB is available"
        )


def check_path_name(path) -> None:
    """Refuse a path with a component longer than the file systems allow (:data:`LIMITS` ``["name_bytes"]``)."""
    for part in Path(path).parts:
        size = len(os.fsencode(part))
        if size > LIMITS["name_bytes"]:
            raise RuleError(
                shorten(str(path), 120),
                f"a path component is {size} bytes long; file systems allow at most {LIMITS['name_bytes']}",
            )


def check_camera_correction(name: str, held_out_delta_E) -> None:
    """Refuse a colour correction whose median leave-one-out ΔE*ab says it failed (> :data:`MAX_HELD_OUT_DELTA_E`).

    A correction fitted to a uniform grey photo or to patches read in the wrong order reproduces its
    own patches yet predicts a held-out patch no better than chance; ``held_out_delta_E`` (N,) is
    :func:`~wardjax.smartphone.colorchecker_held_out_delta_E`, NaN for unusable patches.
    """
    d = np.asarray(held_out_delta_E, np.float64)
    d = d[np.isfinite(d)]
    if d.size == 0:
        raise RuleError(name, "no patch could be held out: the correction's error cannot be estimated")
    med = float(np.median(d))
    if med > MAX_HELD_OUT_DELTA_E:
        raise RuleError(
            name,
            f"the colour correction failed: held-out ΔE*ab {med:.3g} (median over {d.size} patches) exceeds "
            f"{MAX_HELD_OUT_DELTA_E:g}; check the chart photo and the patch layout",
        )
