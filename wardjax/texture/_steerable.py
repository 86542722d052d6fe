"""The steerable pyramid as a pytree (image-based paper, section 4.2): build, collapse, and the periodic + smooth split.

Four orientation bands per level (Simoncelli & Freeman 1995), built in the
Fourier domain by :mod:`._pyramid`. The periodic component of
:func:`periodic_smooth_decomposition` (Moisan 2011) has no border jumps, so
the pyramid of a texture sees no cross at the image edges.
"""

from __future__ import annotations

import functools

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ._pyramid import (
    ORIENTATIONS,
    max_pyramid_height,
    periodic_smooth,
    pyramid_build,
    pyramid_masks,
    pyramid_reconstruct,
    pyramid_shapes,
)

DEFAULT_HEIGHT = 4
"""Pyramid levels used when the region allows (fewer for small regions)."""

_MIN_SIDE = 8  # smallest region/output side: a pyramid of height 1 needs 8 pixels


class SteerablePyramid(eqx.Module):
    """Subbands of a steerable pyramid (four orientations), finest level first.

    Attributes
    ----------
    highpass
        ``(..., H, W)`` high-pass residual (frequencies above half Nyquist).
    bands
        Tuple of ``height`` arrays; level ``l`` is ``(..., 4, H_l, W_l)`` with
        ``H_{l+1} = ceil(H_l / 2)``, orientation ``b`` tuned to ``θ = π b / 4``
        (``cos³(θ − π b / 4)`` angular response; θ measured from the image's x
        axis towards +y, i.e. downwards).
    lowpass
        ``(..., H_height, W_height)`` low-pass residual; keeps the image mean.

    Coefficients are band-passed images sampled on each level's grid, so their
    amplitude does not depend on image size (pyrtools' ``SteerablePyramidFreq``
    bands equal these times ``H W / (H_l W_l)``).
    """

    highpass: np.ndarray
    bands: tuple[np.ndarray, ...]
    lowpass: np.ndarray

    @property
    def height(self) -> int:
        return len(self.bands)

    @property
    def shape(self) -> tuple[int, int]:
        return tuple(self.highpass.shape[-2:])

    def subbands(self) -> dict[str, np.ndarray]:
        """All subbands by name: ``highpass``, ``level{l}_orient{b}``, ``lowpass``."""
        out = {"highpass": self.highpass}
        for level, band in enumerate(self.bands):
            for b in range(ORIENTATIONS):
                out[f"level{level}_orient{b}"] = band[..., b, :, :]
        out["lowpass"] = self.lowpass
        return out


def band_names(height: int) -> tuple[str, ...]:
    """Names of the subbands of a pyramid of ``height`` levels, in storage order."""
    return ("highpass", *(f"level{lv}_orient{b}" for lv in range(height) for b in range(ORIENTATIONS)), "lowpass")


@functools.lru_cache(maxsize=16)
def _device_masks(shape: tuple[int, int], height: int, dtype: str) -> dict:
    return jax.tree_util.tree_map(lambda a: jnp.asarray(a, dtype), pyramid_masks(shape, height))


def _float_dtype(a: np.ndarray) -> np.dtype:
    return np.dtype(np.float64) if a.dtype == np.float64 else np.dtype(np.float32)


def _check_height(height: int, shape: tuple[int, int], what: str) -> int:
    top = max_pyramid_height(shape)
    if isinstance(height, bool) or not isinstance(height, (int, np.integer)) or not 0 <= height <= top:
        raise ValueError(
            f"height={height!r} is not possible for {what} of {shape[0]}x{shape[1]} pixels: "
            f"expected an integer in [0, {top}] (floor(log2(min side)) - 2)"
        )
    return int(height)


def build_steerable_pyramid(image, height: int = DEFAULT_HEIGHT) -> SteerablePyramid:
    """Steerable pyramid (4 orientations, frequency domain) of one image or a stack.

    Simoncelli & Freeman (1995) in the Fourier domain, as used by Heeger & Bergen
    (1995) and the image-based paper (section 4.2). With ``X`` the DFT of the
    image, normalised by ``H W``, and ``u = log2 r`` the log radial frequency
    (``r = 1`` at Nyquist):

    * highpass ``= IDFT(X hi0)``, ``hi0(u) = cos(π u / 2)`` on ``[−1, 0]``;
    * ``Z_0 = X lo0``, ``lo0 = sqrt(1 − hi0²)``;
    * band ``(l, b)`` ``= IDFT_l(i Z_l A_b(θ) hi(u + l + 1))`` with
      ``A_b(θ) = sqrt(0.8) cos³(θ − π b / 4)``;
    * ``Z_{l+1}`` = the coefficients of ``Z_l`` on a grid ``ceil(·/2)`` as large,
      times ``lo(u + l + 1)``; the lowpass residual is ``IDFT(Z_height)``.

    Since ``hi² + lo² = 1`` and ``Σ_b A_b² = 1`` the transform is a tight frame,
    and :func:`reconstruct_steerable_pyramid` inverts it exactly (to rounding)
    for every size, odd sizes included. Boundaries are periodic: apply
    :func:`periodic_smooth_decomposition` first to analyse a photograph.

    Parameters
    ----------
    image
        ``(..., H, W)`` real image(s). float64 input is transformed in float64,
        anything else in float32.
    height
        Number of band-pass levels, ``0 ≤ height ≤ floor(log2(min(H, W))) − 2``.

    Returns
    -------
    SteerablePyramid
        NumPy arrays in the working dtype.
    """
    a = np.asarray(image)
    if a.ndim < 2 or not np.issubdtype(a.dtype, np.number) or np.iscomplexobj(a):
        raise ValueError(f"image must be a real array of shape (..., H, W), got dtype {a.dtype} shape {a.shape}")
    dtype = _float_dtype(a)
    shape = tuple(a.shape[-2:])
    height = _check_height(height, shape, "an image")
    lead = a.shape[:-2]
    with jax.enable_x64(True):
        x = jnp.asarray(a.reshape(-1, *shape), dtype)
        hp, bands, lp = pyramid_build(x, _device_masks(shape, height, dtype.name), pyramid_shapes(shape, height))
        return SteerablePyramid(
            highpass=np.asarray(hp).reshape(*lead, *hp.shape[-2:]),
            bands=tuple(np.asarray(b).reshape(*lead, *b.shape[-3:]) for b in bands),
            lowpass=np.asarray(lp).reshape(*lead, *lp.shape[-2:]),
        )


def reconstruct_steerable_pyramid(pyramid: SteerablePyramid) -> np.ndarray:
    """Collapse a :class:`SteerablePyramid` back into an image (the exact inverse of the build).

    ``Z_l = pad(Z_{l+1} lo_l) + Σ_b DFT_l(band_lb) (−i A_b hi_l)``,
    ``X = Z_0 lo0 + DFT(highpass) hi0``, image ``= IDFT(X)``. Subbands may have been
    modified (that is what synthesis does); their shapes must be those a build
    of the same image size gives.

    Returns
    -------
    ndarray ``(..., H, W)`` in the pyramid's dtype (float32 or float64).
    """
    hp = np.asarray(pyramid.highpass)
    shape = tuple(hp.shape[-2:])
    height = len(pyramid.bands)
    _check_height(height, shape, "a pyramid")
    shapes = pyramid_shapes(shape, height)
    lead = hp.shape[:-2]
    for level, band in enumerate(pyramid.bands):
        want = (*lead, ORIENTATIONS, *shapes[level])
        if np.shape(band) != want:
            raise ValueError(f"pyramid.bands[{level}] has shape {np.shape(band)}, expected {want}")
    if np.shape(pyramid.lowpass) != (*lead, *shapes[-1]):
        raise ValueError(f"pyramid.lowpass has shape {np.shape(pyramid.lowpass)}, expected {(*lead, *shapes[-1])}")
    dtype = _float_dtype(hp)
    with jax.enable_x64(True):
        out = pyramid_reconstruct(
            jnp.asarray(hp.reshape(-1, *shape), dtype),
            tuple(jnp.asarray(np.reshape(b, (-1, ORIENTATIONS, *s)), dtype) for b, s in zip(pyramid.bands, shapes)),
            jnp.asarray(np.reshape(pyramid.lowpass, (-1, *shapes[-1])), dtype),
            _device_masks(shape, height, dtype.name),
            shapes,
        )
        return np.asarray(out).reshape(*lead, *shape)


def periodic_smooth_decomposition(image) -> tuple[np.ndarray, np.ndarray]:
    """Split ``image = periodic + smooth`` (Moisan 2011) so the FFT sees no border discontinuity.

    ``smooth`` solves the periodic discrete Poisson equation ``Δ s = v`` where
    ``v`` is zero except on the border, where it holds the jumps across the
    wrap-around edges (``v[0, :] = u[−1, :] − u[0, :] = −v[−1, :]``, likewise on
    columns); ``periodic = image − smooth``. ``smooth`` has zero mean and is
    harmonic inside the image, so the periodic component keeps the texture and
    drops the cross-shaped artefact a plain FFT has.

    Parameters
    ----------
    image
        ``(..., H, W)`` real image(s), float64 kept, others in float32.

    Returns
    -------
    periodic, smooth : ndarray ``(..., H, W)``
    """
    a = np.asarray(image)
    if a.ndim < 2 or not np.issubdtype(a.dtype, np.number) or np.iscomplexobj(a):
        raise ValueError(f"image must be a real array of shape (..., H, W), got dtype {a.dtype} shape {a.shape}")
    if not np.isfinite(a).all():
        raise ValueError("image holds NaN or inf; crop to valid pixels first (see largest_valid_rectangle)")
    dtype = _float_dtype(a)
    with jax.enable_x64(True):
        p, s = periodic_smooth(jnp.asarray(a.reshape(-1, *a.shape[-2:]), dtype))
        return np.asarray(p).reshape(a.shape), np.asarray(s).reshape(a.shape)
