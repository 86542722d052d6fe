"""Forward models that make synthetic data: scanlines in the papers' rig.

The rig (image-based paper, Fig. 2): the sample lies in the plane z = 0; lamp
and camera are in the plane x = 0, which contains the normal; a scanline is a
line of sample points ``(x₀, y, 0)`` along y. At ``x₀ = 0`` the scanline
passes through the mirror point, where the half vector is the normal; at
``x₀ ≠ 0`` the half vector tilts towards x, which is what makes αx visible at
all. Lengths are in millimetres.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ..ward import WardParams
from ._forward import ward_values

__all__ = [
    "ScanlineData",
    "ScanlineRig",
    "scanline_directions",
    "scanline_positions",
    "simulate_scanlines",
    "x_offset_for_slope",
]


class ScanlineRig(NamedTuple):
    """Lamp and camera positions (mm) in the plane x = 0.

    Attributes
    ----------
    lamp, camera
        ``(..., 3)`` positions; ``x`` must be 0 for the papers' symmetry.
    """

    lamp: np.ndarray
    camera: np.ndarray

    @classmethod
    def from_angles(
        cls,
        lamp_distance: float = 600.0,
        lamp_angle_deg: float = 25.0,
        camera_distance: float = 700.0,
        camera_angle_deg: float = 25.0,
    ) -> ScanlineRig:
        """Lamp on the +y side, camera on the −y side, angles from the normal."""
        tl, tc = np.deg2rad(lamp_angle_deg), np.deg2rad(camera_angle_deg)
        lamp = np.array([0.0, lamp_distance * np.sin(tl), lamp_distance * np.cos(tl)])
        camera = np.array([0.0, -camera_distance * np.sin(tc), camera_distance * np.cos(tc)])
        return cls(lamp, camera)

    @classmethod
    def random(cls, n: int, rng: np.random.Generator) -> ScanlineRig:
        """``n`` rigs with lamp and camera 400–900 mm away at 15–40° (the papers' range)."""
        dl, dc = rng.uniform(400, 900, n), rng.uniform(400, 900, n)
        tl, tc = np.deg2rad(rng.uniform(15, 40, n)), np.deg2rad(rng.uniform(15, 40, n))
        lamp = np.stack([np.zeros(n), dl * np.sin(tl), dl * np.cos(tl)], -1)
        camera = np.stack([np.zeros(n), -dc * np.sin(tc), dc * np.cos(tc)], -1)
        return cls(lamp, camera)

    def mirror_y(self) -> np.ndarray:
        """y of the mirror point on x = 0: ``(yL zC + yC zL) / (zL + zC)``."""
        lamp, cam = np.asarray(self.lamp), np.asarray(self.camera)
        return (lamp[..., 1] * cam[..., 2] + cam[..., 1] * lamp[..., 2]) / (lamp[..., 2] + cam[..., 2])


def scanline_directions(points: np.ndarray, rig: ScanlineRig) -> tuple[np.ndarray, np.ndarray]:
    """Unit directions to lamp and camera from sample points ``(..., 3)`` (mm).

    ``rig.lamp``/``rig.camera`` broadcast against ``points[..., :]``; a rig per
    scanline has shape ``(S, 3)`` and points ``(S, N, 3)``, so insert the
    sample axis: pass ``rig`` with ``(S, 1, 3)`` leaves or one rig.
    """
    lamp = np.asarray(rig.lamp)
    cam = np.asarray(rig.camera)
    wi = lamp - points
    wo = cam - points
    wi = wi / np.linalg.norm(wi, axis=-1, keepdims=True)
    wo = wo / np.linalg.norm(wo, axis=-1, keepdims=True)
    return wi, wo


def _slope_y(y, x0, lamp, cam):
    """Along-scanline half-vector slope ``h_y / h_z`` at ``(x0, y, 0)``."""
    p = np.stack([x0 + 0 * y, y, 0 * y], -1)
    wi, wo = scanline_directions(p, ScanlineRig(lamp, cam))
    h = wi + wo
    return h[..., 1] / h[..., 2]


def scanline_positions(
    rig: ScanlineRig,
    x_offset: np.ndarray,
    half_span: np.ndarray,
    n_samples: int = 256,
) -> np.ndarray:
    """Sample points ``(S, N, 3)`` on scanlines covering a slope range around the mirror.

    The points are evenly spaced in y between the two places where the
    along-scanline half-vector slope ``h_y/h_z`` equals ``±half_span`` (for a
    lobe of width αy, ``half_span = 3 αy`` covers ±3α). Found by bisection:
    the slope falls monotonically as y grows.

    Parameters
    ----------
    rig
        One rig, or a rig per scanline with ``(S, 3)`` leaves.
    x_offset, half_span
        ``(S,)`` scanline offsets (mm) and slope half-ranges.
    """
    x0 = np.atleast_1d(np.asarray(x_offset, float))
    span = np.broadcast_to(np.asarray(half_span, float), x0.shape)
    lamp = np.broadcast_to(np.asarray(rig.lamp, float), x0.shape + (3,))
    cam = np.broadcast_to(np.asarray(rig.camera, float), x0.shape + (3,))
    ym = ScanlineRig(lamp, cam).mirror_y()
    reach = 20.0 * np.maximum(lamp[:, 2], cam[:, 2])
    ends = []
    for target in (span, -span):
        lo, hi = ym - reach, ym + reach
        for _ in range(80):
            mid = 0.5 * (lo + hi)
            s = _slope_y(mid, x0, lamp, cam)
            go_right = s > target  # slope decreases with y
            lo = np.where(go_right, mid, lo)
            hi = np.where(go_right, hi, mid)
        ends.append(0.5 * (lo + hi))
    t = np.linspace(0.0, 1.0, n_samples)
    y = ends[0][:, None] + (ends[1] - ends[0])[:, None] * t
    return np.stack([np.broadcast_to(x0[:, None], y.shape), y, np.zeros_like(y)], -1)


def x_offset_for_slope(rig: ScanlineRig, slope) -> np.ndarray:
    """x offset (mm) of the scanline whose half vector tilts by ``h_x/h_z = slope`` at the mirror y.

    A scanline "through the highlight" of a lobe of width αx has
    ``|slope| ≲ αx``; ``slope`` may be negative. Found by bisection (the
    tilt grows monotonically with |x|).
    """
    slope = np.atleast_1d(np.asarray(slope, float))
    lamp = np.broadcast_to(np.asarray(rig.lamp, float), slope.shape + (3,))
    cam = np.broadcast_to(np.asarray(rig.camera, float), slope.shape + (3,))
    ym = ScanlineRig(lamp, cam).mirror_y()
    target = np.abs(slope)
    lo, hi = np.zeros_like(target), 5.0 * np.maximum(lamp[..., 2], cam[..., 2])
    for _ in range(80):
        mid = 0.5 * (lo + hi)
        p = np.stack([mid, ym, np.zeros_like(mid)], -1)
        wi, wo = scanline_directions(p, ScanlineRig(lamp, cam))
        h = wi + wo
        tilt = np.abs(h[..., 0] / h[..., 2])
        lo = np.where(tilt < target, mid, lo)
        hi = np.where(tilt < target, hi, mid)
    return np.sign(slope) * 0.5 * (lo + hi)


class ScanlineData(NamedTuple):
    """Simulated scanlines: what :func:`wardjax.fit_scanlines` takes, plus the truth.

    Attributes
    ----------
    f_r
        ``(S, N, 3)`` noisy BRDF values.
    wi, wo
        ``(S, N, 3)`` directions to lamp and camera.
    f_true
        ``(S, N, 3)`` noise-free BRDF values.
    sigma
        ``(S, N, 3)`` the noise standard deviation used per value (the
        weights ``1/σ²`` a calibrated noise model would give).
    points
        ``(S, N, 3)`` sample positions (mm).
    """

    f_r: np.ndarray
    wi: np.ndarray
    wo: np.ndarray
    f_true: np.ndarray
    sigma: np.ndarray
    points: np.ndarray


def simulate_scanlines(
    params: WardParams,
    *,
    x_offsets=0.0,
    rig: ScanlineRig | None = None,
    n_samples: int = 256,
    span: float = 3.2,
    noise_rel: float = 0.01,
    noise_abs: float = 0.0,
    shot: float = 0.0,
    normalization: str = "ward1992",
    seed: int | np.random.Generator = 0,
) -> ScanlineData:
    """Render noisy BRDF samples along scanlines through the highlight.

    Parameters
    ----------
    params
        :class:`WardParams` batched over ``S`` scanlines (or unbatched, then
        broadcast over ``x_offsets``).
    x_offsets
        ``(S,)`` scanline offsets from the plane of lamp and camera (mm).
    rig
        One :class:`ScanlineRig` or one per scanline (``(S, 3)`` leaves);
        default :meth:`ScanlineRig.from_angles`.
    n_samples
        Samples per scanline, evenly spaced in y.
    span
        The scanline covers along-scanline half-vector slopes ``±span · αy``.
    noise_rel, noise_abs, shot
        Gaussian noise with ``σ² = (noise_rel f)² + noise_abs² + shot · f``:
        relative (the tests' σ = 0.01 f), a floor, and photon shot noise.
    seed
        Seed or NumPy ``Generator``; the same seed gives the same data.
    """
    rng = seed if isinstance(seed, np.random.Generator) else np.random.default_rng(seed)
    rig = rig if rig is not None else ScanlineRig.from_angles()
    ay = np.asarray(params.alpha_y, float)
    x0 = np.asarray(x_offsets, float)
    shape = np.broadcast_shapes(np.shape(ay), np.shape(x0), np.shape(np.asarray(rig.lamp))[:-1])
    s = int(np.prod(shape)) if shape else 1
    x0 = np.broadcast_to(x0, shape).reshape(s)
    half = span * np.broadcast_to(ay, shape).reshape(s)
    pts = scanline_positions(rig, x0, half, n_samples)
    lamp = np.broadcast_to(np.asarray(rig.lamp, float), (s, 3))[:, None, :]
    cam = np.broadcast_to(np.asarray(rig.camera, float), (s, 3))[:, None, :]
    wi, wo = scanline_directions(pts, ScanlineRig(lamp, cam))

    def leaf(x, tail):
        x = np.asarray(x, float)
        return np.broadcast_to(x, (s,) + tail) if x.ndim <= len(tail) else x.reshape((s,) + tail)

    rho_s = np.asarray(params.rho_s, float)
    rs_tail = (3,) if rho_s.shape[-1:] == (3,) and rho_s.ndim == np.ndim(params.rho_d) else ()
    p = WardParams.from_estimate(  # the checked material, laid out per scanline
        rho_d=leaf(params.rho_d, (3,))[:, None, :],
        rho_s=leaf(rho_s, rs_tail)[:, None, ...],
        alpha_x=leaf(params.alpha_x, ())[:, None],
        alpha_y=leaf(params.alpha_y, ())[:, None],
    )
    f_true = ward_values(p, wi, wo, normalization)
    sigma = np.sqrt((noise_rel * f_true) ** 2 + noise_abs**2 + shot * np.abs(f_true))
    f_r = f_true + sigma * rng.standard_normal(f_true.shape)
    return ScanlineData(f_r=f_r, wi=wi, wo=wo, f_true=f_true, sigma=sigma, points=pts)
