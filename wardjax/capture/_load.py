"""Loading a capture folder: the validated file, the images decoded to linear light."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

from .._files import RAW_SUFFIXES, as_rgb, decode_lut, read_image, sha256
from ..geometry import Camera, Rig
from ._errors import CAPTURE_FILE, CaptureError
from ._rules import RuleError, check_image_pair, check_lit_exposure
from ._schema import CaptureFile, parse_capture_file, unit_direction
from ._smartphone import SmartphoneCapture, check_relative, load_smartphone_capture

__all__ = ["IMAGE_SUFFIXES", "Capture", "load_capture"]

IMAGE_SUFFIXES = (".png", ".tif", ".tiff", ".jpg", ".jpeg") + RAW_SUFFIXES


@dataclasses.dataclass(frozen=True, eq=False)
class Capture:
    """A loaded, validated capture.

    Attributes
    ----------
    path
        The capture folder.
    name
        ``name`` from the file, or the folder name.
    config
        The validated :class:`CaptureFile`.
    rig
        The :class:`~wardjax.geometry.Rig` (camera, lamp, regions).
    lit, dark
        ``(H, W, 3)`` float32 linear images (full scale 1); ``dark`` may be ``None``.
    lit_clipped
        ``(H, W, 3)`` bool: the lit value is the largest code (clipped).
    saturation
        Linear level from which a value counts as clipped.
    checksums
        ``{file name: "sha256:…"}`` of ``capture.toml`` and every image read.
    """

    path: Path
    name: str
    config: CaptureFile
    rig: Rig
    lit: np.ndarray
    dark: np.ndarray | None
    lit_clipped: np.ndarray
    saturation: float
    checksums: dict[str, str]

    @property
    def method(self) -> str:
        return self.config.method

    @property
    def tangent(self) -> tuple[float, float]:
        t = unit_direction(self.config.material.tangent)
        return (t[0], t[1])

    @property
    def rho_standard(self) -> np.ndarray:
        return np.asarray(self.config.rho_standard, float)


def _load_image(folder: Path, name: str, field: str, cfg: CaptureFile):
    path = folder / name
    check_relative(name, field)
    if path.is_dir():
        raise CaptureError(name, None, f"is a folder, expected an image file (named by {CAPTURE_FILE} {field})")
    if not path.is_file():
        raise CaptureError(name, None, f"image file is missing (named by {CAPTURE_FILE} {field})")
    suffix = path.suffix.lower()
    if suffix not in IMAGE_SUFFIXES:
        raise CaptureError(
            CAPTURE_FILE, field, f"unsupported image type {suffix!r}; expected one of {', '.join(IMAGE_SUFFIXES)}"
        )
    enc, bits = cfg.images.encoding, cfg.images.bit_depth
    if suffix in RAW_SUFFIXES and (enc != "linear" or bits != 16):
        raise CaptureError(
            CAPTURE_FILE,
            "images.encoding",
            f"raw file {name} is decoded linear 16-bit; "
            f'set encoding = "linear" and bit_depth = 16 (got {enc!r}, {bits})',
        )
    if suffix in (".jpg", ".jpeg") and bits != 8:
        raise CaptureError(CAPTURE_FILE, "images.bit_depth", f"JPEG {name} is 8-bit, got bit_depth = {bits}")
    try:
        stored = read_image(path, rgb=False)
        channels = 1 if stored.ndim == 2 else int(stored.shape[-1])
        codes = as_rgb(stored)
        del stored
    except Exception as e:  # any reader failure is a corrupt file to the user
        reason = str(e).splitlines()[0] if str(e) else type(e).__name__
        raise CaptureError(name, None, f"cannot read the image ({reason[:160]})") from None
    want = np.uint8 if bits == 8 else np.uint16
    if codes.dtype != want:
        raise CaptureError(
            name,
            None,
            f"holds {codes.dtype} values but {CAPTURE_FILE} images.bit_depth = {bits} (expected {np.dtype(want).name})",
        )
    w, h = cfg.camera.image_size
    if codes.shape[:2] != (h, w):
        raise CaptureError(
            name, None, f"is {codes.shape[1]}×{codes.shape[0]} pixels but {CAPTURE_FILE} camera.image_size = [{w}, {h}]"
        )
    return codes, sha256(path), channels


def load_capture(path) -> Capture | SmartphoneCapture:
    """Load and validate a capture folder.

    Parameters
    ----------
    path
        The folder holding ``capture.toml`` and its images.

    Returns
    -------
    Capture or SmartphoneCapture
        A :class:`SmartphoneCapture` when ``method = "smartphone"``.

    Raises
    ------
    CaptureError
        One line naming the file and the field or value at fault.
    """
    folder = Path(path)
    if not folder.is_dir():
        raise CaptureError(str(folder), None, "not a folder (a capture is a folder with capture.toml and images)")
    cfg = parse_capture_file(folder / CAPTURE_FILE)
    if cfg.method == "smartphone":
        return load_smartphone_capture(folder, cfg)
    checksums = {CAPTURE_FILE: sha256(folder / CAPTURE_FILE)}
    lit_codes, checksums[cfg.images.lit], lit_ch = _load_image(folder, cfg.images.lit, "images.lit", cfg)
    enc, bits = cfg.images.encoding, cfg.images.bit_depth
    top = (1 << bits) - 1
    lut = decode_lut(enc, bits)
    lit = lut[lit_codes]
    clipped = lit_codes == top
    if clipped.all():
        raise CaptureError(cfg.images.lit, None, "every pixel is saturated (at the largest code); reduce the exposure")
    try:
        check_lit_exposure(cfg.images.lit, lit_codes, float(lit.max()), cfg.fit.noise_floor)
    except RuleError as e:
        raise CaptureError(e.field, None, e.message) from None
    dark = None
    if cfg.images.dark is not None:
        dark_codes, checksums[cfg.images.dark], dark_ch = _load_image(folder, cfg.images.dark, "images.dark", cfg)
        try:
            check_image_pair(
                cfg.images.lit, (*lit_codes.shape[:2], lit_ch), cfg.images.dark, (*dark_codes.shape[:2], dark_ch)
            )
        except RuleError as e:
            raise CaptureError(e.field, None, e.message) from None
        dark = lut[dark_codes]
        del dark_codes
    del lit_codes
    saturation = float(0.5 * (lut[top] + lut[top - 1]))
    cam = Camera(
        position=cfg.rig.camera,
        look_at=cfg.camera.look_at,
        focal_px=(cfg.camera.focal_px, cfg.camera.focal_px_y or cfg.camera.focal_px),
        image_size=cfg.camera.image_size,
        principal_point=cfg.camera.principal_point,
        # a huge or tiny hint made unit, so that the camera's axes stay finite (3 values in, 3 out)
        up=unit_direction(cfg.camera.up),  # pyright: ignore[reportArgumentType]
    )
    rig = Rig(lamp=cfg.rig.lamp, camera=cam, probe=cfg.regions.probe, standard=cfg.regions.standard)
    name = cfg.name or folder.resolve().name
    return Capture(folder, name, cfg, rig, lit, dark, clipped, saturation, checksums)
