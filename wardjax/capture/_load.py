"""Loading a capture folder: the validated file, the images decoded to linear light."""

from __future__ import annotations

import dataclasses
import functools
import math
from pathlib import Path

import numpy as np

from .._files import RAW_SUFFIXES, decode_lut, file_problem, sha256
from .._rules import RuleError, check_image_pair, check_lit_exposure, check_lit_picture
from ..geometry import Camera, Rig
from ._errors import CAPTURE_FILE, CaptureError
from ._images import CaptureImages, ImageSource, Window, open_image
from ._photo import PhotoCapture, load_photo_capture
from ._photo_schema import FlashFile, MultiviewFile
from ._schema import CaptureFile, parse_capture_file, unit_direction
from ._smartphone import SmartphoneCapture, check_relative, load_smartphone_capture

__all__ = ["IMAGE_SUFFIXES", "Capture", "load_capture"]

IMAGE_SUFFIXES = (".png", ".tif", ".tiff", ".jpg", ".jpeg") + RAW_SUFFIXES


@dataclasses.dataclass(frozen=True, eq=False)
class Capture:
    """A loaded, validated capture.

    The images are held as *sources* (:class:`~wardjax.capture.CaptureImages`):
    a TIFF is read by windows of rows when one is asked for
    (:meth:`window`), so that fitting a 50 MP capture never holds a whole
    image; PNG and JPEG (one compressed stream each) are decoded at load
    and held as codes. :attr:`lit`, :attr:`dark` and :attr:`lit_clipped`
    build the whole image on first access and keep it.

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
    images
        The lit and dark image sources and their decoding.
    saturation
        Linear level from which a value counts as clipped.
    checksums
        ``{file name: "sha256:…"}`` of ``capture.toml`` and every image read.
    """

    path: Path
    name: str
    config: CaptureFile
    rig: Rig
    images: CaptureImages
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

    def window(self, rows: slice, cols: slice = slice(None)) -> Window:
        """``rows × cols`` of the lit and dark images, linear float32, and where lit is clipped.

        Only the rows asked for are decoded (a TIFF's overlapping segments).
        """
        return self.images.window(rows, cols)

    @functools.cached_property
    def lit(self) -> np.ndarray:
        """``(H, W, 3)`` float32 linear lit image (full scale 1), built on first access."""
        return self.images.whole("lit")

    @functools.cached_property
    def dark(self) -> np.ndarray | None:
        """``(H, W, 3)`` float32 linear dark image, or ``None``; built on first access."""
        return None if self.images.dark is None else self.images.whole("dark")

    @functools.cached_property
    def lit_clipped(self) -> np.ndarray:
        """``(H, W, 3)`` bool: the lit value is the largest code (clipped); built on first access."""
        return self.images.whole("clipped")


def _open_image(folder: Path, name: str, field: str, cfg: CaptureFile) -> tuple[ImageSource, str]:
    """The source of one image named by ``field``, its kind, bit depth and size checked (from its header)."""
    path = folder / name
    check_relative(name, field)
    if path.is_dir():
        raise CaptureError(name, None, f"is a folder, expected an image file (named by {CAPTURE_FILE} {field})")
    if (problem := file_problem(path)) == "no such file":
        raise CaptureError(name, None, f"image file is missing (named by {CAPTURE_FILE} {field})")
    if problem is not None:
        raise CaptureError(name, None, f"{problem}; expected an image file (named by {CAPTURE_FILE} {field})")
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
        source = open_image(path, name)
    except Exception as e:  # any reader failure is a corrupt file to the user
        raise CaptureError(name, None, f"cannot read the image ({_reason(e)})") from None
    want = np.uint8 if bits == 8 else np.uint16
    if source.dtype != want:
        raise CaptureError(
            name,
            None,
            f"holds {source.dtype} values but {CAPTURE_FILE} images.bit_depth = {bits} "
            f"(expected {np.dtype(want).name})",
        )
    w, h = cfg.camera.image_size
    if (source.height, source.width) != (h, w):
        raise CaptureError(
            name, None, f"is {source.width}×{source.height} pixels but {CAPTURE_FILE} camera.image_size = [{w}, {h}]"
        )
    return source, sha256(path)


def _reason(e: Exception) -> str:
    return ((str(e).splitlines() or [""])[0] or type(e).__name__)[:160]


def _extremes(source: ImageSource) -> tuple[int, int]:
    """The smallest and largest code of an image, every band of it decoded once (a corrupt segment fails here)."""
    try:
        return source.extremes()
    except Exception as e:
        raise CaptureError(source.name, None, f"cannot read the image ({_reason(e)})") from None


# Blocks of adjacent rows read, evenly spaced, for the lit image's neighbour correlation: a few hundred rows of
# any image, read as a few contiguous windows (a tiled image decodes each tile row once, not once per row pair).
_BLOCKS, _BLOCK_ROWS = 8, 16
# Fewer neighbouring pixel pairs than this say too little (random codes would spread by ± 0.05 about r = 0).
_MIN_PAIRS = 400


def _neighbour_correlation(source: ImageSource) -> float:
    """The larger of the horizontal and vertical lag-1 correlations of ``source``'s codes, averaged over channels.

    Read from at most :data:`_BLOCKS` windows of :data:`_BLOCK_ROWS` adjacent rows spread over the image;
    NaN where they hold one value or fewer than :data:`_MIN_PAIRS` pixel pairs
    (the estimate's spread, about ``1/√n``, would reach the rule's bound).
    """
    h, w = source.height, source.width
    if h < 2 or w < 2:
        return math.nan
    n = min(_BLOCK_ROWS, h)  # windows start on multiples of n: whole strips or tiles of that height, none twice
    starts = (np.unique(np.linspace(0, h // n - 1, min(_BLOCKS, h // n)).round().astype(int)) * n).tolist()
    try:
        blocks = [source.read(slice(r, r + n)).astype(np.float64) for r in starts]  # each (n, W, 3)
    except Exception as e:
        raise CaptureError(source.name, None, f"cannot read the image ({_reason(e)})") from None

    def corr(x: np.ndarray, y: np.ndarray) -> float:  # per channel (last axis), then the mean of those defined
        if x.shape[0] < _MIN_PAIRS:
            return math.nan
        x, y = x - x.mean(axis=0), y - y.mean(axis=0)
        den = np.sqrt((x * x).sum(axis=0) * (y * y).sum(axis=0))
        r = (x * y).sum(axis=0)[den > 0] / den[den > 0]
        return float(r.mean()) if r.size else math.nan

    c = blocks[0].shape[-1]
    horizontal = corr(*(np.concatenate([b[:, d : w - 1 + d].reshape(-1, c) for b in blocks]) for d in (0, 1)))
    vertical = corr(*(np.concatenate([b[d : n - 1 + d].reshape(-1, c) for b in blocks]) for d in (0, 1)))
    return max(horizontal, vertical) if math.isfinite(horizontal) and math.isfinite(vertical) else math.nan


def load_capture(path) -> Capture | SmartphoneCapture | PhotoCapture:
    """Load and validate a capture folder.

    Parameters
    ----------
    path
        The folder holding ``capture.toml`` and its images.

    Returns
    -------
    Capture or SmartphoneCapture or PhotoCapture
        A :class:`SmartphoneCapture` when ``method = "smartphone"``; a
        :class:`PhotoCapture` when ``method = "flash"`` or ``"multiview"``.

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
    if isinstance(cfg, (FlashFile, MultiviewFile)):
        return load_photo_capture(folder, cfg)
    checksums = {CAPTURE_FILE: sha256(folder / CAPTURE_FILE)}
    lit, checksums[cfg.images.lit] = _open_image(folder, cfg.images.lit, "images.lit", cfg)
    enc, bits = cfg.images.encoding, cfg.images.bit_depth
    top = (1 << bits) - 1
    lut = decode_lut(enc, bits)
    # The pixel rules, from one banded pass over each image (the whole of neither is held);
    # lit's first, as each image is checked before the next is opened.
    lo, hi = _extremes(lit)
    if lo == top:
        raise CaptureError(cfg.images.lit, None, "every pixel is saturated (at the largest code); reduce the exposure")
    try:  # the encodings are increasing: the brightest linear value is that of the largest code
        check_lit_exposure(cfg.images.lit, np.array([lo, hi], lit.dtype), float(lut[hi]), cfg.fit.noise_floor)
        check_lit_picture(cfg.images.lit, _neighbour_correlation(lit))
    except RuleError as e:
        raise CaptureError(e.field, None, e.message) from None
    dark = None
    if cfg.images.dark is not None:
        dark, checksums[cfg.images.dark] = _open_image(folder, cfg.images.dark, "images.dark", cfg)
        try:
            shapes = [(im.height, im.width, im.channels) for im in (lit, dark)]
            check_image_pair(cfg.images.lit, shapes[0], cfg.images.dark, shapes[1])
        except RuleError as e:
            raise CaptureError(e.field, None, e.message) from None
        _extremes(dark)
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
    return Capture(folder, name, cfg, rig, CaptureImages(lit, dark, lut, top), saturation, checksums)
