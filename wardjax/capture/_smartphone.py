"""``method = "smartphone"`` capture folders: a photo, a region, threshold judgements.

A smartphone capture folder holds::

    captures/red-gloss/
      capture.toml
      photo.jpg           white-balanced, off-specular sRGB photo of the surface

with ``capture.toml``::

    method = "smartphone"
    name = "red-gloss"               # optional; default the folder name

    [photo]
    file = "photo.jpg"               # PNG/JPEG/TIFF, 8 or 16 bit RGB
    region = [120, 360, 200, 440]    # [y0, y1, x0, x1] in pixels, over the surface
    decoding = "gamma2.2"            # "gamma2.2" (the paper) or "srgb"

    [thresholds]                     # one of the two forms
    ppb = [18, 17, 19]               # each observer's whole-pixel threshold (pixels per bar)
    # ppb_mean = 17.3                # or a published mean …
    # n_observers = 3                # … over this many observers

    [setup]                          # optional; names in calibration/smartphone_setup.toml
    display = "iphone5s"
    viewing = "paper"

    [specular]                       # optional
    n = 1.5                          # refractive index: ρs from Fresnel (0.050 for 1.5)
    n_range = [1.4, 1.7]             # plausible range, quoted as ±2σ of ρs

    [fit]                            # optional
    seed = 0                         # sampler seed

    [color_correction]               # optional: a ColorChecker 24 in the photo corrects the camera
    first_center = [166.0, 169.5]    # (y, x) pixel centre of the grid's top-left patch
    pitch = [21.2, 20.8]             # (dy, dx) between patch centres, pixels
    grid = [6, 4]                    # rows, columns as the chart appears in the photo
    half_size = 5                    # each patch box is (2·half_size + 1)² pixels
    order = [18, 12, 6, 0, ...]      # chart index (0 dark skin … 23 black) of each grid cell, row-major
    method = "Finlayson 2015"        # or "Cheung 2004", "Vandermonde"
    degree = 2                       # root-polynomial / Vandermonde degree
    terms = 3                        # Cheung 2004 terms

With ``[color_correction]`` ρd is read through the chart's correction and its
σ carries the correction's leave-one-out colour error
(``wardjax.smartphone.chart_correction``); a patch under the surface's
region is left out of the fit.

The method: ρd from the photo (linearise, Bradford D65 → E, robust region
mean), ρs from Fresnel, α from the threshold PPBs through the calibrated
PPB → α model with an emcee posterior (:func:`wardjax.fit_smartphone`).
``wardjax fit`` (:func:`wardjax.run`) writes the same ``params.json`` (schema ``wardjax.params/1``)
and ``material.rad`` as for the image-based method.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Annotated, Literal

import numpy as np
import pydantic
from pydantic import BaseModel, ConfigDict, Field, Strict

from .._files import file_problem, read_image, sha256
from .._rules import LIMITS, RuleError, check_photo_region
from ._errors import CAPTURE_FILE, CaptureError, pydantic_error
from ._setup import load_display, load_viewing

__all__ = [
    "SmartphoneCapture",
    "SmartphoneCaptureFile",
    "grid_boxes",
    "load_smartphone_capture",
    "parse_smartphone_file",
]


class _Section(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


# Strict: a TOML boolean is not a number (lax pydantic would read ``true`` as 1); integers pass as floats.
_Float = Annotated[float, Strict(), Field(allow_inf_nan=False)]
_Pixel = Annotated[int, Strict(), Field(ge=0)]


class PhotoSection(_Section):
    file: str = Field(min_length=1)
    region: tuple[_Pixel, _Pixel, _Pixel, _Pixel]
    decoding: Literal["gamma2.2", "srgb"] = "gamma2.2"


class ThresholdsSection(_Section):
    # at most LIMITS["list"] observers: each one's threshold is a term of the posterior's likelihood
    ppb: list[Annotated[int, Field(ge=1, strict=True)]] | None = Field(
        default=None, min_length=1, max_length=int(LIMITS["list"])
    )
    ppb_mean: Annotated[_Float, Field(gt=0)] | None = None
    n_observers: Annotated[int, Field(ge=1, le=int(LIMITS["list"]), strict=True)] | None = None

    @pydantic.model_validator(mode="after")
    def _one_form(self):
        if (self.ppb is None) == (self.ppb_mean is None):
            raise ValueError(
                "give either ppb = [...] (each observer) or ppb_mean with n_observers, not both or neither"
            )
        if self.ppb_mean is not None and self.n_observers is None:
            raise ValueError("ppb_mean needs n_observers")
        return self


class SetupSection(_Section):
    display: str = "iphone5s"
    viewing: str = "paper"


class SpecularSection(_Section):
    n: Annotated[_Float, Field(gt=1.0, lt=4.0)] = 1.5
    n_range: tuple[Annotated[_Float, Field(gt=1.0, lt=4.0)], Annotated[_Float, Field(gt=1.0, lt=4.0)]] = (1.4, 1.7)


class SmartphoneFitSection(_Section):
    seed: Annotated[int, Strict()] = 0


class ColorCorrectionSection(_Section):
    first_center: tuple[_Float, _Float]
    pitch: tuple[_Float, _Float]
    grid: tuple[Annotated[int, Field(ge=1, strict=True)], Annotated[int, Field(ge=1, strict=True)]]
    half_size: Annotated[int, Field(ge=0, strict=True)]
    order: list[Annotated[int, Field(ge=0, le=23, strict=True)]] = Field(min_length=24, max_length=24)
    method: Literal["Finlayson 2015", "Cheung 2004", "Vandermonde"] = "Finlayson 2015"
    degree: Annotated[int, Field(ge=1, le=4, strict=True)] = 2
    terms: Annotated[int, Field(ge=3, le=22, strict=True)] = 3

    def regions(self) -> list[tuple[int, int, int, int]]:
        """The 24 patch boxes ``(y0, y1, x0, x1)`` in chart order."""
        return grid_boxes(self.first_center, self.pitch, self.grid, self.half_size, self.order)


def grid_boxes(first_center, pitch, grid, half_size: int, order) -> list[tuple[int, int, int, int]]:
    """Boxes ``(yc − h, yc + h + 1, xc − h, xc + h + 1)`` around a regular grid of centres, in ``order``.

    Cell ``(r, c)`` of the ``grid`` (row-major in the image) is centred at
    ``first_center + (r·dy, c·dx)`` and is box number ``order[r·cols + c]``.
    """
    cols = grid[1]
    boxes: list = [None] * len(order)
    for cell, idx in enumerate(order):
        r, c = divmod(cell, cols)
        yc = int(round(first_center[0] + r * pitch[0]))
        xc = int(round(first_center[1] + c * pitch[1]))
        boxes[idx] = (yc - half_size, yc + half_size + 1, xc - half_size, xc + half_size + 1)
    return boxes


class SmartphoneCaptureFile(_Section):
    """The whole ``capture.toml`` of a ``method = "smartphone"`` capture."""

    method: Literal["smartphone"]
    name: str | None = None
    photo: PhotoSection
    thresholds: ThresholdsSection
    setup: SetupSection = SetupSection()
    specular: SpecularSection = SpecularSection()
    fit: SmartphoneFitSection = SmartphoneFitSection()
    color_correction: ColorCorrectionSection | None = None


@dataclasses.dataclass(frozen=True, eq=False)
class SmartphoneCapture:
    """A loaded smartphone capture: the validated file, the photo, checksums."""

    path: Path
    name: str
    config: SmartphoneCaptureFile
    photo: np.ndarray
    checksums: dict[str, str]

    @property
    def method(self) -> str:
        return "smartphone"


def parse_smartphone_file(raw: dict, file: str) -> SmartphoneCaptureFile:
    """Validate a parsed ``capture.toml`` (raises :class:`~wardjax.capture.CaptureError`)."""
    try:
        cfg = SmartphoneCaptureFile.model_validate(raw)
    except pydantic.ValidationError as e:
        raise pydantic_error(e, file) from None
    y0, y1, x0, x1 = cfg.photo.region
    if y1 <= y0 or x1 <= x0:
        raise CaptureError(
            file, "photo.region", f"[y0, y1, x0, x1] must have y1 > y0 and x1 > x0 (got {list(cfg.photo.region)})"
        )
    cc = cfg.color_correction
    if cc is not None and (sorted(cc.order) != list(range(24)) or cc.grid[0] * cc.grid[1] != 24):
        raise CaptureError(
            file,
            "color_correction.order",
            f"a ColorChecker 24: grid {list(cc.grid)} must hold 24 cells and order each chart index 0–23 once",
        )
    lo, hi = cfg.specular.n_range
    if not lo <= cfg.specular.n <= hi:
        raise CaptureError(file, "specular.n", f"{cfg.specular.n} lies outside specular.n_range [{lo}, {hi}]")
    for field, fn, value in (
        ("setup.display", load_display, cfg.setup.display),
        ("setup.viewing", load_viewing, cfg.setup.viewing),
    ):
        try:
            fn(value)
        except (KeyError, ValueError) as e:
            raise CaptureError(file, field, str(e).strip("'\"")) from None
    # A threshold is one of the gratings the display showed: a whole number of pixels per bar in its range.
    disp = load_display(cfg.setup.display)
    t = cfg.thresholds
    for field, values in (
        ("thresholds.ppb", t.ppb or []),
        ("thresholds.ppb_mean", [] if t.ppb_mean is None else [t.ppb_mean]),
    ):
        bad = [v for v in values if not disp.ppb_min <= v <= disp.ppb_max]
        if bad:
            raise CaptureError(
                file,
                field,
                f"{bad[0]} lies outside the gratings display {disp.name!r} shows: "
                f"{disp.ppb_min} to {disp.ppb_max} pixels per bar",
            )
    return cfg


def check_relative(name: str, field: str) -> None:
    """Refuse a file named in ``capture.toml`` that lies outside the capture folder (absolute, ``..``, NUL)."""
    if Path(name).is_absolute() or ".." in Path(name).parts or "\x00" in name:
        raise CaptureError(CAPTURE_FILE, field, f"file {name!r} must be a path inside the capture folder")


def load_smartphone_capture(folder: Path, cfg: SmartphoneCaptureFile) -> SmartphoneCapture:
    """Load a smartphone capture folder whose ``capture.toml`` validated to ``cfg``."""
    check_relative(cfg.photo.file, "photo.file")
    path = folder / cfg.photo.file
    if path.is_dir():
        raise CaptureError(CAPTURE_FILE, "photo.file", f"{cfg.photo.file!r} is a folder, expected an image file")
    if (problem := file_problem(path)) == "no such file":
        raise CaptureError(CAPTURE_FILE, "photo.file", f"{cfg.photo.file!r} does not exist in {folder}")
    if problem is not None:
        raise CaptureError(CAPTURE_FILE, "photo.file", f"{cfg.photo.file!r} {problem}; expected an image file")
    try:
        photo = read_image(path)
    except (OSError, ValueError, RuntimeError) as e:
        text = str(e).strip().splitlines()
        raise CaptureError(
            cfg.photo.file, None, f"cannot be read as an image ({text[0] if text else type(e).__name__})"
        ) from None
    if photo.ndim != 3 or photo.shape[-1] != 3:
        raise CaptureError(
            cfg.photo.file, None, f"is not an RGB image (shape {photo.shape}); the method needs a colour photo"
        )
    if photo.dtype not in (np.uint8, np.uint16):
        raise CaptureError(
            cfg.photo.file, None, f"holds {photo.dtype} values; the method reads 8- or 16-bit photos (uint8, uint16)"
        )
    h, w = photo.shape[:2]
    y0, y1, x0, x1 = cfg.photo.region
    if y1 > h or x1 > w:
        raise CaptureError(
            CAPTURE_FILE, "photo.region", f"{list(cfg.photo.region)} reaches outside the {w}×{h} photo {cfg.photo.file}"
        )
    try:
        check_photo_region(cfg.photo.file, photo[y0:y1, x0:x1], float(np.iinfo(photo.dtype).max))
    except RuleError as e:
        raise CaptureError(e.field, "photo.region", e.message) from None
    if cfg.color_correction is not None:
        for k, (b0, b1, a0, a1) in enumerate(cfg.color_correction.regions()):
            if b0 < 0 or a0 < 0 or b1 > h or a1 > w:
                raise CaptureError(
                    CAPTURE_FILE,
                    "color_correction",
                    f"chart patch {k} box {[b0, b1, a0, a1]} reaches outside the {w}×{h} photo {cfg.photo.file}",
                )
    checksums = {CAPTURE_FILE: sha256(folder / CAPTURE_FILE), cfg.photo.file: sha256(path)}
    return SmartphoneCapture(folder, cfg.name or folder.resolve().name, cfg, photo, checksums)
