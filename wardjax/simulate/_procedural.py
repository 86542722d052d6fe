"""Procedural ρd textures used to test and benchmark texture analysis/synthesis.

Each generator returns a linear RGB ρd image ``(H, W, 3)`` in ``[0, 1 − ρs]``,
drawn from a seeded ``numpy.random.Generator`` on a canvas larger than the
image and cropped, so the textures are *not* periodic (as a photograph is not).

* ``noise`` — stationary fractal (1/f^β) noise with a colour tint: what the
  Heeger–Bergen model describes well.
* ``wood`` — straight grain: fibres (noise elongated along y) over soft,
  irregular growth bands.
* ``wood_rings`` — sharp, closely spaced growth rings distorted by turbulence:
  quasi-periodic, so Heeger–Bergen needs more iterations (about 10) to match it.
* ``marble`` — sinusoidal veins distorted by turbulence (Perlin's marble).
* ``bricks`` — a regular running-bond brick wall: the structured, periodic kind
  of texture the method cannot reproduce (its arrangement is lost).
"""

from __future__ import annotations

import numpy as np

__all__ = ["PLANE_TEXTURES", "TEXTURE_KINDS", "plane_texture", "procedural_texture"]

# The ρd modulations of simulated captures, on the sample plane (mm).
PLANE_TEXTURES = ("wood", "marble", "noise", "none")

TEXTURE_KINDS = ("noise", "wood", "marble", "wood_rings", "bricks")


def _fractal(
    shape: tuple[int, int],
    rng: np.random.Generator,
    beta: float,
    cutoff: float = 0.0,
    stretch: float = 1.0,
    f_min: float = 1.0 / 48.0,
) -> np.ndarray:
    """Gaussian noise with amplitude spectrum ``1 / max(f, f_min)^β`` (optionally low-passed), unit std.

    The spectrum is flat below ``f_min`` cycles per pixel, so the texture is
    stationary at scales much smaller than the image (a texture, not a
    gradient); ``stretch > 1`` scales vertical frequencies up, elongating
    features along y.
    """
    h, w = shape
    fy = np.fft.fftfreq(h)[:, None] * stretch
    fx = np.fft.rfftfreq(w)[None, :]
    f = np.sqrt(fx**2 + fy**2)
    amp = 1.0 / np.maximum(f, f_min) ** beta
    if cutoff > 0:
        amp = amp * np.exp(-((f / cutoff) ** 2))
    spec = (rng.standard_normal((h, w // 2 + 1)) + 1j * rng.standard_normal((h, w // 2 + 1))) * amp
    x = np.fft.irfft2(spec, s=(h, w))
    return (x - x.mean()) / x.std()


def _colourise(v: np.ndarray, dark, light) -> np.ndarray:
    v = np.clip(v, 0.0, 1.0)[..., None]
    return (1.0 - v) * np.asarray(dark) + v * np.asarray(light)


def procedural_texture(kind: str, shape: tuple[int, int], seed: int = 0, *, rho_s: float = 0.04) -> np.ndarray:
    """A seeded procedural ρd texture of ``shape = (H, W)``; ``kind`` is one of :data:`TEXTURE_KINDS`."""
    if kind not in TEXTURE_KINDS:
        raise ValueError(f"kind={kind!r}, expected one of {TEXTURE_KINDS}")
    h, w = (int(s) for s in shape)
    rng = np.random.default_rng(seed)
    pad = 32
    canvas = (h + 2 * pad, w + 2 * pad)
    yy, xx = np.mgrid[0 : canvas[0], 0 : canvas[1]].astype(np.float64)
    if kind == "noise":
        n1 = _fractal(canvas, rng, 1.2)
        n2 = _fractal(canvas, rng, 0.6)
        own = [_fractal(canvas, rng, 0.9) for _ in range(3)]
        r = 0.45 + 0.07 * n1 + 0.02 * n2
        img = np.stack([r + 0.015 * own[0], 0.9 * r + 0.015 * own[1], 0.75 * r + 0.02 * own[2]], axis=-1)
    elif kind == "wood":
        fibres = _fractal(canvas, rng, 1.0, stretch=4.0)
        turb = _fractal(canvas, rng, 2.2)
        bands = (0.5 - 0.5 * np.cos(2 * np.pi * (xx / 14.0 + 1.0 * turb))) ** 3
        v = 0.35 + 0.3 * bands + 0.12 * fibres
        img = _colourise(v, (0.55, 0.33, 0.16), (0.25, 0.12, 0.05))
    elif kind == "wood_rings":
        turb = _fractal(canvas, rng, 2.0)
        grain = _fractal(canvas, rng, 0.3)
        cx, cy = -3.0 * canvas[1], canvas[0] * rng.uniform(0.3, 0.7)
        r = np.hypot(xx - cx, 0.25 * (yy - cy))
        rings = r / 12.0 + 1.2 * turb
        v = 0.75 * (0.5 - 0.5 * np.cos(2 * np.pi * rings)) ** 2 + 0.08 * grain
        img = _colourise(v, (0.55, 0.33, 0.16), (0.25, 0.12, 0.05))
    elif kind == "marble":
        turb = _fractal(canvas, rng, 1.8, f_min=1.0 / 128.0)
        fine = _fractal(canvas, rng, 0.8)
        phase = 2 * np.pi * (xx * 0.011 + yy * 0.004) + 2.0 * turb
        v = np.abs(np.sin(phase)) ** 0.35 + 0.05 * fine
        img = _colourise(v, (0.30, 0.30, 0.33), (0.82, 0.80, 0.76))
    else:  # bricks
        bh, bw, mortar = 12, 28, 3
        row = yy // bh
        offset = (row % 2) * (bw // 2)
        in_mortar = ((yy % bh) < mortar) | (((xx + offset) % bw) < mortar)
        col = (xx + offset) // bw
        table = rng.uniform(-0.04, 0.04, size=(int(row.max()) + 1, int(col.max()) + 1))
        tint = table[row.astype(int), col.astype(int)]
        fine = 0.015 * _fractal(canvas, rng, 0.5)
        img = np.where(
            in_mortar[..., None], np.array([0.62, 0.60, 0.56]), np.array([0.45, 0.17, 0.10]) + tint[..., None]
        )
        img = img + fine[..., None]
    # Every real ρd map has some independent variation per channel (pigment, sensor
    # noise); without it the RGB covariance is singular and PCA channels are empty.
    img = img + 0.006 * np.stack([_fractal(canvas, rng, 0.7) for _ in range(3)], axis=-1)
    out = img[pad : pad + h, pad : pad + w]
    return np.clip(out, 0.0, 1.0 - rho_s)


# --------------------------------------------------------------------------- on the sample plane (mm)


def _smooth_noise(x, y, rng: np.random.Generator, waves: int = 10, wavelength=(25.0, 90.0)) -> np.ndarray:
    """Smooth random field with unit variance: a sum of random plane waves."""
    out = np.zeros(np.shape(x))
    for _ in range(waves):
        k = 2 * np.pi / rng.uniform(*wavelength)
        th = rng.uniform(0, 2 * np.pi)
        ph = rng.uniform(0, 2 * np.pi)
        out += np.sin(k * (np.cos(th) * x + np.sin(th) * y) + ph)
    return out * np.sqrt(2.0 / waves)


def plane_texture(kind: str, x, y, *, amplitude: float = 0.08, seed: int = 0) -> np.ndarray:
    """A multiplicative ρd modulation ``m(x, y)`` (mean ≈ 1) at sample points (mm).

    ``"wood"``: growth rings running along y (slightly wavy, at a phase drawn from ``seed``), with fine grain;
    ``"marble"``: veins, a turbulent sine pattern across the surface;
    ``"noise"``: isotropic broadband noise (wavelengths 2–40 mm, amplitude
    spectrum ∝ wavelength, a 1/f field), no preferred direction;
    ``"none"``: ``m = 1``. The modulation stays within ``1 ± amplitude``.
    """
    rng = np.random.default_rng(seed)
    x = np.asarray(x, np.float64)
    y = np.asarray(y, np.float64)
    if kind == "none":
        return np.ones_like(x)
    if kind == "wood":
        r = x + 1.5 * _smooth_noise(x, y, rng, wavelength=(150.0, 400.0))
        period = rng.uniform(9.0, 13.0)
        grain = _smooth_noise(x, y, rng, wavelength=(4.0, 12.0))
        # The rings' phase is drawn per seed (last, so the other draws stay): anchored at x = 0 they would put
        # the same ring under the lobe in every capture, and captures of different seeds would not be
        # independent draws of the texture.
        rings = np.sin(2 * np.pi * r / period + rng.uniform(0.0, 2 * np.pi))
        m = 0.8 * rings + 0.2 * np.tanh(grain)
    elif kind == "marble":
        th = rng.uniform(0.3, 1.2)
        phase = 2 * np.pi * (np.cos(th) * x + np.sin(th) * y) / rng.uniform(40.0, 70.0)
        m = np.sin(phase + 2.5 * _smooth_noise(x, y, rng))
        m = np.sign(m) * np.abs(m) ** 0.5  # sharpen the veins
    elif kind == "noise":
        bands = [(2.0, 5.0), (5.0, 12.0), (12.0, 40.0)]
        m = sum(lam[0] * _smooth_noise(x, y, rng, waves=24, wavelength=lam) for lam in bands)
        m = np.tanh(m / np.sqrt(sum(lam[0] ** 2 for lam in bands)) / 1.5)
    else:
        raise ValueError(f"texture={kind!r} is not one of 'wood', 'marble', 'noise', 'none' (or a callable)")
    return 1.0 + amplitude * np.clip(m, -1.0, 1.0)
