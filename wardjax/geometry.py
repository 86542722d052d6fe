"""The rig of the image-based method: pinhole camera, lamp, sample plane, mirror points.

Image-based paper, section 3 and Fig. 2. The sample lies in the plane
``z = 0`` (millimetres, z up). The stripline between probe and reference
standard runs along ``y``; the probe lies at ``x > 0``, the standard at
``x < 0``; lamp and camera lie in the plane ``x = 0``, which is orthogonal to
the sample plane. The lamp's radiation being symmetric about that plane, a
probe point ``P = (x, y, 0)`` and its mirror point ``P' = (−x, y, 0)`` on the
standard receive the same irradiance — the symmetry the reconstruction
``f_r = (v − v_bg)/(v_std − v_std_bg) · ρ_std/π`` relies on.

Camera: an ideal pinhole with pixel centres at integer coordinates ``(u, v)``
(``u`` the column, ``v`` the row, row 0 at the top). The camera frame is
built from its position ``C``, the point it looks at and an ``up`` hint::

    forward = normalise(look_at − C)
    right   = normalise(forward × up)
    down    = forward × right

A pixel's ray is ``d = right · (u − cx)/fx + down · (v − cy)/fy + forward``
and it meets the sample plane at ``P = C − (C_z / d_z) d`` (in front of the
camera only when ``d_z < 0``). With the camera in the plane ``x = 0``, the
default ``up = z`` and the principal point on the image's centre column, the
mirror pixel of column ``u`` is column ``2 cx − u``.
"""

from __future__ import annotations

import dataclasses
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

__all__ = [
    "BandGeometry",
    "Camera",
    "PixelGeometry",
    "Rig",
    "back_project",
    "in_box",
    "irradiance_factor",
    "mirror_point",
    "pixel_geometry",
    "project",
    "to_material_frame",
]


def _vec(x, n: int = 3) -> np.ndarray:
    a = np.asarray(x, dtype=np.float64)
    if a.shape != (n,):
        raise ValueError(f"expected {n} numbers, got shape {a.shape}")
    return a


@dataclasses.dataclass(frozen=True)
class Camera:
    """A pinhole camera looking at the sample plane.

    Parameters
    ----------
    position
        Centre of projection ``(x, y, z)`` in mm, ``z > 0``.
    look_at
        A point (mm) on the optical axis.
    focal_px
        Focal length in pixels, ``f`` or ``(fx, fy)``.
    image_size
        ``(width, height)`` in pixels.
    principal_point
        ``(cx, cy)`` in pixels; default the image centre ``((W−1)/2, (H−1)/2)``.
    up
        A direction that is "up" in the image (not parallel to the optical
        axis); default ``z``.
    """

    position: tuple[float, float, float]
    look_at: tuple[float, float, float]
    focal_px: float | tuple[float, float]
    image_size: tuple[int, int]
    principal_point: tuple[float, float] | None = None
    up: tuple[float, float, float] = (0.0, 0.0, 1.0)

    @property
    def width(self) -> int:
        return int(self.image_size[0])

    @property
    def height(self) -> int:
        return int(self.image_size[1])

    @property
    def focal(self) -> tuple[float, float]:
        f = np.atleast_1d(np.asarray(self.focal_px, dtype=np.float64))
        return (float(f[0]), float(f[-1]))

    @property
    def principal(self) -> tuple[float, float]:
        if self.principal_point is None:
            return ((self.width - 1) / 2.0, (self.height - 1) / 2.0)
        return (float(self.principal_point[0]), float(self.principal_point[1]))

    def axes(self) -> np.ndarray:
        """``(3, 3)`` rows ``right, down, forward`` (world coordinates, unit length)."""
        c = _vec(self.position)
        fwd = _vec(self.look_at) - c
        n = np.linalg.norm(fwd)
        if not n > 0:
            raise ValueError("camera look_at coincides with its position")
        fwd = fwd / n
        right = np.cross(fwd, _vec(self.up))
        nr = np.linalg.norm(right)
        if not nr > 1e-9:
            raise ValueError("camera up is parallel to the optical axis")
        right = right / nr
        down = np.cross(fwd, right)
        return np.stack([right, down, fwd])


@dataclasses.dataclass(frozen=True)
class Rig:
    """Lamp, camera and the extents of probe and standard on the sample plane.

    Parameters
    ----------
    lamp
        Lamp position (mm), in the plane ``x = 0``, ``z > 0``.
    camera
        The :class:`Camera`.
    probe, standard
        ``(x_min, x_max, y_min, y_max)`` rectangles (mm) on ``z = 0``; the
        probe at ``x > 0``, the standard at ``x < 0``. ``None`` means the whole
        half-plane.
    """

    lamp: tuple[float, float, float]
    camera: Camera
    probe: tuple[float, float, float, float] | None = None
    standard: tuple[float, float, float, float] | None = None

    def probe_box(self) -> tuple[float, float, float, float]:
        return (*self.probe,) if self.probe is not None else (0.0, np.inf, -np.inf, np.inf)

    def standard_box(self) -> tuple[float, float, float, float]:
        return (*self.standard,) if self.standard is not None else (-np.inf, 0.0, -np.inf, np.inf)


def in_box(points: np.ndarray, box) -> np.ndarray:
    """True where ``points[..., :2]`` lie in ``box = (x_min, x_max, y_min, y_max)`` (closed)."""
    x, y = points[..., 0], points[..., 1]
    x0, x1, y0, y1 = box
    with np.errstate(invalid="ignore"):
        return (x >= x0) & (x <= x1) & (y >= y0) & (y <= y1)


def back_project(camera: Camera, u, v) -> tuple[np.ndarray, np.ndarray | np.bool_]:
    """Points where the rays of pixels ``(u, v)`` meet the sample plane ``z = 0``.

    Returns
    -------
    points
        ``(..., 3)`` in mm (z exactly 0); NaN where the ray misses the plane.
    hit
        ``(...)`` True where the ray meets the plane in front of the camera.
    """
    right, down, fwd = camera.axes()
    fx, fy = camera.focal
    cx, cy = camera.principal
    a = (np.asarray(u, np.float64) - cx) / fx
    b = (np.asarray(v, np.float64) - cy) / fy
    d = a[..., None] * right + b[..., None] * down + fwd
    c = _vec(camera.position)
    dz = d[..., 2]
    hit = dz < -1e-12
    t = np.where(hit, -c[2] / np.where(hit, dz, -1.0), np.nan)
    pts = c + t[..., None] * d
    pts[..., 2] = np.where(hit, 0.0, np.nan)
    return pts, hit


def project(camera: Camera, points) -> tuple[np.ndarray, np.ndarray]:
    """Pixel coordinates ``(..., 2)`` = ``(u, v)`` of world points; ``in_front`` mask."""
    axes = camera.axes()
    rel = np.asarray(points, np.float64) - _vec(camera.position)
    cam = rel @ axes.T  # (..., 3): right, down, forward components
    z = cam[..., 2]
    in_front = z > 1e-9
    zs = np.where(in_front, z, np.nan)
    fx, fy = camera.focal
    cx, cy = camera.principal
    uv = np.stack([cx + fx * cam[..., 0] / zs, cy + fy * cam[..., 1] / zs], -1)
    return uv, in_front


def mirror_point(points) -> np.ndarray:
    """The mirror of sample points in the plane ``x = 0``: ``(x, y, z) → (−x, y, z)``."""
    p = np.array(points, dtype=np.float64, copy=True)
    p[..., 0] = -p[..., 0]
    return p


def irradiance_factor(points, lamp) -> np.ndarray:
    """Irradiance of a unit-intensity point lamp on the plane ``z = 0`` (mm⁻²).

    ``E = cos θi / r² = z_L / r³`` with ``r`` the lamp distance. It is the
    same at a point and at its mirror point, which is why it cancels in the
    reconstruction ratio.
    """
    lamp = _vec(lamp)
    r = np.linalg.norm(lamp - np.asarray(points, np.float64), axis=-1)
    return lamp[2] / r**3


def to_material_frame(w, tangent) -> np.ndarray:
    """Express sample-frame directions in the material frame (x = tangent, z = normal).

    ``tangent`` is a direction ``(tx, ty)`` in the sample plane; the
    material's ``y`` axis is ``z × tangent``.
    """
    t = np.asarray(tangent, np.float64)
    t = t / np.linalg.norm(t)
    w = np.asarray(w)
    if t[0] == 1.0 and t[1] == 0.0:
        return w
    x = w[..., 0] * t[0] + w[..., 1] * t[1]
    y = -w[..., 0] * t[1] + w[..., 1] * t[0]
    return np.stack([x, y, w[..., 2]], -1).astype(w.dtype, copy=False)


class PixelGeometry(NamedTuple):
    """What the method needs to know about each pixel.

    Attributes
    ----------
    points
        ``(..., 3)`` the pixel's point on the sample plane (mm); NaN if the ray misses.
    wi, wo
        ``(..., 3)`` unit directions to lamp and camera, sample frame.
    dist_lamp, dist_camera
        ``(...)`` distances (mm).
    irradiance
        ``(...)`` :func:`irradiance_factor` (mm⁻²).
    in_probe, in_standard
        ``(...)`` the point lies on the probe / the standard.
    mirror_points
        ``(..., 3)`` :func:`mirror_point` of ``points``.
    mirror_pixels
        ``(..., 2)`` pixel ``(u, v)`` of the mirror point.
    mirror_ok
        ``(...)`` the mirror point lies on the standard and its pixel inside
        the image (bilinear interpolation needs its 2×2 neighbours).
    """

    points: np.ndarray
    wi: np.ndarray
    wo: np.ndarray
    dist_lamp: np.ndarray
    dist_camera: np.ndarray
    irradiance: np.ndarray
    in_probe: np.ndarray
    in_standard: np.ndarray
    mirror_points: np.ndarray
    mirror_pixels: np.ndarray
    mirror_ok: np.ndarray


def pixel_geometry(rig: Rig, u, v) -> PixelGeometry:
    """Back-project pixels ``(u, v)`` and compute directions, distances, mirror pixels.

    Parameters
    ----------
    rig
        The :class:`Rig`.
    u, v
        Pixel column and row coordinates, any matching shape.
    """
    cam = rig.camera
    pts, hit = back_project(cam, u, v)
    lamp = _vec(rig.lamp)
    c = _vec(cam.position)
    to_l = lamp - pts
    to_c = c - pts
    dl = np.linalg.norm(to_l, axis=-1)
    dc = np.linalg.norm(to_c, axis=-1)
    wi = to_l / dl[..., None]
    wo = to_c / dc[..., None]
    irr = lamp[2] / dl**3
    in_probe = hit & in_box(pts, rig.probe_box())
    in_std = hit & in_box(pts, rig.standard_box())
    mp = mirror_point(pts)
    muv, front = project(cam, mp)
    with np.errstate(invalid="ignore"):
        inside = (
            (muv[..., 0] >= 0) & (muv[..., 0] <= cam.width - 1) & (muv[..., 1] >= 0) & (muv[..., 1] <= cam.height - 1)
        )
    mirror_ok = hit & front & inside & in_box(mp, rig.standard_box())
    return PixelGeometry(pts, wi, wo, dl, dc, irr, in_probe, in_std, mp, muv, mirror_ok)


class BandGeometry(NamedTuple):
    """:func:`band_geometry_jnp` of a band of image rows, ``(B, W, …)`` arrays.

    Attributes
    ----------
    points
        ``(B, W, 3)`` the pixel's point on the sample plane (mm); NaN if the ray misses.
    wi, wo
        ``(B, W, 3)`` unit directions to lamp and camera in the material frame
        (x = ``tangent``); 0 where the ray misses.
    in_probe, in_standard
        ``(B, W)`` the point lies on the probe / the standard.
    mirror_pixels
        ``(B, W, 2)`` pixel ``(u, v)`` of the mirror point; NaN where undefined.
    mirror_ok
        ``(B, W)`` as :attr:`PixelGeometry.mirror_ok`.
    """

    points: jax.Array
    wi: jax.Array
    wo: jax.Array
    in_probe: jax.Array
    in_standard: jax.Array
    mirror_pixels: jax.Array
    mirror_ok: jax.Array


def rig_constants(rig: Rig, tangent) -> np.ndarray:
    """The rig as one float64 vector for the compiled kernel (29 numbers)."""
    cam = rig.camera
    t = np.asarray(tangent, np.float64)
    t = t / np.linalg.norm(t)
    return np.concatenate(
        [
            cam.axes().ravel(),
            _vec(cam.position),
            cam.focal,
            cam.principal,
            _vec(rig.lamp),
            rig.probe_box(),
            rig.standard_box(),
            t,
        ]
    )


def _jnp_in_box(x, y, box):
    return (x >= box[0]) & (x <= box[1]) & (y >= box[2]) & (y <= box[3])


def band_geometry_jnp(k, rows, *, width: int, height: int, col0=0, ncols: int | None = None):
    """:func:`pixel_geometry` + :func:`to_material_frame` of whole rows in ``jnp`` (traceable; dtype of ``k``).

    ``k`` is :func:`rig_constants`; returns the :class:`BandGeometry` of image
    columns ``col0 … col0 + ncols − 1`` (default all ``width``) of ``rows``.
    Same mathematics as :func:`pixel_geometry` (the float64 reference, tested
    equal), with the directions in the material frame of the tangent in
    ``k``; in float32 the points are good to ~10⁻⁴ mm and the mirror pixels
    to ~10⁻⁴ px. The capture pipeline fuses it into its compiled kernels.
    """
    # Planar: every quantity is a (B, W) plane per component (vectorises; no size-3 axes until the end).
    ax = [[k[3 * i + j] for j in range(3)] for i in range(3)]  # rows right, down, forward
    c = [k[9], k[10], k[11]]
    fx, fy, cx, cy = k[12], k[13], k[14], k[15]
    lamp, probe, std, t = k[16:19], k[19:23], k[23:27], k[27:29]
    ncols = width if ncols is None else ncols
    shape = (rows.shape[0], ncols)
    u = jnp.broadcast_to((jnp.arange(ncols, dtype=k.dtype) + jnp.asarray(col0, k.dtype))[None, :], shape)
    v = jnp.broadcast_to(rows.astype(k.dtype)[:, None], shape)
    a = (u - cx) / fx
    b = (v - cy) / fy
    dx, dy, dz = (a * ax[0][j] + b * ax[1][j] + ax[2][j] for j in range(3))
    hit = dz < -1e-12
    s = jnp.where(hit, -c[2] / jnp.where(hit, dz, -1.0), jnp.nan)
    x = c[0] + s * dx
    y = c[1] + s * dy
    pts = jnp.stack([x, y, jnp.where(hit, 0.0, jnp.nan).astype(k.dtype)], -1)

    def unit_to_material(ex, ey, ez):
        inv = 1.0 / jnp.sqrt(ex * ex + ey * ey + ez * ez)
        ex, ey, ez = ex * inv, ey * inv, ez * inv
        w = jnp.stack([ex * t[0] + ey * t[1], -ex * t[1] + ey * t[0], ez], -1)
        return jnp.where(hit[..., None], w, 0.0)

    wi = unit_to_material(lamp[0] - x, lamp[1] - y, jnp.broadcast_to(lamp[2], shape))
    wo = unit_to_material(c[0] - x, c[1] - y, jnp.broadcast_to(c[2], shape))
    in_probe = hit & _jnp_in_box(x, y, probe)
    in_std = hit & _jnp_in_box(x, y, std)
    rx, ry, rz = -x - c[0], y - c[1], -c[2]  # mirror point − camera
    cam_x, cam_y, z = (ax[i][0] * rx + ax[i][1] * ry + ax[i][2] * rz for i in range(3))
    front = z > 1e-9
    zs = jnp.where(front, z, jnp.nan)
    mu = cx + fx * cam_x / zs
    mv = cy + fy * cam_y / zs
    inside = (mu >= 0) & (mu <= width - 1) & (mv >= 0) & (mv <= height - 1)
    mirror_ok = hit & front & inside & _jnp_in_box(-x, y, std)
    return BandGeometry(pts, wi, wo, in_probe, in_std, jnp.stack([mu, mv], -1), mirror_ok)
