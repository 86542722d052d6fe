"""Colour handling of the smartphone method: sRGB decoding, Bradford adaptation, ΔE.

The diffuse reflectance of a surface is read from a well-exposed, white-balanced,
off-specular sRGB photograph (smartphone paper, section 3.1):

1. decode the 8-bit code values to linear light, either with the paper's pure
   power law ``V = (C/255)^2.2`` (``decoding="gamma2.2"``) or with the exact
   piecewise sRGB curve of IEC 61966-2-1 (``decoding="srgb"``);
2. change the white point of the linear sRGB values from D65 to illuminant E with
   the Bradford transform, keeping the sRGB primaries:

   .. math::

       \\mathrm{RGB}_E = M_E^{-1}\\, B_{D65\\to E}\\, M_{D65}\\, \\mathrm{RGB}_{D65}

   where ``M_W`` is the normalised primary matrix of the sRGB primaries with white
   ``W`` and ``B`` the Bradford von Kries matrix. A neutral stays neutral and R = G = B
   for a perfect white, so the channels read as reflectance factors;
3. average the region robustly (per channel, a mean after rejecting pixels more than
   3.5 robust standard deviations, 1.4826 × MAD, from the median).

ρd is therefore expressed in the sRGB primaries with white E, the convention
``params.json`` and Radiance use. colour-science does all colorimetry (it is called
at this boundary; no kernel is copied).

Colour differences: CIE 1976 ``ΔE*ab`` (the paper's) and CIEDE2000.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Literal

import colour
import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "DECODINGS",
    "Decoding",
    "decode_srgb",
    "delta_E_CIE1976",
    "delta_E_CIE2000",
    "diffuse_from_srgb",
    "diffuse_to_Lab",
    "Lab_to_diffuse",
    "luminance_from_rho_d",
    "matrix_rgb_D65_to_E",
    "validate_region",
    "validate_rgb_image",
]

Decoding = Literal["gamma2.2", "srgb"]
DECODINGS: tuple[str, ...] = ("gamma2.2", "srgb")

_SRGB = colour.RGB_COLOURSPACES["sRGB"]
_CCS = colour.CCS_ILLUMINANTS["CIE 1931 2 Degree Standard Observer"]
_WHITES = {"D65": _CCS["D65"], "E": _CCS["E"], "D50": _CCS["D50"]}
_MAD_TO_SIGMA = 1.4826
_CLIP_SIGMAS = 3.5


def _white_XYZ(name: str) -> NDArray:
    return colour.xy_to_XYZ(_WHITES[name])


def _npm(white: str) -> NDArray:
    """Normalised primary matrix: linear RGB (sRGB primaries, given white) → XYZ, Y(white) = 1."""
    return colour.normalised_primary_matrix(_SRGB.primaries, _WHITES[white])


def _bradford(source: str, target: str) -> NDArray:
    return colour.adaptation.matrix_chromatic_adaptation_VonKries(
        _white_XYZ(source), _white_XYZ(target), transform="Bradford"
    )


def matrix_rgb_D65_to_E() -> NDArray:
    """3×3 matrix taking linear sRGB (white D65) to linear RGB with sRGB primaries, white E.

    ``M_E⁻¹ · Bradford(D65→E) · M_D65``; it maps (1, 1, 1) to (1, 1, 1).
    """
    return np.linalg.inv(_npm("E")) @ _bradford("D65", "E") @ _npm("D65")


# ----------------------------------------------------------------------------- validation


def validate_rgb_image(image: ArrayLike, name: str = "image") -> NDArray:
    """Check that ``image`` is an RGB photo ``(H, W, 3)`` of uint8/uint16 codes or floats in [0, 1].

    Returns it as a NumPy array; raises one clear ``TypeError``/``ValueError`` otherwise.
    """
    if not isinstance(image, np.ndarray):
        try:
            image = np.asarray(image)
        except Exception as exc:  # pragma: no cover - exotic inputs
            raise TypeError(f"{name} must be an array (H, W, 3), got {type(image).__name__}") from exc
    if image.ndim != 3 or image.shape[-1] != 3:
        raise ValueError(
            f"{name} must be an RGB photo of shape (H, W, 3); got shape {image.shape}"
            + (" (greyscale?)" if image.ndim == 2 else "")
            + (" (RGBA? drop the alpha channel)" if image.ndim == 3 and image.shape[-1] == 4 else "")
        )
    if image.shape[0] == 0 or image.shape[1] == 0:
        raise ValueError(f"{name} is empty: shape {image.shape}")
    if image.dtype == np.uint8 or image.dtype == np.uint16:
        return image
    if np.issubdtype(image.dtype, np.floating):
        if not np.all(np.isfinite(image)):
            raise ValueError(f"{name} contains NaN or infinite values")
        if image.min() < 0.0 or image.max() > 1.0:
            raise ValueError(
                f"{name} is floating point with values in [{image.min():.3g}, {image.max():.3g}];"
                " expected encoded values in [0, 1] (or pass uint8/uint16 codes)"
            )
        return image
    raise TypeError(f"{name} must hold uint8, uint16 or float values; got dtype {image.dtype}")


def validate_region(region, shape: tuple[int, ...], name: str = "region") -> tuple[int, int, int, int]:
    """Check ``region = (y0, y1, x0, x1)`` (half-open, pixels) against an image shape ``(H, W, ...)``."""
    try:
        vals = tuple(region)
    except TypeError:
        raise TypeError(f"{name} must be a tuple (y0, y1, x0, x1) of integers; got {region!r}") from None
    if len(vals) != 4:
        raise ValueError(f"{name} must have four entries (y0, y1, x0, x1); got {region!r}")
    out = []
    for v in vals:
        if isinstance(v, (bool, np.bool_)) or not isinstance(v, (int, np.integer)):
            raise TypeError(f"{name} entries must be integers (pixel indices); got {region!r}")
        out.append(int(v))
    y0, y1, x0, x1 = out
    h, w = int(shape[0]), int(shape[1])
    if y1 <= y0 or x1 <= x0:
        raise ValueError(f"{name} {tuple(out)} is empty: need y0 < y1 and x0 < x1")
    if y0 < 0 or x0 < 0 or y1 > h or x1 > w:
        raise ValueError(f"{name} {tuple(out)} lies outside the {h}×{w} image (rows 0..{h}, columns 0..{w})")
    return y0, y1, x0, x1


# ----------------------------------------------------------------------------- decoding


def decode_srgb(values: ArrayLike, decoding: str = "gamma2.2") -> NDArray:
    """Encoded sRGB values → linear RGB (white D65).

    Parameters
    ----------
    values
        uint8 or uint16 code values, or floats already scaled to [0, 1].
    decoding
        ``"gamma2.2"``: ``V = C^2.2`` (the paper, section 3.1); ``"srgb"``: the exact
        IEC 61966-2-1 curve (linear segment below 0.04045, else ``((C+0.055)/1.055)^2.4``),
        via ``colour.cctf_decoding``.
    """
    if decoding not in DECODINGS:
        raise ValueError(f"decoding must be one of {DECODINGS}; got {decoding!r}")
    v = np.asarray(values)
    if v.dtype == np.uint8:
        c = v.astype(np.float64) / 255.0
    elif v.dtype == np.uint16:
        c = v.astype(np.float64) / 65535.0
    else:
        c = v.astype(np.float64)
    if decoding == "gamma2.2":
        return np.power(c, 2.2)
    return np.asarray(colour.cctf_decoding(c, function="sRGB"), dtype=np.float64)


def _robust_mean(pixels: NDArray) -> tuple[NDArray, NDArray, NDArray]:
    """Per-channel clipped mean of ``pixels (N, 3)``: mean, its standard error, and the count kept."""
    med = np.median(pixels, axis=0)
    mad = np.median(np.abs(pixels - med), axis=0) * _MAD_TO_SIGMA
    keep = np.abs(pixels - med) <= _CLIP_SIGMAS * np.maximum(mad, 1e-12)
    n = keep.sum(axis=0)
    mean = np.where(keep, pixels, 0.0).sum(axis=0) / n
    var = np.where(keep, (pixels - mean) ** 2, 0.0).sum(axis=0) / np.maximum(n - 1, 1)
    return mean, np.sqrt(var / n), n


def diffuse_from_srgb(
    image: ArrayLike,
    region: Sequence[float],
    *,
    decoding: str = "gamma2.2",
    return_stderr: bool = False,
):
    """Estimate RGB ρd from a white-balanced sRGB photo (smartphone paper, section 3.1).

    Parameters
    ----------
    image
        The photo, ``(H, W, 3)``: uint8/uint16 codes or floats in [0, 1], sRGB-encoded,
        white-balanced, exposed so a perfect white would just reach full scale.
    region
        ``(y0, y1, x0, x1)``, half-open pixel box over the surface (rows y, columns x).
    decoding
        ``"gamma2.2"`` (the paper) or ``"srgb"`` (exact IEC 61966-2-1 curve).
    return_stderr
        Also return the standard error of the region mean per channel.

    Returns
    -------
    rho_d : ndarray, shape (3,)
        Reflectance factors in linear RGB with sRGB primaries and white E:
        ``M_E⁻¹ B_{D65→E} M_D65 · mean(decode(C))``.
    stderr : ndarray, shape (3,)
        Only with ``return_stderr=True``: the standard error propagated through the
        same matrix (pixel noise and texture; not camera or exposure error).
    """
    img = validate_rgb_image(image)
    y0, y1, x0, x1 = validate_region(region, img.shape)
    lin = decode_srgb(img[y0:y1, x0:x1].reshape(-1, 3), decoding)
    mean, se, _ = _robust_mean(lin)
    m = matrix_rgb_D65_to_E()
    rho = m @ mean
    if return_stderr:
        return rho, np.sqrt((m**2) @ (se**2))
    return rho


# ----------------------------------------------------------------------------- colorimetry


def luminance_from_rho_d(rho_d: ArrayLike) -> NDArray | np.floating:
    """Luminance factor Y of ρd (sRGB primaries, white E); a scalar ρd is grey (Y = ρd).

    ``Y = M_E[1] · ρd`` — the middle row of the normalised primary matrix, which sums to 1.
    """
    r = np.asarray(rho_d, dtype=np.float64)
    if r.ndim == 0 or r.shape[-1] != 3:
        if r.ndim == 0:
            return r
        raise ValueError(f"rho_d must be a scalar or RGB (..., 3); got shape {r.shape}")
    return r @ _npm("E")[1]


def diffuse_to_Lab(rho_d: ArrayLike, white: str = "D50") -> NDArray:
    """ρd (sRGB primaries, white E) → XYZ (white E) → Bradford to ``white`` → CIELAB under ``white``.

    ``white="D50"`` is the paper's section 3.2 (ColorChecker against D50 references);
    ``white="E"`` its section 9.1.
    """
    r = np.asarray(rho_d, dtype=np.float64)
    xyz_e = r @ _npm("E").T
    xyz = xyz_e if white == "E" else xyz_e @ _bradford("E", white).T
    return np.asarray(colour.XYZ_to_Lab(xyz, _WHITES[white]))


def Lab_to_diffuse(Lab: ArrayLike, white: str = "D50") -> NDArray:
    """Inverse of :func:`diffuse_to_Lab`: CIELAB under ``white`` → ρd (sRGB primaries, white E)."""
    xyz = np.asarray(colour.Lab_to_XYZ(np.asarray(Lab, dtype=np.float64), _WHITES[white]))
    xyz_e = xyz if white == "E" else xyz @ _bradford(white, "E").T
    return xyz_e @ np.linalg.inv(_npm("E")).T


def delta_E_CIE1976(Lab1: ArrayLike, Lab2: ArrayLike) -> NDArray:
    """CIE 1976 colour difference ``ΔE*ab = ‖Lab1 − Lab2‖`` (the paper's ΔE_ab), via colour-science."""
    return np.asarray(colour.delta_E(np.asarray(Lab1, float), np.asarray(Lab2, float), method="CIE 1976"))


def delta_E_CIE2000(Lab1: ArrayLike, Lab2: ArrayLike) -> NDArray:
    """CIEDE2000 colour difference (Sharma, Wu & Dalal 2005), via colour-science."""
    return np.asarray(colour.delta_E(np.asarray(Lab1, float), np.asarray(Lab2, float), method="CIE 2000"))
