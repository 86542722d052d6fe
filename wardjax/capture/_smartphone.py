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
from ._errors import CAPTURE_FILE, CaptureError, pydantic_error
from ._rules import LIMITS, RuleError, check_photo_region
from ._setup import load_display, load_viewing

__all__ = ["SmartphoneCapture", "SmartphoneCaptureFile", "load_smartphone_capture", "parse_smartphone_file"]


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


class SmartphoneCaptureFile(_Section):
    """The whole ``capture.toml`` of a ``method = "smartphone"`` capture."""

    method: Literal["smartphone"]
    name: str | None = None
    photo: PhotoSection
    thresholds: ThresholdsSection
    setup: SetupSection = SetupSection()
    specular: SpecularSection = SpecularSection()
    fit: SmartphoneFitSection = SmartphoneFitSection()


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
    checksums = {CAPTURE_FILE: sha256(folder / CAPTURE_FILE), cfg.photo.file: sha256(path)}
    return SmartphoneCapture(folder, cfg.name or folder.resolve().name, cfg, photo, checksums)
