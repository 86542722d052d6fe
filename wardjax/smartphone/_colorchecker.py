"""ColorChecker validation of the ρd method (smartphone paper, section 3.2).

- :func:`colorchecker_reference_Lab`: the 24 reference CIELAB values under D50, either
  from colour-science's published chromaticities (``"ColorChecker24 - After November
  2014"``, X-Rite's) or computed from its reflectance spectra under D50.
- :func:`simulate_colorchecker_photo`: a synthetic, ideal camera's photo of the chart.
- :func:`colorchecker_patch_regions`: patch boxes from a manual grid layout.
- :func:`fit_camera_correction`: a chart-based camera correction: a tone exponent from the
  neutral patches, then colour-science's characterisation (``"Finlayson 2015"``
  root-polynomial by default, ``"Cheung 2004"`` polynomial) in linear RGB, white E.
- ``colorchecker_held_out_delta_E``: its leave-one-out ΔE*ab per patch
  (``colorchecker_held_out_Lab``: the CIELAB residual behind it).
"""

from __future__ import annotations

import io
from collections.abc import Sequence
from dataclasses import dataclass, field

import colour
import imageio.v3 as iio
import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..capture import grid_boxes
from ._color import Lab_to_diffuse, delta_E_CIE1976, diffuse_from_srgb, diffuse_to_Lab, luminance_from_rho_d

__all__ = [
    "COLORCHECKER_NAMES",
    "CORRECTION_METHODS",
    "CameraCorrection",
    "colorchecker_delta_E",
    "colorchecker_held_out_delta_E",
    "colorchecker_held_out_Lab",
    "colorchecker_patch_regions",
    "colorchecker_reference_Lab",
    "colorchecker_rho_d",
    "fit_camera_correction",
    "simulate_colorchecker_photo",
]

_CC_CHROMATICITIES = "ColorChecker24 - After November 2014"
_CC_SPECTRA = "BabelColor Average"
_CMFS = "CIE 1931 2 Degree Standard Observer"

COLORCHECKER_NAMES: tuple[str, ...] = tuple(colour.CCS_COLOURCHECKERS[_CC_CHROMATICITIES].data.keys())
"""Patch names in chart order: row by row, dark skin (1) … black (24)."""


def _sds():
    sds = colour.SDS_COLOURCHECKERS[_CC_SPECTRA]
    return [sds[name] for name in sds]


def _XYZ_of_spectra(illuminant: str) -> NDArray:
    """XYZ (perfect white: Y = 1) of the 24 chart spectra under a CIE illuminant."""
    sds = _sds()
    shape = sds[0].shape  # 380–730 nm, 10 nm: align the CMFs and illuminant to it
    cmfs = colour.MSDS_CMFS[_CMFS].copy().align(shape)
    ill = colour.SDS_ILLUMINANTS[illuminant].copy().align(shape)
    return np.array([colour.sd_to_XYZ(sd, cmfs, ill, method="Integration") for sd in sds]) / 100.0


def colorchecker_reference_Lab(source: str = "chromaticities") -> NDArray:
    """Reference CIELAB (D50) of the 24 patches, in chart order, shape (24, 3).

    ``source="chromaticities"``: colour-science's ``CCS_COLOURCHECKERS["ColorChecker24 -
    After November 2014"]`` (X-Rite, D50). ``source="spectra"``: its
    ``SDS_COLOURCHECKERS["BabelColor Average"]`` spectra integrated under D50 (CIE 1931 2°).
    """
    if source == "chromaticities":
        cc = colour.CCS_COLOURCHECKERS[_CC_CHROMATICITIES]
        xyY = np.array(list(cc.data.values()))
        return np.asarray(colour.XYZ_to_Lab(colour.xyY_to_XYZ(xyY), cc.illuminant))
    if source == "spectra":
        d50 = colour.CCS_ILLUMINANTS[_CMFS]["D50"]
        return np.asarray(colour.XYZ_to_Lab(_XYZ_of_spectra("D50"), d50))
    raise ValueError(f"source must be 'chromaticities' or 'spectra'; got {source!r}")


def simulate_colorchecker_photo(
    *,
    patch_px: int = 32,
    gap_px: int = 8,
    jpeg_quality: int | None = 95,
    clip: bool = True,
    quantize: bool = True,
) -> tuple[NDArray, list[tuple[int, int, int, int]]]:
    """Photo of the chart by an ideal sRGB camera under D65, and the 24 patch boxes.

    Each patch's XYZ is its spectrum (BabelColor Average) under CIE D65, scaled so a
    perfect white has Y = 1; the camera is white-balanced to D65, so XYZ → linear sRGB
    with no adaptation, and a perfect white gives RGB = (1, 1, 1) before encoding. The
    values are clipped to [0, 1] (``clip``), encoded with the exact sRGB curve, rounded to
    8 bits (``quantize``) and, when ``jpeg_quality`` is set, written and read back as a
    JPEG through imageio. The chart is laid out in its usual 4 rows × 6 columns on a
    mid-grey surround.

    Returns
    -------
    image : ndarray
        ``uint8 (H, W, 3)`` when quantised, else float in [0, 1] (or beyond without clip).
    regions : list of (y0, y1, x0, x1)
        Central boxes (inner half of each patch), chart order.
    """
    rgb_lin = np.asarray(colour.XYZ_to_RGB(_XYZ_of_spectra("D65"), "sRGB", apply_cctf_encoding=False))
    if clip:
        rgb_lin = np.clip(rgb_lin, 0.0, 1.0)
    enc = np.sign(rgb_lin) * np.asarray(colour.cctf_encoding(np.abs(rgb_lin), function="sRGB"))
    pitch = patch_px + gap_px
    h, w = 4 * pitch + gap_px, 6 * pitch + gap_px
    img = np.full((h, w, 3), float(colour.cctf_encoding(0.18, function="sRGB")))
    regions = []
    q = patch_px // 4
    for i in range(24):
        r, c = divmod(i, 6)
        y0, x0 = gap_px + r * pitch, gap_px + c * pitch
        img[y0 : y0 + patch_px, x0 : x0 + patch_px] = enc[i]
        regions.append((y0 + q, y0 + patch_px - q, x0 + q, x0 + patch_px - q))
    if not quantize:
        return img, regions
    img8 = np.round(np.clip(img, 0.0, 1.0) * 255.0).astype(np.uint8)
    if jpeg_quality is not None:
        buf = io.BytesIO()
        iio.imwrite(buf, img8, extension=".jpg", quality=int(jpeg_quality))
        img8 = iio.imread(buf.getvalue(), extension=".jpg")
    return img8, regions


def colorchecker_patch_regions(
    first_center: tuple[float, float],
    pitch: tuple[float, float],
    grid: tuple[int, int],
    half_size: int,
    order: Sequence[int],
) -> list[tuple[int, int, int, int]]:
    """Boxes around a regular grid of patch centres, returned in chart order.

    Parameters
    ----------
    first_center
        ``(y, x)`` pixel centre of the grid's top-left patch.
    pitch
        ``(dy, dx)`` centre-to-centre spacing in pixels.
    grid
        ``(rows, cols)`` of the grid as it appears in the image.
    half_size
        Box half-width: each box is ``(yc − h, yc + h + 1, xc − h, xc + h + 1)``.
    order
        For each grid cell in row-major image order, the chart index (0–23) it shows.
    """
    rows, cols = grid
    if len(order) != rows * cols or sorted(order) != list(range(rows * cols)):
        raise ValueError(f"order must be a permutation of 0..{rows * cols - 1}; got {list(order)}")
    return grid_boxes(first_center, pitch, grid, half_size, order)


def colorchecker_rho_d(image: ArrayLike, regions, *, decoding: str = "gamma2.2") -> NDArray:
    """ρd (sRGB primaries, white E) of each patch box, shape (len(regions), 3)."""
    return np.array([diffuse_from_srgb(image, r, decoding=decoding) for r in regions])


CORRECTION_METHODS: tuple[str, ...] = ("Finlayson 2015", "Cheung 2004", "Vandermonde")
"""colour-science's colour-correction methods (``colour.MATRIX_COLOUR_CORRECTION_METHODS``)."""

_NEUTRAL_CHROMA = 4.0  # C*ab below which a reference patch counts as neutral (the chart's greys: < 1.5)


@dataclass(frozen=True)
class CameraCorrection:
    """Chart-based camera correction: a tone exponent, then colour-science's colour correction.

    ``ρd' = apply_matrix_colour_correction(ρd^γ, M, method, **options)`` in linear RGB (sRGB
    primaries, white E). ``γ`` corrects a camera whose tone curve is not the assumed
    decoding (γ = 1: none); ``M`` (3 × terms) maps the ``method``'s expansion of the
    linearised RGB to the reference: for ``"Finlayson 2015"`` the root-polynomial terms of
    ``degree`` (e.g. degree 2: R, G, B, √RG, √GB, √RB — exposure-invariant), for
    ``"Cheung 2004"`` a polynomial of ``terms`` terms (3: a plain 3×3 matrix).
    """

    gamma: float
    method: str
    matrix: NDArray
    options: dict = field(default_factory=dict)

    def apply(self, rho_d: ArrayLike) -> NDArray:
        r = np.clip(np.asarray(rho_d, dtype=np.float64), 1e-6, None)
        out = colour.characterisation.apply_matrix_colour_correction(
            r**self.gamma, self.matrix, method=self.method, **self.options
        )
        return np.asarray(out)


# The tone exponents a decoded camera photo can need (1: the decoding was right). Outside them the grey patches
# do not show the chart's white-to-black ramp, and the correction built on the exponent would overflow.
_TONE_EXPONENTS = (0.2, 5.0)


def _tone_exponent(x: NDArray, ref_rgb: NDArray, reference_Lab: NDArray) -> float:
    """γ of ``Y_ref ∝ Y(ρd)^γ``, by a log–log line through the chart's neutral patches."""
    neutral = np.hypot(reference_Lab[:, 1], reference_Lab[:, 2]) < _NEUTRAL_CHROMA
    if neutral.sum() < 2:
        raise ValueError(f"the tone exponent needs ≥ 2 neutral patches (C*ab < {_NEUTRAL_CHROMA}); got {neutral.sum()}")
    y_cam = np.asarray(luminance_from_rho_d(x[neutral]))
    y_ref = np.asarray(luminance_from_rho_d(ref_rgb[neutral]))
    if np.ptp(np.log(y_cam)) < 1e-3:  # the chart runs from white to black: one level is no photo of it
        raise ValueError(
            f"the chart's {int(neutral.sum())} grey patches all read one level (Y = {float(np.mean(y_cam)):.3g}); "
            "the tone curve cannot be fitted: check the chart photo and the patch layout"
        )
    gamma = float(np.polyfit(np.log(y_cam), np.log(y_ref), 1)[0])
    if not _TONE_EXPONENTS[0] <= gamma <= _TONE_EXPONENTS[1]:
        raise ValueError(
            f"the chart's grey patches give a tone exponent of {gamma:.3g}; a decoded photo's lies near 1 "
            f"({_TONE_EXPONENTS[0]:g} to {_TONE_EXPONENTS[1]:g} allowed): check the chart photo and the patch layout"
        )
    return gamma


def fit_camera_correction(
    rho_d: ArrayLike,
    reference_Lab: ArrayLike,
    *,
    method: str = "Finlayson 2015",
    degree: int = 2,
    terms: int = 3,
    tone: bool = True,
) -> CameraCorrection:
    """Fit a :class:`CameraCorrection` to chart patches with colour-science's characterisation.

    The references are taken to linear RGB (sRGB primaries, white E) through CIELAB D50, and
    ``colour.matrix_colour_correction`` fits ``M`` by least squares on those values.

    Parameters
    ----------
    rho_d
        The method's ρd of the patches, (N, 3); leave out clipped patches.
    reference_Lab
        Their reference CIELAB under D50, (N, 3).
    method
        One of :data:`CORRECTION_METHODS`: ``"Finlayson 2015"`` (root-polynomial, Finlayson,
        Mackiewicz & Hurlbert 2015, of ``degree``), ``"Cheung 2004"`` (polynomial of ``terms``
        terms) or ``"Vandermonde"`` (of ``degree``).
    tone
        First fit the tone exponent γ: a straight line of log reference luminance against
        log camera luminance through the neutral patches among ``rho_d`` (reference
        C*ab < 4); else γ = 1.
    """
    x = np.asarray(rho_d, dtype=np.float64)
    ref = np.asarray(reference_Lab, dtype=np.float64)
    if method not in CORRECTION_METHODS:
        raise ValueError(f"method must be one of {CORRECTION_METHODS}; got {method!r}")
    options = {"terms": int(terms)} if method == "Cheung 2004" else {"degree": int(degree)}
    if x.ndim != 2 or x.shape[-1] != 3 or ref.shape != x.shape:
        raise ValueError(f"rho_d and reference_Lab must both be (N, 3); got {x.shape} and {ref.shape}")
    x = np.clip(x, 1e-6, None)
    ref_rgb = np.asarray(Lab_to_diffuse(ref, "D50"))
    g = _tone_exponent(x, ref_rgb, ref) if tone else 1.0
    n_terms = np.asarray(colour.characterisation.polynomial_expansion(x[:2], method, **options)).shape[-1]
    if x.shape[0] < n_terms:
        raise ValueError(f"{method} with {options} has {n_terms} terms; it needs ≥ {n_terms} patches, got {x.shape[0]}")
    m = colour.matrix_colour_correction(x**g, ref_rgb, method=method, **options)
    return CameraCorrection(gamma=g, method=method, matrix=np.asarray(m), options=options)


def colorchecker_held_out_delta_E(
    rho_d: ArrayLike,
    reference_Lab: ArrayLike,
    *,
    usable: ArrayLike | None = None,
    **fit_options,
) -> NDArray:
    """Leave-one-out ΔE*ab (D50) of :func:`fit_camera_correction` over a chart's patches.

    Each usable patch is corrected by a fit on all the other usable patches and compared with
    its reference; unusable patches (e.g. clipped ones, ``usable`` False) are neither fitted
    nor scored (NaN). ``fit_options`` go to ``fit_camera_correction``. Shape (N,): the
    norm of ``colorchecker_held_out_Lab``.
    """
    return np.linalg.norm(colorchecker_held_out_Lab(rho_d, reference_Lab, usable=usable, **fit_options), axis=-1)


def colorchecker_held_out_Lab(
    rho_d: ArrayLike, reference_Lab: ArrayLike, *, usable: ArrayLike | None = None, **fit_options
) -> NDArray:
    """Leave-one-out CIELAB residual (D50) of ``fit_camera_correction`` per patch, shape (N, 3).

    Row ``k``: ``Lab(correction fitted without k applied to patch k) − reference_Lab[k]``;
    NaN for patches that are not ``usable`` (neither fitted nor scored). Its norm is
    ``colorchecker_held_out_delta_E``.
    """
    x = np.asarray(rho_d, dtype=np.float64)
    ref = np.asarray(reference_Lab, dtype=np.float64)
    ok = np.ones(x.shape[0], bool) if usable is None else np.asarray(usable, bool)
    if ok.shape != x.shape[:1]:
        raise ValueError(f"usable must have shape ({x.shape[0]},); got {ok.shape}")
    out = np.full(x.shape, np.nan)
    for k in np.flatnonzero(ok):
        fit = ok.copy()
        fit[k] = False
        corr = fit_camera_correction(x[fit], ref[fit], **fit_options)
        out[k] = diffuse_to_Lab(corr.apply(x[k : k + 1]), "D50")[0] - ref[k]
    return out


def colorchecker_delta_E(rho_d: ArrayLike, reference_Lab: ArrayLike) -> NDArray:
    """Per-patch CIE 1976 ΔE*ab of ρd → Lab (D50, section 3.2) against the reference."""
    return delta_E_CIE1976(diffuse_to_Lab(rho_d, "D50"), reference_Lab)
