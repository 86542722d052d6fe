"""Synthetic captures: the mirror image of load → reconstruct → fit.

:func:`simulate_capture` renders the lamp-on and lamp-off images a camera
would record of a textured Ward probe beside a diffuse reflectance standard
in the rig of the image-based paper (Fig. 2), adds sensor noise, quantises
to 8 or 16 bits in an encoding, and writes a complete capture folder in the
format :func:`wardjax.load_capture` reads. The ground truth goes beside it
(``truth.json``, ``truth_rho_d.tif``); the loader ignores those files.

Radiance reaching pixel ``p`` whose ray meets the sample plane at ``P``:

* probe (``x > 0``): ``L = f_r(ωi, ωo; ρd(P)) · E(P)``
* standard (``x < 0``): ``L = ρ_std / π · E(P)``
* elsewhere (the table): ``L = 0.05 / π · E(P)``

with ``E(P) = I · D(P) · cos θi / r²`` (a point lamp of intensity ``I`` and
directivity ``D``, symmetric about the plane ``x = 0``). The camera records
``v = k · V(p) · L + a · V(p) · ρ(P)`` with exposure ``k``, vignetting
``V = cos⁴`` of the ray's angle to the optical axis and ambient light ``a``
that is present in both frames (the background the dark frame removes).
"""

from __future__ import annotations

import dataclasses
import json
import os
import tempfile
from collections.abc import Callable
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from .capture import CAPTURE_FILE, Capture, encode_image, load_capture
from .geometry import Camera, Rig, pixel_geometry, project, to_material_frame
from .ward import WardParams, ward_brdf

__all__ = ["SensorNoise", "default_rig", "procedural_texture", "simulate_capture", "write_capture_toml"]

TABLE_REFLECTANCE = 0.05


@dataclasses.dataclass(frozen=True)
class SensorNoise:
    """Gaussian sensor noise in linear units of full scale: ``σ² = read² + shot · v``.

    The default is a decent camera: σ ≈ 0.1 % of full scale in the dark and
    ≈ 0.3 % at half scale.
    """

    read: float = 0.001
    shot: float = 1.6e-5

    def sigma(self, v: np.ndarray) -> np.ndarray:
        return np.sqrt(self.read**2 + self.shot * np.maximum(v, 0.0))


def default_rig(image_size=(320, 240)) -> Rig:
    """The default rig: lamp and camera 500 mm away at ±36.9° in the plane x = 0.

    Probe ``[3, 120] × [−150, 150]`` mm, standard its mirror image. The focal
    length frames both with a 4 % margin; the principal point is the centre.
    """
    lamp = (0.0, 300.0, 400.0)
    position = (0.0, -300.0, 400.0)
    probe = (3.0, 120.0, -150.0, 150.0)
    standard = (-120.0, -3.0, -150.0, 150.0)
    return Rig(lamp=lamp, camera=framed_camera(position, (0.0, 0.0, 0.0), image_size, [probe, standard]),
               probe=probe, standard=standard)


def framed_camera(position, look_at, image_size, boxes, margin: float = 0.04) -> Camera:
    """A camera whose focal length just frames the corners of ``boxes`` (mm rectangles on z = 0)."""
    w, h = int(image_size[0]), int(image_size[1])
    unit = Camera(position=tuple(position), look_at=tuple(look_at), focal_px=1.0, image_size=(w, h))
    corners = np.array([[x, y, 0.0] for b in boxes for x in b[:2] for y in b[2:]])
    uv, _ = project(unit, corners)
    cx, cy = unit.principal
    need = max(np.max(np.abs(uv[:, 0] - cx)) / (w / 2), np.max(np.abs(uv[:, 1] - cy)) / (h / 2))
    return dataclasses.replace(unit, focal_px=round(float((1 - margin) / need), 2))


def _smooth_noise(x, y, rng: np.random.Generator, waves: int = 10, wavelength=(25.0, 90.0)) -> np.ndarray:
    """Smooth random field with unit variance: a sum of random plane waves."""
    out = np.zeros(np.shape(x))
    for _ in range(waves):
        k = 2 * np.pi / rng.uniform(*wavelength)
        th = rng.uniform(0, 2 * np.pi)
        ph = rng.uniform(0, 2 * np.pi)
        out += np.sin(k * (np.cos(th) * x + np.sin(th) * y) + ph)
    return out * np.sqrt(2.0 / waves)


def procedural_texture(kind: str, x, y, *, amplitude: float = 0.08, seed: int = 0) -> np.ndarray:
    """A multiplicative ρd modulation ``m(x, y)`` (mean ≈ 1) at sample points (mm).

    ``"wood"``: growth rings running along y (slightly wavy), with fine grain;
    ``"marble"``: veins, a turbulent sine pattern across the surface;
    ``"none"``: ``m = 1``. The modulation stays within ``1 ± amplitude``.
    """
    rng = np.random.default_rng(seed)
    x = np.asarray(x, np.float64)
    y = np.asarray(y, np.float64)
    if kind == "none":
        return np.ones_like(x)
    if kind == "wood":
        r = x + 1.5 * _smooth_noise(x, y, rng, wavelength=(150.0, 400.0))
        rings = np.sin(2 * np.pi * r / rng.uniform(9.0, 13.0))
        grain = _smooth_noise(x, y, rng, wavelength=(4.0, 12.0))
        m = 0.8 * rings + 0.2 * np.tanh(grain)
    elif kind == "marble":
        th = rng.uniform(0.3, 1.2)
        phase = 2 * np.pi * (np.cos(th) * x + np.sin(th) * y) / rng.uniform(40.0, 70.0)
        m = np.sin(phase + 2.5 * _smooth_noise(x, y, rng))
        m = np.sign(m) * np.abs(m) ** 0.5  # sharpen the veins
    else:
        raise ValueError(f"texture={kind!r} is not one of 'wood', 'marble', 'none' (or a callable)")
    return 1.0 + amplitude * np.clip(m, -1.0, 1.0)


def _toml_value(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        return repr(v)
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    raise TypeError(f"cannot write {type(v).__name__} to TOML")


def write_capture_toml(path: Path, config: dict, header: str = "") -> None:
    """Write a ``capture.toml`` from a dict of top-level values and ``[sections]``, atomically."""
    lines = [f"# {line}" for line in header.splitlines()]
    sections = {k: v for k, v in config.items() if isinstance(v, dict)}
    for k, v in config.items():
        if not isinstance(v, dict) and v is not None:
            lines.append(f"{k} = {_toml_value(v)}")
    for name, sec in sections.items():
        lines.append("")
        lines.append(f"[{name}]")
        lines += [f"{k} = {_toml_value(v)}" for k, v in sec.items() if v is not None]
    _write_atomic(Path(path), ("\n".join(lines) + "\n").encode())


def _write_atomic(path: Path, data: bytes) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    with os.fdopen(fd, "wb") as fh:
        fh.write(data)
    os.replace(tmp, path)


def _write_image_atomic(path: Path, codes: np.ndarray) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.stem}.", suffix=path.suffix)
    os.close(fd)
    try:
        suffix = path.suffix.lower()
        if suffix in (".tif", ".tiff"):
            import tifffile

            tifffile.imwrite(tmp, codes, photometric="rgb" if codes.ndim == 3 else None)
        elif suffix in (".jpg", ".jpeg"):
            import imageio.v3 as iio

            iio.imwrite(tmp, codes, quality=95)
        else:
            import imagecodecs

            with open(tmp, "wb") as fh:
                fh.write(imagecodecs.png_encode(codes, level=6))
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)


def _render(params: WardParams, rig: Rig, rho_d_map, tangent, rho_standard, normalization, rows) -> tuple:
    """Noise-free radiance (per unit lamp intensity) and local reflectance for pixel rows."""
    cam = rig.camera
    u, v = np.meshgrid(np.arange(cam.width, dtype=np.float64), rows.astype(np.float64))
    g = pixel_geometry(rig, u, v)
    x, y = g.points[..., 0], g.points[..., 1]
    rho_d = rho_d_map(np.nan_to_num(x), np.nan_to_num(y))  # (..., 3)
    wi = to_material_frame(g.wi, tangent)
    wo = to_material_frame(g.wo, tangent)
    p = WardParams(rho_d=rho_d, rho_s=np.asarray(params.rho_s, float), alpha_x=np.asarray(params.alpha_x, float),
                   alpha_y=np.asarray(params.alpha_y, float))
    with jax.enable_x64(True):
        f = np.asarray(ward_brdf(jax.tree_util.tree_map(jnp.asarray, p), np.nan_to_num(wi), np.nan_to_num(wo),
                                 normalization=normalization))
    rho_std = np.broadcast_to(np.asarray(rho_standard, float), (3,))
    local = np.full(g.points.shape, TABLE_REFLECTANCE)
    local = np.where(g.in_standard[..., None], rho_std, local)
    local = np.where(g.in_probe[..., None], rho_d, local)
    brdf = local / np.pi
    brdf = np.where(g.in_probe[..., None], f, brdf)
    # Lamp directivity: a cos³ falloff about the lamp's axis, which points at the
    # origin from within the plane x = 0, so it is symmetric about that plane.
    lamp = np.asarray(rig.lamp, float)
    to_p = np.nan_to_num(g.points) - lamp
    cos_axis = -(to_p @ lamp) / (np.linalg.norm(to_p, axis=-1) * np.linalg.norm(lamp))
    e = g.irradiance * np.clip(cos_axis, 0, 1) ** 3
    # Vignetting cos⁴ of the ray's angle to the optical axis.
    fx, fy = cam.focal
    cx, cy = cam.principal
    tan2 = ((u - cx) / fx) ** 2 + ((v - cy) / fy) ** 2
    vig = 1.0 / (1.0 + tan2) ** 2
    hit = np.isfinite(g.points[..., 0])
    radiance = np.where(hit[..., None], brdf * e[..., None] * vig[..., None], 0.0)
    ambient = np.where(hit[..., None], local * vig[..., None], 0.0)
    truth = np.where(g.in_probe[..., None], rho_d, np.nan)
    return radiance, ambient, truth, g.in_probe | g.in_standard


def simulate_capture(
    params: WardParams,
    out,
    seed: int = 0,
    *,
    rig: Rig | None = None,
    image_size: tuple[int, int] = (320, 240),
    texture: str | Callable = "wood",
    texture_amplitude: float = 0.08,
    noise: SensorNoise | None = None,
    encoding: str = "srgb",
    bit_depth: int = 8,
    image_format: str = "png",
    exposure: float | None = None,
    headroom: float = 0.8,
    ambient: float = 0.02,
    dark: bool = True,
    tangent=(1.0, 0.0),
    rho_standard=0.99,
    model: str | None = None,
    normalization: str = "ward1992",
    name: str | None = None,
    noise_floor: float = 0.002,
    band_rows: int = 256,
) -> Capture:
    """Render a capture of a Ward probe and write it as a capture folder.

    Parameters
    ----------
    params
        The probe's :class:`WardParams` (unbatched). ρd is the mean diffuse
        reflectance; the texture modulates it.
    out
        The capture folder to write (created; existing files are replaced).
    seed
        Seeds the texture and the sensor noise.
    rig
        A :class:`~wardjax.geometry.Rig`; default :func:`default_rig` for ``image_size``.
    image_size
        ``(width, height)`` when ``rig`` is not given.
    texture
        ``"wood"``, ``"marble"``, ``"none"`` or a callable ``(x, y) → (..., 3)`` ρd map (mm).
    texture_amplitude
        Relative amplitude of the procedural texture.
    noise
        :class:`SensorNoise`; default ``SensorNoise()``. ``SensorNoise(0, 0)`` for none.
    encoding, bit_depth, image_format
        How the images are stored: ``"srgb" | "gamma2.2" | "linear"``,
        ``8 | 16``, ``"png" | "tif" | "jpg"``.
    exposure
        Linear value of unit radiance per unit lamp intensity; default: the
        brightest probe or standard pixel lands at ``headroom`` of full scale.
        A larger exposure clips highlights.
    ambient
        Ambient light (fraction of full scale on a white surface), in both frames.
    dark
        Write the lamp-off frame.
    tangent, rho_standard, model, normalization, name, noise_floor
        Written to ``capture.toml``; ``model`` defaults to ``"isotropic"``
        when ``alpha_x == alpha_y`` else ``"anisotropic"``.

    Returns
    -------
    Capture
        The folder, loaded with :func:`wardjax.load_capture`.
    """
    out = Path(out)
    if bit_depth not in (8, 16):
        raise ValueError(f"bit_depth must be 8 or 16, got {bit_depth}")
    if image_format not in ("png", "tif", "jpg"):
        raise ValueError(f"image_format must be 'png', 'tif' or 'jpg', got {image_format!r}")
    if image_format == "jpg" and bit_depth != 8:
        raise ValueError("JPEG images are 8-bit")
    rig = rig or default_rig(image_size)
    noise = SensorNoise() if noise is None else noise
    rng = np.random.default_rng(seed)
    tex_seed = int(rng.integers(2**31))
    base = np.broadcast_to(np.asarray(params.rho_d, float), (3,))
    if callable(texture):
        rho_d_map = texture
        tex_name = getattr(texture, "__name__", "callable")
    else:
        def rho_d_map(x, y):
            m = procedural_texture(texture, x, y, amplitude=texture_amplitude, seed=tex_seed)
            return np.clip(base * m[..., None], 0.0, 1.0)
        tex_name = texture
    cam = rig.camera
    h, w = cam.height, cam.width
    radiance = np.empty((h, w, 3), np.float32)
    amb = np.empty((h, w, 3), np.float32)
    truth = np.empty((h, w, 3), np.float32)
    lit_area = np.zeros((h, w), bool)
    for r0 in range(0, h, band_rows):
        rows = np.arange(r0, min(r0 + band_rows, h))
        rad, a, t, on = _render(params, rig, rho_d_map, tangent, rho_standard, normalization, rows)
        radiance[r0:r0 + len(rows)] = rad
        amb[r0:r0 + len(rows)] = a
        truth[r0:r0 + len(rows)] = t
        lit_area[r0:r0 + len(rows)] = on
    if exposure is None:
        peak = float(np.max(radiance[lit_area])) if lit_area.any() else float(np.max(radiance))
        exposure = headroom / peak
    lit = exposure * radiance
    lit += ambient * amb
    dark_img = ambient * amb
    del radiance, amb
    for img in (lit, dark_img):
        img += (noise.sigma(img) * rng.standard_normal(img.shape)).astype(np.float32)

    ext = {"png": ".png", "tif": ".tif", "jpg": ".jpg"}[image_format]
    out.mkdir(parents=True, exist_ok=True)
    _write_image_atomic(out / f"lit{ext}", encode_image(lit, encoding, bit_depth))
    if dark:
        _write_image_atomic(out / f"dark{ext}", encode_image(dark_img, encoding, bit_depth))
    import tifffile

    fd, tmp = tempfile.mkstemp(dir=out, prefix=".truth_rho_d.", suffix=".tif")
    os.close(fd)
    tifffile.imwrite(tmp, truth, photometric="rgb")
    os.replace(tmp, out / "truth_rho_d.tif")

    if model is None:
        model = "isotropic" if float(params.alpha_x) == float(params.alpha_y) else "anisotropic"
    rs = np.asarray(rho_standard, float)
    config = {
        "method": "scanline",
        "name": name,
        "rho_standard": float(rs) if rs.ndim == 0 else [float(c) for c in rs],
        "images": {"lit": f"lit{ext}", "dark": f"dark{ext}" if dark else None, "encoding": encoding,
                   "bit_depth": int(bit_depth)},
        "rig": {"lamp": [float(c) for c in rig.lamp], "camera": [float(c) for c in cam.position]},
        "camera": {"look_at": [float(c) for c in cam.look_at], "up": [float(c) for c in cam.up],
                   "focal_px": cam.focal[0], "focal_px_y": cam.focal[1] if cam.focal[1] != cam.focal[0] else None,
                   "principal_point": [float(c) for c in cam.principal], "image_size": [w, h]},
        "regions": {"probe": None if rig.probe is None else [float(c) for c in rig.probe],
                    "standard": None if rig.standard is None else [float(c) for c in rig.standard]},
        "material": {"tangent": [float(c) for c in tangent]},
        "fit": {"model": model, "normalization": normalization, "noise_floor": float(noise_floor)},
    }
    if not any(v is not None for v in config["regions"].values()):
        del config["regions"]
    write_capture_toml(out / CAPTURE_FILE, config, header="Simulated by wardjax.simulate_capture; "
                       "the truth is in truth.json and truth_rho_d.tif.")
    truth_doc = {
        "params": {"rho_d": base.tolist(), "rho_s": float(params.rho_s), "alpha_x": float(params.alpha_x),
                   "alpha_y": float(params.alpha_y)},
        "normalization": normalization, "texture": tex_name, "texture_amplitude": texture_amplitude,
        "seed": seed, "exposure": exposure, "ambient": ambient,
        "noise": {"read": noise.read, "shot": noise.shot}, "tangent": list(map(float, tangent)),
    }
    _write_atomic(out / "truth.json", (json.dumps(truth_doc, indent=2) + "\n").encode())
    return load_capture(out)
