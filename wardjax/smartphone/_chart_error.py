"""A ColorChecker in the photo: the camera correction it gives, and the colour error it leaves in ρd.

The chart's own patches score the correction: each usable patch is corrected
by a fit on all the others and compared with its published colour, giving a
held-out CIELAB residual ``r_k = Lab(ρd'_k) − Lab_ref,k`` (D50) per patch —
the leave-one-out ΔE*ab is ``|r_k|``. Those residuals are the correction's
error on a colour it never saw, so they are also the error on the surface's
corrected ρd: ``rho_d_color_sigma`` moves the surface's colour by each
residual in CIELAB and takes the spread of ρd that results,

    σ_c = √( (1/K) Σ_k (ρ_c(Lab_s + r_k) − ρ_c,s)² ),

a non-parametric propagation (no Jacobian: CIELAB is non-linear in ρd, most
of all in a dark channel). Its ΔE*ab equivalent is about the RMS held-out ΔE of the
chart; that it also predicts each patch's error is what
``tests/test_chart_error.py`` checks on the real PlantCV photo (RMS of the
error/σ ratio over 23 patches × 3 channels within [0.5, 2]).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ._color import Lab_to_diffuse, decode_srgb, diffuse_to_Lab, validate_rgb_image
from ._colorchecker import (
    CameraCorrection,
    colorchecker_held_out_Lab,
    colorchecker_reference_Lab,
    colorchecker_rho_d,
    fit_camera_correction,
)

__all__ = ["ChartCorrection", "chart_correction", "rho_d_color_sigma"]


class ChartCorrection(NamedTuple):
    """A camera correction fitted on a ColorChecker in the photo, with its held-out error.

    Attributes
    ----------
    correction
        The correction fitted on every usable patch (``CameraCorrection``).
    usable
        ``(24,)`` bool: patches the fit used (not clipped, black, or under the surface's region).
    rho_d_raw
        ``(24, 3)`` ρd of each patch box before correction (sRGB primaries, white E).
    delta_E_raw
        ``(24,)`` ΔE*ab (D50) of the uncorrected patches against the chart; NaN where unusable.
    held_out_Lab
        ``(24, 3)`` leave-one-out CIELAB residual of each usable patch; NaN rows elsewhere.
    """

    correction: CameraCorrection
    usable: NDArray
    rho_d_raw: NDArray
    delta_E_raw: NDArray
    held_out_Lab: NDArray

    @property
    def delta_E_held_out(self) -> NDArray:
        """``(24,)`` leave-one-out ΔE*ab (D50) per patch; NaN where unusable."""
        return np.linalg.norm(self.held_out_Lab, axis=-1)

    def summary(self) -> dict:
        """The figures ``params.json`` keeps under ``fit.color_correction`` (ΔE*ab, D50)."""
        d_raw, d_loo = self.delta_E_raw[self.usable], self.delta_E_held_out[self.usable]
        c = self.correction
        return {
            "chart": "ColorChecker24 - After November 2014 (colour-science), CIELAB D50",
            "method": c.method,
            "options": dict(c.options),
            "tone_exponent": float(c.gamma),
            "patches_used": int(self.usable.sum()),
            "delta_E_uncorrected": {"mean": float(np.mean(d_raw)), "max": float(np.max(d_raw))},
            "delta_E_held_out": {
                "mean": float(np.mean(d_loo)),
                "rms": float(np.sqrt(np.mean(d_loo**2))),
                "max": float(np.max(d_loo)),
            },
        }


def rho_d_color_sigma(rho_d: ArrayLike, held_out_Lab: ArrayLike) -> NDArray:
    """1σ of a corrected ρd from the chart's held-out CIELAB residuals (module docstring), shape (3,).

    Parameters
    ----------
    rho_d
        The surface's corrected ρd, ``(3,)`` (sRGB primaries, white E).
    held_out_Lab
        ``(K, 3)`` residuals (rows with NaN are skipped), e.g. ``ChartCorrection.held_out_Lab``.
    """
    rho = np.asarray(rho_d, dtype=np.float64)
    r = np.asarray(held_out_Lab, dtype=np.float64)
    r = r[np.all(np.isfinite(r), axis=-1)]
    if r.shape[0] < 2:
        raise ValueError(f"the colour error needs ≥ 2 held-out patches; got {r.shape[0]}")
    lab = diffuse_to_Lab(np.clip(rho, 1e-6, None)[None], "D50")[0]
    moved = Lab_to_diffuse(lab[None] + r, "D50")
    return np.sqrt(np.mean((moved - rho) ** 2, axis=0))


def _overlaps(a: Sequence[int], b: Sequence[int]) -> bool:
    return a[0] < b[1] and b[0] < a[1] and a[2] < b[3] and b[2] < a[3]


def chart_correction(
    photo: ArrayLike,
    regions: Sequence[Sequence[int]],
    *,
    decoding: str = "gamma2.2",
    surface: Sequence[int] | None = None,
    method: str = "Finlayson 2015",
    degree: int = 2,
    terms: int = 3,
) -> ChartCorrection:
    """Fit the camera correction on a ColorChecker 24 in ``photo`` and score it patch by patch.

    Parameters
    ----------
    photo
        The sRGB photo ``(H, W, 3)`` holding the chart (uint8/uint16 or floats in [0, 1]).
    regions
        24 boxes ``(y0, y1, x0, x1)`` in chart order (dark skin … black), e.g. from
        ``wardjax.smartphone.colorchecker_patch_regions``.
    decoding
        The photo's decoding, as for the surface.
    surface
        The surface's region: a patch whose box overlaps it is left out of the fit (a
        surface is never corrected with its own reference).
    method, degree, terms
        the options of ``wardjax.smartphone.fit_camera_correction``.

    Raises
    ------
    ValueError
        Fewer usable patches than the method has terms plus one.
    """
    img = validate_rgb_image(photo)
    if len(regions) != 24:
        raise ValueError(f"a ColorChecker 24 needs 24 patch boxes; got {len(regions)}")
    ref = colorchecker_reference_Lab("chromaticities")
    raw = colorchecker_rho_d(img, regions, decoding=decoding)
    # A patch whose median is at full scale (1 after decoding) or 0 in a channel reads the clip, not the chart.
    boxes = [img[y0:y1, x0:x1].reshape(-1, 3) for y0, y1, x0, x1 in regions]
    med = np.array([np.median(decode_srgb(b, decoding), axis=0) for b in boxes])
    usable = np.all((med > 0.0) & (med < 1.0), axis=-1)
    if surface is not None:
        usable &= np.array([not _overlaps(r, surface) for r in regions])
    options = {"method": method, "degree": degree, "terms": terms}
    corr = fit_camera_correction(raw[usable], ref[usable], **options)
    held = colorchecker_held_out_Lab(raw, ref, usable=usable, **options)
    d_raw = np.where(usable, np.linalg.norm(diffuse_to_Lab(np.clip(raw, 1e-6, None), "D50") - ref, axis=-1), np.nan)
    return ChartCorrection(corr, usable, raw, d_raw, held)
