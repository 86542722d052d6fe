"""The two validation scenes of the smartphone paper as data both renderers read: light sources and a camera.

**(b) A sphere under an environment** (the paper's Fig. 11). The environment is
a grey radiance map over directions, cut into ``n_theta × n_phi`` latitude–
longitude cells; every cell becomes one *distant* source (Radiance ``source``)
in the cell's centre direction, with the cell's solid angle

.. math::

    ω_k = Δφ\\,(\\cos θ_0 - \\cos θ_1), \\qquad
    \\text{cone angle } a_k = 2\\arccos(1 - ω_k / 2π)

(Radiance gives a ``source`` of angle ``a`` the solid angle ``2π(1 − cos a/2)``)
and the cell's mean radiance.

**(c) A phone screen reflected in a flat sample at 45°** (Figs. 7, 9, 10). The
sample lies on ``z = 0``; the phone stands on it leaning over the sample, its
screen at ``45°`` to the sample normal and facing it; the eye looks at the
sample from ``45°`` at ``eye_to_surface`` mm, on the far side, so the mirror
direction at the sample's centre meets the screen head-on (the paper's
set-up: 18 in to the sample, 19.1 in to the reflected screen). The screen
image (pixels of ``pixel_pitch`` mm, values 0–1 of the range between the
screen's black and white luminance) is cut into square cells of ``cell_px``
screen pixels; each cell is one flat rectangular source (a Radiance ``light``
polygon) with the cell's mean radiance, optionally emitting more along the
screen normal, ``L(θe) = L cos^m θe``. A flat source of area ``A`` seen from
distance ``d`` at ``θs`` from its normal has ``ω = A cos θs / d²``.

Luminance and radiance: Radiance's white-light efficacy is 179 lm/W, so a
screen luminance of ``Y`` cd/m² is a radiance of ``Y/179`` W sr⁻¹ m⁻², and a
render's luminance is 179 times its (grey) radiance.

Both renderers then compute, per pixel, the same sum over sources,
``Σ_k L_k ω_k cos θ_i f_r``, with the lobe widened by each source's size
(``a² = α² + ω_k/4π``, Radiance's rule). The sum tends to the integral over
the environment (the screen) as the cells shrink.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from typing import NamedTuple

import numpy as np

from ..geometry import Camera

__all__ = [
    "LUMINOUS_EFFICACY",
    "DistantSources",
    "PhoneScene",
    "ScreenSources",
    "camera_rays",
    "environment_sources",
    "phone_scene",
    "square_wave",
    "sky_environment",
]

LUMINOUS_EFFICACY = 179.0  # lm/W: Radiance's white-light efficacy (luminance = 179 × grey radiance)


class DistantSources(NamedTuple):
    """Distant light sources (an environment): unit directions ``(K, 3)``, solid angles and grey radiances ``(K,)``."""

    direction: np.ndarray
    solid_angle: np.ndarray
    radiance: np.ndarray


class ScreenSources(NamedTuple):
    """Flat rectangular sources (a screen's cells).

    Attributes
    ----------
    centre
        ``(K, 3)`` cell centres (mm).
    half_u, half_v
        ``(K, 3)`` half edge vectors; ``half_u × half_v`` points along the emitting normal.
    radiance
        ``(K,)`` grey radiance along the normal.
    normal
        ``(3,)`` the emitting side's unit normal.
    exponent
        ``m`` of the directional emission ``cos^m θe`` (0: a Lambertian screen).
    """

    centre: np.ndarray
    half_u: np.ndarray
    half_v: np.ndarray
    radiance: np.ndarray
    normal: np.ndarray
    exponent: float


def camera_rays(camera: Camera) -> tuple[np.ndarray, np.ndarray]:
    """Unit ray directions ``(H, W, 3)`` through the pixel centres of a pinhole camera, and its centre ``(3,)``."""
    right, down, fwd = camera.axes()
    fx, fy = camera.focal
    cx, cy = camera.principal
    u, v = np.meshgrid(np.arange(camera.width, dtype=np.float64), np.arange(camera.height, dtype=np.float64))
    d = ((u - cx) / fx)[..., None] * right + ((v - cy) / fy)[..., None] * down + fwd
    d /= np.linalg.norm(d, axis=-1, keepdims=True)
    return d, np.asarray(camera.position, np.float64)


def sky_environment(direction: np.ndarray) -> np.ndarray:
    """A grey analytic environment (radiance per unit): a bright sky over a dark ground, a window and a lamp.

    Sky ``0.4 + 0.6 cos θ`` above the horizon, ground ``0.1``, a rectangular
    "window" of radiance 3 (azimuth 20–60°, elevation 10–40°) and a small
    "lamp" of radiance 8 within 12° of ``(−0.5, −0.6, 0.62)``: sharp features
    so that gloss shows, smooth regions so that the diffuse term does.
    """
    d = np.asarray(direction, np.float64)
    z = d[..., 2]
    el = np.degrees(np.arcsin(np.clip(z, -1, 1)))
    az = np.degrees(np.arctan2(d[..., 1], d[..., 0]))
    out = np.where(z > 0, 0.4 + 0.6 * z, 0.1)
    out = np.where((az > 20) & (az < 60) & (el > 10) & (el < 40), 3.0, out)
    lamp = np.array([-0.5, -0.6, 0.62])
    lamp /= np.linalg.norm(lamp)
    return np.where(d @ lamp > np.cos(np.radians(12.0)), 8.0, out)


def environment_sources(
    environment: Callable[[np.ndarray], np.ndarray] | np.ndarray,
    n_theta: int = 12,
    n_phi: int = 24,
    *,
    supersample: int = 4,
) -> DistantSources:
    """Cut a grey environment into ``n_theta × n_phi`` latitude–longitude cells, one distant source each.

    Parameters
    ----------
    environment
        A callable ``direction (..., 3) → radiance (...)`` (averaged over
        ``supersample²`` points per cell) or an ``(n_theta, n_phi)`` array of
        cell radiances (rows from the zenith ``+z`` down, columns from azimuth 0).
    n_theta, n_phi
        Cells in polar angle and azimuth (ignored for an array).
    supersample
        Points per cell side when ``environment`` is a callable.

    Returns
    -------
    DistantSources
        Cells of zero radiance are left out.
    """
    if callable(environment):
        s = int(supersample)
        t = (np.arange(n_theta * s) + 0.5) / (n_theta * s) * np.pi
        p = (np.arange(n_phi * s) + 0.5) / (n_phi * s) * 2 * np.pi
        tt, pp = np.meshgrid(t, p, indexing="ij")
        d = np.stack([np.sin(tt) * np.cos(pp), np.sin(tt) * np.sin(pp), np.cos(tt)], -1)
        w = np.sin(tt)  # solid-angle weight within a cell
        v = np.asarray(environment(d), np.float64)
        num = (v * w).reshape(n_theta, s, n_phi, s).sum((1, 3))
        radiance = num / w.reshape(n_theta, s, n_phi, s).sum((1, 3))
    else:
        radiance = np.asarray(environment, np.float64)
        if radiance.ndim != 2:
            raise ValueError(f"environment: expected an (n_theta, n_phi) map, got shape {radiance.shape}")
        n_theta, n_phi = radiance.shape
    t0 = np.arange(n_theta) / n_theta * np.pi
    t1 = t0 + np.pi / n_theta
    tc = 0.5 * (t0 + t1)
    pc = (np.arange(n_phi) + 0.5) / n_phi * 2 * np.pi
    tt, pp = np.meshgrid(tc, pc, indexing="ij")
    d = np.stack([np.sin(tt) * np.cos(pp), np.sin(tt) * np.sin(pp), np.cos(tt)], -1)
    omega = np.broadcast_to(((np.cos(t0) - np.cos(t1)) * 2 * np.pi / n_phi)[:, None], tt.shape)
    keep = radiance > 0
    return DistantSources(d[keep], omega[keep].copy(), radiance[keep])


def square_wave(ppb: int, width_px: int, height_px: int, *, angle_deg: float = 0.0, supersample: int = 4) -> np.ndarray:
    """A white/black square-wave grating of ``ppb`` pixels per bar, bars tilted ``angle_deg`` from the screen's
    vertical, as pixel coverage ``(height_px, width_px)`` in [0, 1] (each pixel the mean of ``supersample²`` points;
    ``angle_deg = 0``: :func:`wardjax.smartphone.grating_image` / 255)."""
    s = int(supersample)
    off = (np.arange(s) + 0.5) / s - 0.5
    x = (np.arange(width_px)[:, None] + 0.5 + off[None, :]).ravel()
    y = (np.arange(height_px)[:, None] + 0.5 + off[None, :]).ravel()
    a = math.radians(angle_deg)
    u = x[None, :] * math.cos(a) + y[:, None] * math.sin(a)
    bars = (np.floor(u / ppb) % 2 == 0).astype(np.float64)
    return bars.reshape(height_px, s, width_px, s).mean((1, 3))


@dataclasses.dataclass(frozen=True)
class PhoneScene:
    """Scene (c): a flat sample on ``z = 0`` reflecting a phone screen; see the module docstring.

    Attributes
    ----------
    camera
        The eye (a :class:`~wardjax.geometry.Camera`).
    sources
        The screen's cells (:class:`ScreenSources`).
    sample_box
        ``(x_min, x_max, y_min, y_max)`` of the sample on ``z = 0`` (mm).
    screen_origin, screen_u, screen_v
        The screen's corner at the sample (mm) and its full edge vectors (width along ``u``, length along ``v``).
    """

    camera: Camera
    sources: ScreenSources
    sample_box: tuple[float, float, float, float]
    screen_origin: tuple[float, float, float]
    screen_u: tuple[float, float, float]
    screen_v: tuple[float, float, float]


def _cells(image: np.ndarray, cell_px: int) -> np.ndarray:
    """Mean of each ``cell_px × cell_px`` block (partial blocks at the far edges averaged over what they hold)."""
    h, w = image.shape
    ny, nx = -(-h // cell_px), -(-w // cell_px)
    pad = np.full((ny * cell_px, nx * cell_px), np.nan)
    pad[:h, :w] = image
    return np.nanmean(pad.reshape(ny, cell_px, nx, cell_px), axis=(1, 3))


def phone_scene(
    image: np.ndarray,
    *,
    pixel_pitch: float = 25.4 / 326.0,
    luminance: tuple[float, float] = (0.5, 505.5),
    cell_px: int = 16,
    exponent: float = 0.0,
    eye_to_surface: float = 18.0 * 25.4,
    eye_to_screen: float = 19.1 * 25.4,
    size: tuple[int, int] = (64, 64),
    fov_deg: float = 4.0,
    look_at: tuple[float, float, float] | None = None,
) -> PhoneScene:
    """Build scene (c): the screen showing ``image``, reflected in a sample viewed at 45°.

    Parameters
    ----------
    image
        ``(H_s, W_s)`` screen pixel values in [0, 1] (0: black, 1: white), row 0
        at the phone's top (the edge away from the sample), e.g. :func:`square_wave`.
    pixel_pitch
        Screen pixel pitch (mm); default the iPhone 5s (326 ppi).
    luminance
        The screen's black and white luminance (cd/m²); default the paper's 0.5 and 505.5.
    cell_px
        Screen pixels per source cell side.
    exponent
        Directional emission ``cos^m θe`` (0: Lambertian).
    eye_to_surface, eye_to_screen
        Eye to the sample point at the view centre, and to the screen along the mirror ray (mm; the paper's 18 and
        19.1 in): the screen's centre line meets the mirror ray at ``eye_to_screen − eye_to_surface`` from the sample.
    size, fov_deg
        The eye camera's ``(width, height)`` in pixels and horizontal field of view (degrees).
    look_at
        The camera's aim on the sample; default where the mirror ray from the screen's centre meets it.
    """
    img = np.asarray(image, np.float64)
    if img.ndim != 2 or not np.all(np.isfinite(img)):
        raise ValueError(f"phone_scene: expected a finite (H, W) screen image, got shape {img.shape}")
    if not eye_to_screen > eye_to_surface > 0:
        raise ValueError("phone_scene: need eye_to_screen > eye_to_surface > 0")
    c45 = math.sqrt(0.5)
    eye = np.array([0.0, -eye_to_surface * c45, eye_to_surface * c45])
    hit = (eye_to_screen - eye_to_surface) * np.array([0.0, c45, c45])  # the mirror ray meets the screen here
    normal = np.array([0.0, -c45, -c45])  # the screen faces the sample
    y0 = hit[1] + hit[2]  # the screen plane y + z = y0 meets the sample at y = y0
    hs, ws = img.shape
    length, width = hs * pixel_pitch, ws * pixel_pitch
    up = np.array([0.0, -c45, c45])  # along the screen from its bottom edge (at the sample) to its top
    origin = np.array([-width / 2, y0, 0.0])
    u_axis, v_axis = np.array([1.0, 0.0, 0.0]), up
    cells = _cells(img, int(cell_px))
    ny, nx = cells.shape
    lo, hi = (float(v) / LUMINOUS_EFFICACY for v in luminance)
    radiance = lo + (hi - lo) * np.clip(cells, 0, 1)
    # Cell (i, j): screen rows from the top; the top edge is at v = length.
    js, is_ = np.meshgrid(np.arange(nx), np.arange(ny))
    u0 = js * cell_px * pixel_pitch
    u1 = np.minimum(u0 + cell_px * pixel_pitch, width)
    v1 = length - is_ * cell_px * pixel_pitch
    v0 = np.maximum(v1 - cell_px * pixel_pitch, 0.0)
    centre = origin + ((u0 + u1) / 2)[..., None] * u_axis + ((v0 + v1) / 2)[..., None] * v_axis
    # half_u × half_v points along the emitting normal (Radiance: counter-clockwise seen from the front).
    hu = ((u1 - u0) / 2)[..., None] * u_axis
    hv = ((v1 - v0) / 2)[..., None] * v_axis
    if np.dot(np.cross(u_axis, v_axis), normal) < 0:
        hu = -hu
    sources = ScreenSources(
        centre.reshape(-1, 3), hu.reshape(-1, 3), hv.reshape(-1, 3), radiance.ravel(), normal, float(exponent)
    )
    if look_at is None:
        centre_pt = origin + width / 2 * u_axis + length / 2 * v_axis
        mirror = centre_pt * np.array([1.0, 1.0, -1.0])
        aim = eye + eye[2] / (eye[2] - mirror[2]) * (mirror - eye)
    else:
        aim = np.asarray(look_at, np.float64)
    w, h = (int(v) for v in size)
    f = (w / 2) / math.tan(math.radians(fov_deg) / 2)
    ex, ey, ez = (float(c) for c in eye)
    ax, ay, az = (float(c) for c in aim)
    cam = Camera(position=(ex, ey, ez), look_at=(ax, ay, az), focal_px=f, image_size=(w, h), up=(0.0, 1.0, 0.0))
    box = (-width / 2 - 20.0, width / 2 + 20.0, -200.0, float(y0))
    return PhoneScene(cam, sources, box, tuple(origin), tuple(width * u_axis), tuple(length * v_axis))
