"""The standard's image smoothed within its mask: a Gaussian mean inside, a local plane near the edge."""

from __future__ import annotations

import numpy as np

__all__ = ["smooth_on"]

TRUNCATE = 4.0  # scipy.ndimage.gaussian_filter's default: the kernel's radius is int(4 σ + 0.5) pixels


def _kernels(sigma: float) -> dict[int, np.ndarray]:
    """The 1-D Gaussian of ``σ`` and its first two derivatives on ``[−r, r]``, ``r = int(4 σ + 0.5)``.

    ``φ(x) = exp(−x²/2σ²)/Σφ``, ``φ' = −(x/σ²) φ``, ``φ'' = (x²/σ⁴ − 1/σ²) φ``: the kernels of
    :func:`scipy.ndimage.gaussian_filter` (default ``truncate``), reversed for correlation, computed once
    per smoothing rather than once per filter call.
    """
    r = int(TRUNCATE * sigma + 0.5)
    x = np.arange(-r, r + 1, dtype=np.float64)
    phi = np.exp(-0.5 * x**2 / sigma**2)
    phi /= phi.sum()
    return {0: phi, 1: (-x / sigma**2 * phi)[::-1], 2: ((x**2 / sigma**4 - 1 / sigma**2) * phi)[::-1]}


def _gauss(f: np.ndarray, k: dict[int, np.ndarray], order: tuple[int, int] = (0, 0)) -> np.ndarray:
    """``G_σ * f`` (or the derivative of orders ``(d/dy, d/dx)``) with zeros outside the array: what lies off the
    mask weighs nothing. ``k`` is :func:`_kernels`'s."""
    from scipy.ndimage import correlate1d

    out = correlate1d(f, k[order[0]], axis=0, mode="constant")
    return correlate1d(out, k[order[1]], axis=1, mode="constant")


def _plane_levels(image: np.ndarray, mask: np.ndarray, sigma: float, k: dict[int, np.ndarray]) -> np.ndarray:
    """``(h, w, C)``: at each pixel, the level of the plane fitted with Gaussian weights to the masked pixels.

    The value at ``p`` of ``a + b·(q − p)`` fitted to the pixels ``q`` with ``m = 1`` and weights
    ``G(q − p)`` (normalised convolution of order 1, Knutsson & Westin 1993): the first row of the
    3 × 3 moment matrix's inverse (its cofactors over the determinant, elementwise on images) applied
    to the weighted sums of ``I``. Where the weights do not spread in both directions (a thin strip)
    the plane is not determined and the Gaussian mean ``(G * (m·I)) / (G * m)`` is returned instead.
    """
    m = mask.astype(np.float32)

    def moments(f):  # Σ_q f(q) G(q − p) (1, d_y, d_x) at every p, d = (q − p)/σ: Gaussian derivative filters
        return _gauss(f, k), sigma * _gauss(f, k, (1, 0)), sigma * _gauss(f, k, (0, 1))

    s0, sy, sx = moments(m)
    syy = sigma**2 * _gauss(m, k, (2, 0)) + s0
    sxx = sigma**2 * _gauss(m, k, (0, 2)) + s0
    sxy = sigma**2 * _gauss(m, k, (1, 1))
    c0, c1, c2 = syy * sxx - sxy * sxy, sxy * sx - sy * sxx, sy * sxy - syy * sx
    det = s0 * c0 + sy * c1 + sx * c2
    plane = det > 1e-3 * s0**3
    det = np.where(plane, det, 1.0)
    norm = np.where(s0 > 0, s0, 1.0)
    out = np.empty(image.shape, np.float32)
    for c in range(image.shape[-1]):
        t0, t1, t2 = moments(image[..., c] * m)
        out[..., c] = np.where(plane, (c0 * t0 + c1 * t1 + c2 * t2) / det, t0 / norm)
    return out


def smooth_on(image: np.ndarray, mask: np.ndarray, sigma: float, tile: int = 48) -> np.ndarray:
    """Normalised Gaussian smoothing of ``image`` within ``mask``, to first order; values outside it kept.

    On pixels with ``m = 1``, the level at ``p`` of the plane fitted to the masked pixels with Gaussian
    weights (:func:`_plane_levels`). Where ``p``'s whole kernel window lies on the mask, the plane's
    slope terms vanish by symmetry and its level is the Gaussian mean ``(G * (m·I)) / (G * m)``; near
    the mask's edge, where that mean is one-sided, the plane keeps the standard's gradient (irradiance
    falloff, vignetting) instead of pulling the edge values towards the inside — the edge next to the
    stripline is where the mirror points of the probe's brightest columns fall. The values outside
    (the table, clipped pixels) never bleed in.

    The mean is taken over the whole image; the plane only on ``tile``-pixel tiles that hold a masked
    pixel whose window reaches off the mask, each cropped with a margin of the kernel's radius (so
    its values are those of the plane over the whole image) — or over the whole image when such
    tiles cover most of it (clipped specks scattered over the standard). ``image`` is ``(h, w, C)``, ``mask``
    ``(h, w)``.
    """
    from scipy.ndimage import minimum_filter

    k = _kernels(sigma)
    radius = len(k[0]) // 2
    inside = np.asarray(mask, bool)
    out = np.array(image, np.float32, copy=True)
    whole_window = np.asarray(minimum_filter(inside, size=2 * radius + 1, mode="constant", cval=False), bool)
    edge = inside & ~whole_window
    h, w = mask.shape
    step = max(tile, 2 * radius)
    ny, nx = -(-h // step), -(-w // step)
    tiles = np.pad(edge, ((0, ny * step - h), (0, nx * step - w))).reshape(ny, step, nx, step).any(axis=(1, 3))
    # The mean costs 4 filters over the image, the plane 15 over its tiles: tiles over 0.7 of the image cost more
    # than the plane everywhere (a small standard, or clipped specks scattered over it).
    if tiles.sum() * (step + 2 * radius) ** 2 > 0.7 * h * w:
        return np.where(inside[..., None], _plane_levels(image, mask, sigma, k), out)
    m = inside.astype(np.float32)
    s0 = _gauss(m, k)
    norm = np.where(s0 > 0, s0, 1.0)
    for c in range(image.shape[-1]):
        out[..., c] = np.where(inside, _gauss(image[..., c] * m, k) / norm, out[..., c])
    for ty, tx in zip(*np.nonzero(tiles), strict=True):
        y0, x0 = int(ty) * step, int(tx) * step
        e = edge[y0 : y0 + step, x0 : x0 + step]
        ys = slice(max(y0 - radius, 0), min(y0 + step + radius, h))
        xs = slice(max(x0 - radius, 0), min(x0 + step + radius, w))
        level = _plane_levels(image[ys, xs], mask[ys, xs], sigma, k)
        iy, ix = y0 - ys.start, x0 - xs.start
        level = level[iy : iy + e.shape[0], ix : ix + e.shape[1]]
        view = out[y0 : y0 + step, x0 : x0 + step]
        view[...] = np.where(e[..., None], level, view)
    return out
