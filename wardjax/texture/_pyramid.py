"""Steerable pyramid in the frequency domain, and the periodic + smooth decomposition.

The pyramid is the real, order-3 (four orientation bands) steerable pyramid of
Simoncelli & Freeman (1995), built in the Fourier domain as in pyrtools'
``SteerablePyramidFreq`` (Karasaridis & Simoncelli 1996 filters), which is the
decomposition Heeger & Bergen (1995) and the image-based paper (section 4.2)
analyse textures with. Two things differ from pyrtools, both on purpose:

* the frequency grid is the exact DFT grid (``numpy.fft.fftfreq``) for every
  size, and each coarser level keeps ``ceil(n / 2)`` samples per axis, so the
  transform is a tight frame and reconstruction is exact to rounding for odd
  sizes too (pyrtools' grid is off by half a sample for odd sizes);
* the raised-cosine masks are evaluated in closed form instead of from a
  linearly interpolated lookup table, so ``hi² + lo² = 1`` and
  ``Σ_b A_b² = 1`` hold to rounding (pyrtools: to about 1e-5).

Coefficients at level ``l`` are the band-passed image *sampled* on the level's
grid (DFTs with ``norm="forward"``), so their amplitude does not depend on the
image size; pyrtools' level-``l`` bands are these times ``N M / (N_l M_l)``.

Everything here is private; the public names are re-exported from
:mod:`wardjax.texture`.
"""

from __future__ import annotations

import functools
import math

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from ._jit import texture_jit

__all__ = [
    "ORIENTATIONS",
    "max_pyramid_height",
    "periodic_smooth",
    "periodic_spectrum",
    "pyramid_build",
    "pyramid_collapse",
    "pyramid_map",
    "pyramid_subbands",
    "pyramid_masks",
    "pyramid_reconstruct",
    "pyramid_shapes",
]

ORIENTATIONS = 4
"""Orientation bands per level (steerable filters of order 3, as in the paper)."""

_ORDER = ORIENTATIONS - 1
# Angular gain so that Σ_b A_b(θ)² = 1 for A_b(θ) = g cos^n(θ − π b / K):
# g² = 2^{2n} (n!)² / (K (2n)!)  (Karasaridis & Simoncelli 1996); n = 3, K = 4 → 0.8.
_ANGLE_GAIN = math.sqrt(2 ** (2 * _ORDER) * math.factorial(_ORDER) ** 2 / (ORIENTATIONS * math.factorial(2 * _ORDER)))


def max_pyramid_height(shape: tuple[int, int]) -> int:
    """Deepest pyramid for an image of ``shape``: ``floor(log2(min(shape))) − 2`` (pyrtools' rule), at least 0."""
    return max(0, int(math.floor(math.log2(max(1, min(shape))))) - 2)


def pyramid_shapes(shape: tuple[int, int], height: int) -> tuple[tuple[int, int], ...]:
    """Grid of each level, finest first: level 0 is ``shape``, level ``l + 1`` keeps ``ceil(n_l / 2)`` per axis.

    Returns ``height + 1`` shapes; the last is the low-pass residual's.
    """
    h, w = shape
    out = [(int(h), int(w))]
    for _ in range(height):
        h, w = out[-1]
        out.append((-(-h // 2), -(-w // 2)))
    return tuple(out)


def _hi(u: np.ndarray) -> np.ndarray:
    """Raised-cosine high-pass in log2-radius ``u``: 0 for ``u ≤ −1``, 1 for ``u ≥ 0``, ``cos(π u / 2)`` between."""
    with np.errstate(invalid="ignore"):
        return np.where(u >= 0, 1.0, np.where(u <= -1, 0.0, np.cos(0.5 * np.pi * u)))


def _lo(u: np.ndarray) -> np.ndarray:
    """Complementary low-pass: ``_lo² + _hi² = 1``; exactly 0 for ``u ≥ 0``, 1 for ``u ≤ −1``."""
    with np.errstate(invalid="ignore"):
        return np.where(u >= 0, 0.0, np.where(u <= -1, 1.0, np.sin(-0.5 * np.pi * u)))


def _polar_grid(level_shape: tuple[int, int], full_shape: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """log2 radius and angle of the half-plane (rfft2) DFT grid of one level.

    Frequencies are normalised by the *full-resolution* Nyquist frequency on each
    axis (pyrtools' ``xramp``, ``yramp``), so a level's masks are the full-size
    masks restricted to the frequencies that level keeps.
    """
    (n, m), (n0, m0) = level_shape, full_shape
    ky = np.fft.fftfreq(n) * n  # signed integer frequencies
    kx = np.arange(m // 2 + 1, dtype=np.float64)
    fy, fx = np.meshgrid(2.0 * ky / n0, 2.0 * kx / m0, indexing="ij")
    r = np.hypot(fx, fy)
    with np.errstate(divide="ignore"):
        u = np.log2(r)  # −inf at DC: all low-pass
    return u, np.arctan2(fy, fx)


@functools.lru_cache(maxsize=16)
def pyramid_masks(shape: tuple[int, int], height: int) -> dict:
    """Real frequency masks of the pyramid (NumPy float64, rfft2 half-plane layout, cached per shape).

    Keys: ``hi0``, ``lo0`` (level-0 grid), ``band`` (a tuple; level ``l``:
    ``(4, N_l, M_l//2+1)`` = ``A_b(θ) hi(u + l + 1)``) and ``lo`` (a tuple;
    entry ``l`` is ``lo(u + l + 1)`` on level ``l + 1``'s grid). With
    ``u = log2 r``, these satisfy ``hi0² + lo0² = 1``, ``Σ_b band_l² + lo_l² = 1``.
    """
    shapes = pyramid_shapes(shape, height)
    u0, _ = _polar_grid(shapes[0], shapes[0])
    bands, los = [], []
    for level in range(height):
        u, theta = _polar_grid(shapes[level], shapes[0])
        ang = np.stack([_ANGLE_GAIN * np.cos(theta - np.pi * b / ORIENTATIONS) ** _ORDER for b in range(ORIENTATIONS)])
        bands.append(ang * _hi(u + level + 1)[None])
        u_next, _ = _polar_grid(shapes[level + 1], shapes[0])
        los.append(_lo(u_next + level + 1))
    out = {"hi0": _hi(u0), "lo0": _lo(u0), "band": tuple(bands), "lo": tuple(los)}
    for a in jax.tree_util.tree_leaves(out):
        a.setflags(write=False)
    return out


def _cmul(z: Array, m: Array) -> Array:
    """A complex spectrum times a real mask (the mask cast to the spectrum's dtype, as promotion would)."""
    return z * m.astype(z.dtype)


def _expi(t: Array) -> Array:
    """``exp(i t)`` of real ``t``, complex of the matching precision (``t`` cast, then times ``i``)."""
    return jnp.exp(1j * t.astype(jnp.complex128 if t.dtype == jnp.float64 else jnp.complex64))


def _crop(z: Array, shape: tuple[int, int]) -> Array:
    """Keep the half-plane DFT coefficients of a smaller grid: rows ``−⌊n/2⌋ … ⌈n/2⌉−1``, columns ``0 … m//2``."""
    n, m = shape
    pos, neg = -(-n // 2), n // 2
    rows = z[..., :pos, :] if neg == 0 else jnp.concatenate([z[..., :pos, :], z[..., z.shape[-2] - neg :, :]], axis=-2)
    return rows[..., : m // 2 + 1]


def _pad(z: Array, shape: tuple[int, int]) -> Array:
    """Inverse of :func:`_crop`: put a small grid's coefficients back into a larger one, zeros elsewhere."""
    n_big, m_big = shape
    n = z.shape[-2]
    pos = -(-n // 2)
    lead = z.shape[:-2]
    mid = jnp.zeros((*lead, n_big - n, z.shape[-1]), z.dtype)
    rows = jnp.concatenate([z[..., :pos, :], mid, z[..., pos:, :]], axis=-2)
    return jnp.pad(rows, [(0, 0)] * (rows.ndim - 1) + [(0, m_big // 2 + 1 - z.shape[-1])])


@texture_jit(static_argnames="shapes")
def pyramid_build(
    x: Float[Array, "c h w"], masks: dict, shapes: tuple[tuple[int, int], ...]
) -> tuple[Float[Array, "c h w"], tuple[Float[Array, "c 4 hl wl"], ...], Float[Array, "c hL wL"]]:
    """Analysis: ``(highpass, bands, lowpass)`` of a batch of images ``x`` (``C`` channels).

    ``X = DFT(x) / (N M)``; highpass ``= IDFT(X hi0)``; with ``Z_0 = X lo0``,
    level ``l``'s band ``b`` is ``IDFT_l(i Z_l A_b hi_l)`` (``i = (−i)^3``, the
    order-3 phase; the filter is Hermitian so the band is real) and
    ``Z_{l+1} = crop(Z_l) lo_l``; the low-pass residual is ``IDFT(Z_height)``.
    ``masks`` must be :func:`pyramid_masks` for ``shapes`` in ``x``'s dtype.
    """
    flat = pyramid_subbands(jnp.fft.rfft2(x, norm="forward"), masks, shapes)
    o = ORIENTATIONS
    bands = tuple(jnp.stack(flat[1 + o * lv : 1 + o * (lv + 1)], axis=1) for lv in range(len(shapes) - 1))
    return flat[0], bands, flat[-1]


def _idft(z: Array, shape: tuple[int, int]) -> Array:
    """``irfft2(z, s=shape, norm="forward")`` with the factor ``N M`` folded into the spectrum.

    XLA's inverse transform divides by ``N M``; ``norm="forward"`` multiplies
    the image by ``N M`` afterwards, a pass over the image of its own. Scaling
    the spectrum instead fuses into the mask product that makes it.
    """
    return jnp.fft.irfft2(z * float(shape[0] * shape[1]), s=shape)


def pyramid_subbands(spec, masks: dict, shapes: tuple[tuple[int, int], ...]) -> tuple[Float[Array, "c hl wl"], ...]:
    """The subbands of :func:`pyramid_build` from ``X = rfft2(x, norm="forward")``, as one flat tuple.

    Order: highpass, then level by level the ``ORIENTATIONS`` orientations,
    then lowpass (``2 + ORIENTATIONS · height`` arrays ``(C, H_l, W_l)``).
    Separate arrays spare the copies that stacking the orientations (and
    slicing them apart again for :func:`pyramid_collapse`) would cost.
    """
    highpass = _idft(_cmul(spec, masks["hi0"][None]), shapes[0])
    z = _cmul(spec, masks["lo0"][None])
    out = [highpass]
    for level, band in enumerate(masks["band"]):
        iz = 1j * z
        # One orientation at a time: the same transforms as one batched call, but XLA
        # keeps one band's spectrum live instead of four (a third less temporary memory).
        out.extend(_idft(_cmul(iz, m[None]), shapes[level]) for m in band)
        z = _cmul(_crop(z, shapes[level + 1]), masks["lo"][level][None])
    out.append(_idft(z, shapes[-1]))
    return tuple(out)


def pyramid_map(spec, fn, masks: dict, shapes: tuple[tuple[int, int], ...], collapse: bool = True):
    """Build the pyramid of ``X = rfft2(x, norm="forward")``, send every subband through ``fn``, collapse the results.

    ``fn(k, band)`` gets the ``k``-th subband (the order of
    :func:`pyramid_subbands`; ``k`` is a traced integer for the orientation
    bands) and returns ``(new_band, aux)``. Returns ``(image, auxes)``:
    ``image`` is :func:`pyramid_collapse` of the new bands (``None`` without
    ``collapse``, when ``new_band`` is ignored) and ``auxes`` the ``aux`` of
    every subband, stacked along a new first axis in subband order.

    The collapse is linear, so level ``l``'s share
    ``Σ_b DFT_l(new_lb) A_b hi_l`` is summed as the level is built, and the
    orientations of a level go through one ``lax.scan``: one band is alive at
    a time instead of the whole pyramid twice over (XLA's CPU scheduler would
    otherwise keep them all), so the program needs a fraction of the memory
    and faults in a fraction of the pages.
    """

    def back(new, mask):
        return _cmul(jnp.fft.rfft2(new, norm="forward"), mask[None])

    new, aux_high = fn(0, _idft(_cmul(spec, masks["hi0"][None]), shapes[0]))
    high = back(new, masks["hi0"]) if collapse else None
    auxes, shares = [aux_high[None]], []
    z = _cmul(spec, masks["lo0"][None])
    for level, band in enumerate(masks["band"]):
        iz = 1j * z

        def orient(share, mk, iz=iz, level=level):
            m, k = mk
            new, aux = fn(k, _idft(_cmul(iz, m[None]), shapes[level]))
            return (share + back(new, m) if collapse else share), aux

        share0 = jnp.zeros(iz.shape, iz.dtype) if collapse else jnp.zeros((), iz.dtype)
        ks = jnp.arange(1 + ORIENTATIONS * level, 1 + ORIENTATIONS * (level + 1))
        share, aux = jax.lax.scan(orient, share0, (band, ks))
        shares.append(share)
        auxes.append(aux)
        z = _cmul(_crop(z, shapes[level + 1]), masks["lo"][level][None])
    new, aux_low = fn(1 + ORIENTATIONS * len(masks["band"]), _idft(z, shapes[-1]))
    auxes = jax.tree_util.tree_map(lambda *a: jnp.concatenate(a), *auxes, aux_low[None])
    if high is None:  # not collapse
        return None, auxes
    low = jnp.fft.rfft2(new, norm="forward")
    for level in range(len(shapes) - 2, -1, -1):
        low = _pad(_cmul(low, masks["lo"][level][None]), shapes[level]) + (-1j) * shares[level]
    return _idft(_cmul(low, masks["lo0"][None]) + high, shapes[0]), auxes


@texture_jit(static_argnames="shapes")
def pyramid_reconstruct(
    highpass: Float[Array, "c h w"],
    bands: tuple[Float[Array, "c 4 _ _"], ...],
    lowpass: Float[Array, "c _ _"],
    masks: dict,
    shapes: tuple[tuple[int, int], ...],
) -> Float[Array, "c h w"]:
    """Synthesis (the adjoint of :func:`pyramid_build`, and its inverse since the masks tile the spectrum).

    ``Z_l = pad(Z_{l+1} lo_l) + Σ_b DFT_l(band_lb) (−i A_b hi_l)``;
    ``X = Z_0 lo0 + DFT(highpass) hi0``.
    """
    flat = (highpass, *(band[:, b] for band in bands for b in range(band.shape[1])), lowpass)
    return pyramid_collapse(flat, masks, shapes)


def pyramid_collapse(subbands, masks: dict, shapes: tuple[tuple[int, int], ...]) -> Float[Array, "c h w"]:
    """:func:`pyramid_reconstruct` from the flat tuple of :func:`pyramid_subbands`."""
    height = len(shapes) - 1
    z = jnp.fft.rfft2(subbands[-1], norm="forward")
    for level in range(height - 1, -1, -1):
        band_spec = sum(
            _cmul(jnp.fft.rfft2(subbands[1 + ORIENTATIONS * level + b], norm="forward"), m[None])
            for b, m in enumerate(masks["band"][level])
        )
        z = _pad(_cmul(z, masks["lo"][level][None]), shapes[level]) + (-1j) * band_spec
    spec = _cmul(z, masks["lo0"][None]) + _cmul(jnp.fft.rfft2(subbands[0], norm="forward"), masks["hi0"][None])
    return _idft(spec, shapes[0])


@texture_jit
def periodic_spectrum(u: Float[Array, "c h w"]):
    """``rfft2(p, norm="forward")`` of the periodic component ``p`` of :func:`periodic_smooth`, without forming ``s``.

    The border-jump image ``v`` is zero inside, so its DFT is a sum of two
    rank-one terms of 1-D DFTs: with ``dy = u[−1, :] − u[0, :]`` and
    ``dx = u[:, −1] − u[:, 0]``,
    ``v̂(q, r) = (1 − e^{2πi q/N}) DFT(dy)(r) + DFT(dx)(q) (1 − e^{2πi r/M})``;
    then ``p̂ = û − v̂ / (2 cos(2π q/N) + 2 cos(2π r/M) − 4)`` with ``p̂(0, 0) = û(0, 0)``.
    Two 1-D transforms replace the 2-D pair of :func:`periodic_smooth`.
    """
    n, m = u.shape[-2:]
    dy = jnp.fft.rfft(u[:, -1, :] - u[:, 0, :])  # (c, m//2+1)
    dx = jnp.fft.fft(u[:, :, -1] - u[:, :, 0])  # (c, n)
    tq = 2.0 * jnp.pi * jnp.fft.fftfreq(n, dtype=u.dtype)
    tr = 2.0 * jnp.pi * jnp.fft.rfftfreq(m, dtype=u.dtype)
    v_hat = (1.0 - _expi(tq))[None, :, None] * dy[:, None, :] + dx[:, :, None] * (1.0 - _expi(tr))[None, None, :]
    den = 2.0 * jnp.cos(tq)[:, None] + 2.0 * jnp.cos(tr)[None, :] - 4.0
    den = den.at[0, 0].set(1.0)
    s_hat = (v_hat / den[None].astype(v_hat.dtype)).at[:, 0, 0].set(0.0)
    return (jnp.fft.rfft2(u) - s_hat) / (n * m)


@texture_jit
def periodic_smooth(u: Float[Array, "c h w"]) -> tuple[Float[Array, "c h w"], Float[Array, "c h w"]]:
    """Moisan's (2011) periodic + smooth decomposition ``u = p + s`` of a batch of images.

    ``s`` solves the periodic Poisson problem ``Δ s = v`` where ``v`` holds the
    jumps across the image borders (``v[0, :] = u[−1, :] − u[0, :]``,
    ``v[−1, :] = −v[0, :]``, and the same on columns), i.e.
    ``ŝ(q, r) = v̂(q, r) / (2 cos(2π q / N) + 2 cos(2π r / M) − 4)`` with
    ``ŝ(0, 0) = 0``. ``p = u − s`` is periodic-looking: its DFT has no cross of
    border artefacts, and it keeps the mean of ``u``.
    """
    n, m = u.shape[-2:]
    dy = u[:, -1, :] - u[:, 0, :]
    dx = u[:, :, -1] - u[:, :, 0]
    v = jnp.zeros_like(u)
    v = v.at[:, 0, :].add(dy).at[:, -1, :].add(-dy)
    v = v.at[:, :, 0].add(dx).at[:, :, -1].add(-dx)
    q = 2.0 * jnp.cos(2.0 * jnp.pi * jnp.fft.fftfreq(n, dtype=u.dtype))
    r = 2.0 * jnp.cos(2.0 * jnp.pi * jnp.fft.rfftfreq(m, dtype=u.dtype))
    den = q[:, None] + r[None, :] - 4.0
    den = den.at[0, 0].set(1.0)
    v_spec = jnp.fft.rfft2(v)
    s_hat = v_spec / den[None].astype(v_spec.dtype)
    s_hat = s_hat.at[:, 0, 0].set(0.0)
    s = jnp.fft.irfft2(s_hat, s=(n, m))
    return u - s, s
