"""Photograph captures loaded into BRDF estimates: ``method = "flash"`` and ``method = "multiview"``.

Each photo ``k`` is a linear image ``v`` (decoded from its encoding, divided
by the lens falloff when a flat field is given). The observation model of
one point light is::

    v = exposure_k · P · f_r(wi, wo) · cos θi / d²  +  v_dark

with ``d`` the light–point distance (mm), ``P`` the light's power in pixel
units (given, or from a grey card of reflectance ρ photographed fronto-parallel
with the lamp at the camera at distance ``D``: ``v_card = exposure_card · P ·
(ρ/π) / D²``) and ``exposure = t · (ISO/100) / N²`` (:mod:`._exif`). The
loader inverts it per pixel::

    f_r = (v − v_dark · exposure_k / exposure_dark) / (exposure_k · P · cos θi / d²)

and carries each estimate's σ from the pixel noise
``σ_v² = read² + shot · v + q²/12`` (``q`` the linear step of one code).
A pixel is masked where a channel is clipped, the signal is below the noise
floor, or the light or the camera is at or below the horizon.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

from .._files import decode_lut, encode_values, read_image, sha256
from ..geometry import Camera, back_project
from ._errors import CAPTURE_FILE, CaptureError
from ._exif import EXPOSURE_TOLERANCE, read_exif, relative_exposure
from ._photo_schema import FlashFile, MultiviewFile, ShotSection
from ._smartphone import check_relative
from ._vignetting import Vignetting, fit_vignetting

__all__ = ["PhotoCapture", "load_photo_capture"]

_DIAG_35MM = float(np.hypot(36.0, 24.0))  # mm: the diagonal a 35 mm-equivalent focal length refers to
_FOCAL_TOLERANCE = 0.10  # capture.toml focal_px and the EXIF's 35 mm equivalent agree within 10 % (rounded mm)


@dataclasses.dataclass(frozen=True, eq=False)
class PhotoCapture:
    """A photograph capture turned into per-pixel BRDF estimates.

    Attributes
    ----------
    path, name, method, config
        The folder, its name, ``"flash"`` or ``"multiview"``, the validated file.
    f_r
        ``(H, W, K, C)`` BRDF estimates (sr⁻¹), NaN where masked.
    wi, wo
        ``(H, W, K, 3)`` unit vectors to the light and to the camera (sample frame).
    sigma
        ``(H, W, K, C)`` 1-σ of ``f_r`` from the pixel noise.
    mask
        ``(H, W, K)`` True where the estimate is usable.
    pixel_mm
        Size of one pixel on the sample, mm (at the image centre for a flash photo).
    points
        ``(H, W, 3)`` sample points of the pixels, mm.
    photos
        The photo file names, in order.
    linear
        ``(H, W, K, C)`` the photos' linear values (full scale 1), lens falloff removed.
    dark
        ``(H, W, K, C)`` the dark frame on each photo's exposure scale (zeros without one).
    scale
        ``(H, W, K, C)`` ``exposure · P · cos θi / d²``: linear value per unit f_r.
    exposures
        ``(K,)`` relative exposures.
    light_power
        ``(C,)`` P in pixel units, distances in mm.
    vignetting
        The flat-field falloff model, or ``None``.
    checksums
        ``{file: "sha256:…"}`` of every file read.
    notes
        Assumptions the loader made (said in the fit's report).
    """

    path: Path
    name: str
    method: str
    config: FlashFile | MultiviewFile
    f_r: np.ndarray
    wi: np.ndarray
    wo: np.ndarray
    sigma: np.ndarray
    mask: np.ndarray
    pixel_mm: float
    points: np.ndarray
    photos: tuple[str, ...]
    linear: np.ndarray
    dark: np.ndarray
    scale: np.ndarray
    exposures: np.ndarray
    light_power: np.ndarray
    vignetting: Vignetting | None
    checksums: dict[str, str]
    notes: tuple[str, ...] = ()

    @property
    def encoding(self) -> str:
        return self.config.encoding

    def to_photo(self, f_r: np.ndarray, k: int) -> np.ndarray:
        """``(H, W, C)`` the linear values photo ``k`` would hold if the surface had BRDF ``f_r`` ``(H, W, K|1, C)``
        or ``(H, W, C)``: ``exposure · P · f_r · cos θi / d² + v_dark``."""
        f = np.asarray(f_r, np.float64)
        if f.ndim == 4:
            f = f[:, :, k if f.shape[2] > 1 else 0]
        return f * self.scale[:, :, k] + self.dark[:, :, k]

    def display(self, linear: np.ndarray) -> np.ndarray:
        """Linear values → the photos' encoded (display) values in [0, 1]."""
        return np.asarray(encode_values(np.nan_to_num(linear, nan=0.0), self.encoding), np.float64)


# --------------------------------------------------------------------------- reading photos


class _Shot:
    """One photo read: linear values, clipped pixels, quantisation step, exposure (or None)."""

    def __init__(self, folder: Path, shot: ShotSection, field: str, encoding: str):
        self.name, self.field = shot.file, field
        check_relative(shot.file, f"{field}.file")
        path = folder / shot.file
        if not path.is_file():
            raise CaptureError(CAPTURE_FILE, f"{field}.file", f"{shot.file!r} does not exist in the capture folder")
        try:
            codes = read_image(path)
        except (OSError, ValueError) as e:
            raise CaptureError(shot.file, None, f"cannot be read as an image ({e})") from None
        if codes.dtype not in (np.uint8, np.uint16):
            raise CaptureError(shot.file, None, f"holds {codes.dtype} values; expected 8- or 16-bit codes")
        bits = 8 if codes.dtype == np.uint8 else 16
        top = (1 << bits) - 1
        lut = decode_lut(encoding, bits).astype(np.float64)
        self.linear = lut[codes]
        self.clipped: np.ndarray = np.asarray(np.any(codes == top, axis=-1))
        self.step = np.diff(lut, append=lut[-1] + (lut[-1] - lut[-2]))[codes]
        self.checksum = sha256(path)
        self.exposure = _exposure(path, shot, field)

    @property
    def shape(self) -> tuple[int, int]:
        return self.linear.shape[:2]

    def size_text(self) -> str:
        return f"{self.shape[1]}×{self.shape[0]}"


def _exposure(path: Path, shot: ShotSection, field: str) -> float | None:
    """The photo's relative exposure from capture.toml and its EXIF (which must agree), or None if incomplete."""
    exif = read_exif(path)
    values = {}
    for key, tag in (("exposure_time", "ExposureTime"), ("f_number", "FNumber"), ("iso", "ISOSpeedRatings")):
        given, read = getattr(shot, key), getattr(exif, key)
        if given is not None and read is not None and abs(given - read) > EXPOSURE_TOLERANCE * read:
            raise CaptureError(
                CAPTURE_FILE,
                f"{field}.{key}",
                f"{given:g} contradicts the EXIF of {shot.file} ({tag} = {read:g}); correct or remove the field",
            )
        values[key] = given if given is not None else read
    if any(v is None for v in values.values()):
        return None
    return relative_exposure(values["exposure_time"], values["f_number"], values["iso"])


def _missing_exposure(shot: _Shot) -> CaptureError:
    return CaptureError(
        CAPTURE_FILE,
        f"{shot.field}.exposure_time",
        f"the exposure of {shot.name} is not known (its EXIF lacks ExposureTime, FNumber or ISO): give "
        f"exposure_time, f_number and iso in [{shot.field}] to put its values on the scale of the other photos",
    )


def _exposures(shots: list[_Shot]) -> tuple[list[float], str | None]:
    """Every shot's exposure, or all 1 with a note when none is known; one known and another not is refused."""
    known = [s.exposure is not None for s in shots]
    if not any(known):
        return [1.0] * len(shots), "no photo has its exposure (EXIF or capture.toml): all taken as equal"
    for s in shots:
        if s.exposure is None:
            raise _missing_exposure(s)
    return [float(s.exposure) for s in shots], None  # pyright: ignore[reportArgumentType]


def _check_not_saturated(shot: _Shot) -> None:
    if shot.clipped.all():
        raise CaptureError(shot.name, None, "every pixel is saturated (at the largest code); reduce the exposure")


def _same_size(ref: _Shot, other: _Shot, what: str) -> None:
    if other.shape != ref.shape:
        raise CaptureError(
            other.name, None, f"is {other.size_text()} pixels but {ref.name} is {ref.size_text()}; {what}"
        )


def _vignetting(folder: Path, cfg, ref: _Shot, notes: list[str]) -> Vignetting | None:
    ff = getattr(cfg, "flat_field", None)
    if ff is None:
        return None
    flat = _Shot(folder, ff, "flat_field", cfg.encoding)
    _same_size(ref, flat, "a flat field is taken with the photo's lens and size")
    _check_not_saturated(flat)
    try:
        vig = fit_vignetting(flat.linear)
    except ValueError as e:
        raise CaptureError(ff.file, None, str(e)) from None
    notes.append(f"vignetting from {ff.file}: V(r) = 1 + {vig.coeffs[0]:.3g} r² + … (fit RMS {vig.rms:.3g})")
    return vig


# --------------------------------------------------------------------------- geometry and the estimates


def _bin(a: np.ndarray, b: int) -> np.ndarray:
    """Mean over ``b × b`` blocks of the first two axes (the edges that do not fill a block dropped)."""
    if b == 1:
        return a
    h, w = (a.shape[0] // b) * b, (a.shape[1] // b) * b
    a = a[:h, :w]
    return a.reshape(h // b, b, w // b, b, *a.shape[2:]).mean(axis=(1, 3))


def _unit(v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return v / n, n[..., 0]


def _estimates(points, cams, lights, linear, dark, clipped, step, exposures, power, cfg, binning: int):
    """Per-pixel f_r, σ, mask, wi, wo and scale for K photos.

    ``points (H, W, 3)``; ``cams, lights (K, 3)``; ``linear, dark, step (H, W, K, C)``; ``clipped (H, W, K)``.
    """
    wi, dl = _unit(lights[None, None] - points[:, :, None])  # (H, W, K, 3), (H, W, K)
    wo, _ = _unit(cams[None, None] - points[:, :, None])
    e = np.asarray(exposures, np.float64)[None, None, :, None]
    cos_i = wi[..., 2]
    scale = e * power[None, None, None, :] * (np.maximum(cos_i, 0.0) / dl**2)[..., None]
    signal = linear - dark
    noise = cfg.noise
    var = noise.read**2 + noise.shot * np.maximum(linear, 0.0) + step**2 / 12.0
    var = var + np.where(dark > 0, noise.read**2, 0.0)
    b2 = float(binning * binning)
    signal, var, scale = _bin(signal, binning), _bin(var, binning) / b2, _bin(scale, binning)
    clipped = _bin(clipped.astype(np.float64), binning) > 0
    wi, wo = _unit(_bin(wi, binning))[0], _unit(_bin(wo, binning))[0]
    pts = _bin(points, binning)
    mask = (
        ~clipped
        & (wi[..., 2] > 0)
        & (wo[..., 2] > 0)
        & np.all(scale > 0, axis=-1)
        & np.all(signal > cfg.fit.noise_floor, axis=-1)
    )
    safe = np.where(scale > 0, scale, 1.0)
    f_r = np.where(mask[..., None], signal / safe, np.nan)
    sigma = np.where(mask[..., None], np.sqrt(var) / safe, np.nan)
    return f_r, sigma, mask, wi, wo, scale, pts


def _capture(folder, cfg, est, pixel_mm, names, linear, dark, exposures, power, vig, checksums, notes) -> PhotoCapture:
    """The :class:`PhotoCapture` of :func:`_estimates`' output ``est`` and the photos' linear values (binned here)."""
    f_r, sigma, mask, wi, wo, scale, pts = est
    b = cfg.fit.bin
    name = cfg.name or folder.resolve().name
    return PhotoCapture(
        folder, name, cfg.method, cfg, f_r, wi, wo, sigma, mask, pixel_mm, pts, names,
        _bin(linear, b), _bin(dark, b), scale, np.asarray(exposures), power, vig, checksums, tuple(notes),
    )  # fmt: skip


# --------------------------------------------------------------------------- flash

# More than this fraction of pixels darker in the photo than in its dark frame (on the photo's exposure scale):
# the dark frame is not one of this photo (another exposure, other processing, the lamp on in both).
_MAX_DARKER_FRACTION = 0.5


def _check_dark(photo: _Shot, dark: _Shot | None, lin: np.ndarray, dk: np.ndarray, exposures) -> None:
    if dark is None:
        return
    darker = float(np.mean(np.any(dk > lin, axis=-1)))
    if darker > _MAX_DARKER_FRACTION:
        raise CaptureError(
            dark.name,
            None,
            f"on the exposure scale of {photo.name} (×{exposures[0] / exposures[1]:.3g}, from the exposures) it is "
            f"brighter than {photo.name} in {100 * darker:.0f} % of the pixels: it is not a dark frame of that photo "
            "(another exposure or processing); leave [dark] out or give each photo's real exposure",
        )


def _focal_px(cfg: FlashFile, shot: _Shot, folder: Path) -> float:
    h, w = shot.shape
    exif = read_exif(folder / shot.name)
    from_exif = None if exif.focal_35mm is None else exif.focal_35mm / _DIAG_35MM * float(np.hypot(w, h))
    given = cfg.camera.focal_px
    if given is not None and from_exif is not None and abs(given - from_exif) > _FOCAL_TOLERANCE * from_exif:
        raise CaptureError(
            CAPTURE_FILE,
            "camera.focal_px",
            f"{given:g} contradicts the EXIF of {shot.name} (FocalLengthIn35mmFilm = {exif.focal_35mm:g} mm, "
            f"{from_exif:.0f} px at {shot.size_text()}); correct or remove the field",
        )
    f = given if given is not None else from_exif
    if f is None:
        raise CaptureError(
            CAPTURE_FILE,
            "camera.focal_px",
            f"required: {shot.name} has no EXIF FocalLengthIn35mmFilm to derive the focal length from",
        )
    return float(f)


def _flash_camera(cfg: FlashFile, focal: float, shape: tuple[int, int]) -> Camera:
    h, w = shape
    c = cfg.camera
    pos = (0.0, 0.0, float(c.distance or 0.0)) if c.position is None else tuple(map(float, c.position))
    look = (0.0, 0.0, 0.0) if c.position is None else tuple(map(float, c.look_at))
    return Camera(position=pos, look_at=look, focal_px=focal, image_size=(w, h), up=tuple(map(float, c.up)))  # pyright: ignore[reportArgumentType]


def _lamp_position(cfg: FlashFile, cam: Camera) -> np.ndarray:
    if cfg.lamp.position is not None:
        return np.asarray(cfg.lamp.position, np.float64)
    right, down, fwd = cam.axes()
    ox, oy, oz = cfg.lamp.offset or (0.0, 0.0, 0.0)
    lamp = np.asarray(cam.position) + ox * right - oy * down + oz * fwd
    if lamp[2] <= 0:
        raise CaptureError(CAPTURE_FILE, "lamp.offset", f"puts the lamp at z = {lamp[2]:g} mm, behind the sample")
    return lamp


def _card_power(folder: Path, cfg: FlashFile, focal: float, photo: _Shot, vig: Vignetting | None, e_card: float):
    """P per channel from the grey card: ``v · (1 + r²/f²)^{3/2} · π · D² / (ρ · exposure)``, median over the region."""
    std = cfg.standard
    assert std is not None  # checked by the caller
    card = _Shot(folder, std, "standard", cfg.encoding)
    _check_not_saturated(card)
    h, w = card.shape
    lin = card.linear / (vig.gain(h, w)[..., None] if vig is not None and card.shape == photo.shape else 1.0)
    y0, y1, x0, x1 = std.region or (h // 3, 2 * h // 3, w // 3, 2 * w // 3)
    if y1 > h or x1 > w:
        raise CaptureError(CAPTURE_FILE, "standard.region", f"{[y0, y1, x0, x1]} reaches outside the {w}×{h} photo")
    f = focal * float(np.hypot(w, h) / np.hypot(*photo.shape))
    v, u = np.mgrid[y0:y1, x0:x1]
    r2 = ((u - (w - 1) / 2) ** 2 + (v - (h - 1) / 2) ** 2) / f**2
    ok = ~card.clipped[y0:y1, x0:x1]
    if ok.sum() < 0.5 * ok.size:
        raise CaptureError(std.file, "standard.region", "more than half the card's region is clipped")
    vals = lin[y0:y1, x0:x1][ok] * ((1 + r2[ok]) ** 1.5)[:, None]
    rho = np.asarray(std.reflectance, np.float64)
    return np.median(vals, axis=0) * np.pi * std.distance**2 / (rho * e_card), card


def _load_flash(folder: Path, cfg: FlashFile) -> PhotoCapture:
    notes: list[str] = []
    photo = _Shot(folder, cfg.photo, "photo", cfg.encoding)
    _check_not_saturated(photo)
    checksums = {CAPTURE_FILE: sha256(folder / CAPTURE_FILE), photo.name: photo.checksum}
    dark = None
    if cfg.dark is not None:
        dark = _Shot(folder, cfg.dark, "dark", cfg.encoding)
        _same_size(photo, dark, "the dark frame is the same view as the photo")
        checksums[dark.name] = dark.checksum
    vig = _vignetting(folder, cfg, photo, notes)
    h, w = photo.shape
    gain = np.ones((h, w, 1)) if vig is None else vig.gain(h, w)[..., None]
    focal = _focal_px(cfg, photo, folder)
    cam = _flash_camera(cfg, focal, photo.shape)
    lamp = _lamp_position(cfg, cam)
    shots = [photo] + ([dark] if dark is not None else [])
    card = None
    if cfg.standard is not None:
        card = _Shot(folder, cfg.standard, "standard", cfg.encoding)
        shots.append(card)
    exposures, note = _exposures(shots)
    if note:
        notes.append(note)
    if cfg.standard is not None:
        power, card = _card_power(folder, cfg, focal, photo, vig, exposures[-1])
        checksums[card.name] = card.checksum
        notes.append(f"light power from the grey card {card.name}: P = {', '.join(f'{p:.4g}' for p in power)}")
    else:
        assert cfg.light is not None
        power = np.asarray(cfg.light.power, np.float64)
    v, u = np.mgrid[0:h, 0:w]
    points, hit = back_project(cam, u.astype(np.float64), v.astype(np.float64))
    y0, y1, x0, x1 = cfg.camera.region or (0, h, 0, w)
    if y1 > h or x1 > w:
        raise CaptureError(CAPTURE_FILE, "camera.region", f"{[y0, y1, x0, x1]} reaches outside the {w}×{h} photo")
    crop = (slice(y0, y1), slice(x0, x1))
    lin = (photo.linear / gain)[crop][:, :, None]
    dk = np.zeros_like(lin)
    if dark is not None:
        dk = (dark.linear / gain)[crop][:, :, None] * (exposures[0] / exposures[1])
    _check_dark(photo, dark, lin, dk, exposures)
    seen = np.asarray(hit, bool)  # the pixel's ray meets the sample plane
    pts = np.where(seen[..., None], points, 0.0)[crop]
    clipped = (photo.clipped | ~seen)[crop][:, :, None]
    step = (photo.step / gain)[crop][:, :, None]
    est = _estimates(
        pts, np.asarray([cam.position]), lamp[None], lin, dk, clipped, step, exposures[:1], power, cfg, cfg.fit.bin
    )
    b = cfg.fit.bin
    pixel_mm = float(cam.position[2] if cfg.camera.distance is None else cfg.camera.distance) / focal * b
    return _capture(folder, cfg, est, pixel_mm, (photo.name,), lin, dk, exposures[:1], power, vig, checksums, notes)


# --------------------------------------------------------------------------- multiview


def _load_multiview(folder: Path, cfg: MultiviewFile) -> PhotoCapture:
    notes: list[str] = []
    shots = [_Shot(folder, p, f"photos[{i}]", cfg.encoding) for i, p in enumerate(cfg.photos)]
    checksums = {CAPTURE_FILE: sha256(folder / CAPTURE_FILE)}
    for s in shots:
        _check_not_saturated(s)
        checksums[s.name] = s.checksum
    if cfg.board is not None:
        from ._markers import rectify_views

        cams, lights, linear, clipped, step, width = rectify_views(cfg, shots)
    else:
        for s in shots[1:]:
            _same_size(shots[0], s, "rectified photos of one capture must all be the same size")
        cams = np.asarray([p.camera for p in cfg.photos], np.float64)
        lights = np.asarray([p.light if p.light is not None else p.camera for p in cfg.photos], np.float64)
        linear = np.stack([s.linear for s in shots], 2)
        clipped = np.stack([s.clipped for s in shots], 2)
        step = np.stack([s.step for s in shots], 2)
        width = float(cfg.width)  # pyright: ignore[reportArgumentType]
    exposures, note = _exposures(shots)
    if note:
        notes.append(note)
    h, w = linear.shape[:2]
    pixel = width / w
    x = ((np.arange(w) + 0.5) - w / 2) * pixel
    y = -((np.arange(h) + 0.5) - h / 2) * pixel
    points = np.stack(np.broadcast_arrays(x[None, :], y[:, None], np.zeros((h, w))), -1)
    power = np.asarray(cfg.light.power, np.float64)
    dark = np.zeros_like(linear)
    est = _estimates(points, cams, lights, linear, dark, clipped, step, exposures, power, cfg, cfg.fit.bin)
    b = cfg.fit.bin
    names = tuple(s.name for s in shots)
    return _capture(folder, cfg, est, pixel * b, names, linear, dark, exposures, power, None, checksums, notes)


def load_photo_capture(folder: Path, cfg: FlashFile | MultiviewFile) -> PhotoCapture:
    """Load a ``flash`` or ``multiview`` capture folder whose ``capture.toml`` validated to ``cfg``."""
    if isinstance(cfg, FlashFile):
        return _load_flash(folder, cfg)
    return _load_multiview(folder, cfg)
