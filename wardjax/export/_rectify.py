"""ρd rectified to the sample plane: a regular grid on ``z = 0`` in millimetres, EXR and TIFF.

The camera sees the sample in perspective; a renderer wants the texture on
the surface, in physical units. The rectified map samples the
camera-perspective ρd (`extract_rho_d`) at the projections of
the centres of a regular grid on the sample plane (the capture's pinhole
model, `project`), bilinearly:

.. math::

    ρ_d^\\mathrm{plane}[i, j] = ρ_d^\\mathrm{camera}\\bigl(π(x_0 + (j + ½)s,\\; y_1 - (i + ½)s,\\; 0)\\bigr)

with ``s`` the pixel size (mm), columns along ``+x`` and rows along ``−y``
(the sample seen from above, ``+y`` up), ``(x_0, y_1)`` the top-left corner.
A grid pixel is *measured* (mask 1) when the four camera pixels around its
projection all hold a ρd; the default ``s`` is the median footprint of a
camera pixel on the probe (``√`` of its area), so the grid keeps the
camera's resolution where it is finest on average.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import NamedTuple

import numpy as np

from .._files import atomic_path, write_image
from ..geometry import Camera, back_project, project

__all__ = ["PlaneTexture", "read_exr", "rectify_rho_d", "write_exr", "write_plane_texture"]

MAX_SIDE = 8192  # the rectified grid's longest side (pixels); the pixel size grows past it


class PlaneTexture(NamedTuple):
    """ρd on a regular grid of the sample plane (`rectify_rho_d`).

    Attributes
    ----------
    rho_d
        ``(H, W, 3)`` float32 linear ρd (sRGB primaries, white E); NaN where not measured.
    mask
        ``(H, W)`` bool: the pixel is measured.
    pixel_mm
        The side of a grid pixel (mm).
    origin_mm
        ``(x0, y1)``: the sample-plane point (mm) of the top-left corner of pixel ``[0, 0]``.
    """

    rho_d: np.ndarray
    mask: np.ndarray
    pixel_mm: float
    origin_mm: tuple[float, float]

    def metadata(self) -> dict:
        """Where the grid lies on the sample (written into every file of it)."""
        h, w = self.mask.shape
        x0, y1 = self.origin_mm
        s = self.pixel_mm
        return {
            "pixel_size_mm": s,
            "origin_mm": [x0, y1],
            "extent_mm": {"x": [x0, x0 + w * s], "y": [y1 - h * s, y1]},
            "axes": "column j: x = x0 + (j + 1/2) s; row i: y = y1 - (i + 1/2) s (sample frame, mm, z up)",
            "measured_fraction": float(self.mask.mean()) if self.mask.size else 0.0,
        }


def _footprint_mm(camera: Camera, rho_d: np.ndarray, band_rows: int) -> tuple[np.ndarray, float]:
    """Bounding box ``(x0, x1, y0, y1)`` (mm) of the measured pixels' points, and their median footprint side."""
    h, w = rho_d.shape[:2]
    lo, hi, sides = np.full(2, np.inf), np.full(2, -np.inf), []
    stride = max(1, int(np.sqrt(h * w / 200_000)))  # footprints from ≤ ~200k pixels
    for r0 in range(0, h, band_rows):
        rows = np.arange(r0, min(r0 + band_rows, h))
        ok = np.all(np.isfinite(rho_d[rows]), axis=-1)
        if not ok.any():
            continue
        rr, cc = np.nonzero(ok)
        pts, _ = back_project(camera, cc.astype(np.float64), rows[rr].astype(np.float64))
        good = np.all(np.isfinite(pts[:, :2]), axis=-1)
        if good.any():
            lo = np.minimum(lo, pts[good, :2].min(0))
            hi = np.maximum(hi, pts[good, :2].max(0))
        sub = (rr % stride == 0) & (cc % stride == 0) & good
        if sub.any():
            u, v = cc[sub].astype(np.float64), rows[rr[sub]].astype(np.float64)
            pu, _ = back_project(camera, u + 1.0, v)
            pv, _ = back_project(camera, u, v + 1.0)
            a, b = pu - pts[sub], pv - pts[sub]
            area = np.abs(a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0])
            sides.append(np.sqrt(area[np.isfinite(area)]))
    if not np.all(np.isfinite(lo)) or not sides:
        raise ValueError("no measured ρd pixel meets the sample plane: nothing to rectify")
    return np.array([lo[0], hi[0], lo[1], hi[1]]), float(np.median(np.concatenate(sides)))


def _round_sig(x: float, digits: int = 3) -> float:
    return float(f"{x:.{digits}g}")


def rectify_rho_d(
    rho_d,
    camera: Camera,
    *,
    box: tuple[float, float, float, float] | None = None,
    pixel_mm: float | None = None,
    max_side: int = MAX_SIDE,
    band_rows: int = 512,
) -> PlaneTexture:
    """Resample a camera-perspective ρd onto a regular grid of the sample plane (module docstring).

    Parameters
    ----------
    rho_d
        ``(H, W, 3)`` ρd in the camera's image (``camera.image_size``), NaN where unmeasured.
    camera
        The capture's `Camera`.
    box
        ``(x_min, x_max, y_min, y_max)`` (mm) of the grid; default the
        bounding box of the measured pixels on the plane.
    pixel_mm
        Grid pixel side (mm); default the camera pixels' median footprint on
        the probe, to 3 significant digits.
    max_side
        Largest grid side (pixels); a larger grid gets a larger pixel.
    band_rows
        Grid rows resampled at a time (bounds the working memory).

    Returns
    -------
    PlaneTexture
    """
    rho_d = np.asarray(rho_d)
    if rho_d.ndim != 3 or rho_d.shape[-1] != 3:
        raise ValueError(f"rho_d must be (H, W, 3), got shape {rho_d.shape}")
    if rho_d.shape[:2] != (camera.height, camera.width):
        raise ValueError(
            f"rho_d is {rho_d.shape[1]}×{rho_d.shape[0]} pixels but the camera's image is "
            f"{camera.width}×{camera.height}"
        )
    if box is None or pixel_mm is None:
        auto_box, foot = _footprint_mm(camera, rho_d, band_rows)
    else:
        auto_box, foot = np.asarray(box, np.float64), 0.0
    x0, x1, y0, y1 = (float(v) for v in (box if box is not None else auto_box))
    if not (x1 > x0 and y1 > y0):
        raise ValueError(f"the grid's box (x {x0}…{x1}, y {y0}…{y1} mm) is empty")
    s = float(pixel_mm) if pixel_mm is not None else _round_sig(foot)
    if not s > 0:
        raise ValueError(f"pixel_mm must be > 0, got {s}")
    s = max(s, _round_sig(max(x1 - x0, y1 - y0) / max_side * 1.001))
    w, h = max(1, int(np.ceil((x1 - x0) / s))), max(1, int(np.ceil((y1 - y0) / s)))
    out = np.full((h, w, 3), np.nan, np.float32)
    hi, wi = rho_d.shape[:2]
    xs = x0 + (np.arange(w) + 0.5) * s
    for r0 in range(0, h, band_rows):
        ys = y1 - (np.arange(r0, min(r0 + band_rows, h)) + 0.5) * s
        pts = np.stack(np.broadcast_arrays(xs[None, :], ys[:, None], 0.0), -1)
        uv, front = project(camera, pts)
        u, v = uv[..., 0], uv[..., 1]
        ok = front & np.isfinite(u) & np.isfinite(v) & (u >= 0) & (v >= 0) & (u <= wi - 1) & (v <= hi - 1)
        u, v = np.where(ok, u, 0.0), np.where(ok, v, 0.0)
        iu, iv = np.minimum(np.floor(u).astype(np.int64), wi - 2), np.minimum(np.floor(v).astype(np.int64), hi - 2)
        iu, iv = np.maximum(iu, 0), np.maximum(iv, 0)
        fu, fv = (u - iu)[..., None], (v - iv)[..., None]
        val = (
            rho_d[iv, iu] * (1 - fu) * (1 - fv)
            + rho_d[iv, iu + 1] * fu * (1 - fv)
            + rho_d[iv + 1, iu] * (1 - fu) * fv
            + rho_d[iv + 1, iu + 1] * fu * fv
        )
        out[r0 : r0 + len(ys)] = np.where(ok[..., None], val, np.nan)
    mask = np.all(np.isfinite(out), axis=-1)
    out[~mask] = np.nan
    return PlaneTexture(rho_d=out, mask=mask, pixel_mm=s, origin_mm=(x0, y1))


def write_exr(path, rgb: np.ndarray, *, pixel_mm: float, attributes: dict | None = None) -> None:
    """Write ``(H, W, 3)`` float32 RGB as an OpenEXR file (ZIP, scanlines), atomically.

    The pixel size goes into the standard ``xDensity`` attribute (pixels per
    inch, ``25.4 / pixel_mm``) and into ``wardjaxPixelSizeMm``; ``attributes``
    (JSON-able) into the string attribute ``wardjax`` (JSON).
    """
    import OpenEXR

    header = {
        "compression": OpenEXR.ZIP_COMPRESSION,
        "type": OpenEXR.scanlineimage,
        "xDensity": 25.4 / float(pixel_mm),
        "wardjaxPixelSizeMm": float(pixel_mm),
        "wardjax": json.dumps(attributes or {}, sort_keys=True),
    }
    with atomic_path(path) as tmp, OpenEXR.File(header, {"RGB": np.ascontiguousarray(rgb, np.float32)}) as f:
        f.write(str(tmp))


def read_exr(path) -> tuple[np.ndarray, dict]:
    """An EXR written by `write_exr`: ``(H, W, 3)`` float32 RGB and its header (``wardjax`` parsed)."""
    import OpenEXR

    with OpenEXR.File(str(path)) as f:
        header = dict(f.header())
        rgb = np.asarray(f.channels()["RGB"].pixels, np.float32)
    if isinstance(header.get("wardjax"), str):
        header["wardjax"] = json.loads(header["wardjax"])
    return rgb, header


def write_plane_texture(out_dir, tex: PlaneTexture, *, fill, extra: dict | None = None) -> dict:
    """``rho_d_plane.exr``, ``rho_d_plane.tif`` and ``rho_d_plane_mask.png`` in ``out_dir``; their names.

    Where the map is not measured the files hold ``fill`` (the fit's ρd), so a
    renderer sees a finite texture; the mask (255 measured, 0 filled) tells
    the two apart. The TIFF carries the pixel size as its resolution
    (pixels per centimetre) and the metadata as JSON in its description.
    """
    import tifffile

    out = Path(out_dir)
    meta = tex.metadata() | (extra or {})
    rgb = np.where(tex.mask[..., None], tex.rho_d, np.asarray(fill, np.float32)).astype(np.float32)
    write_exr(out / "rho_d_plane.exr", rgb, pixel_mm=tex.pixel_mm, attributes=meta)
    res = 10.0 / tex.pixel_mm
    with atomic_path(out / "rho_d_plane.tif") as fh:
        tifffile.imwrite(
            fh,
            rgb,
            photometric="rgb",
            resolution=(res, res),
            resolutionunit="CENTIMETER",
            description=json.dumps(meta, sort_keys=True),
            metadata=None,
        )
    write_image(out / "rho_d_plane_mask.png", (tex.mask * np.uint8(255)).astype(np.uint8))
    return {"exr": "rho_d_plane.exr", "tiff": "rho_d_plane.tif", "mask": "rho_d_plane_mask.png"}
