"""The smartphone method end to end: photo → ρd, Fresnel → ρs, thresholds → α posterior.

:func:`fit_smartphone` is the entry point the capture loader calls for
``method = "smartphone"`` folders.
"""

from __future__ import annotations

import numpy as np

from .._rules import check_camera_correction, check_photo_region
from ..capture import load_display, load_viewing
from ..ward import WardParams
from ._alpha_model import AlphaModel
from ._alpha_posterior import _as_thresholds
from ._chart_error import ChartCorrection, rho_d_color_sigma
from ._color import diffuse_from_srgb
from ._fresnel import specular_from_fresnel

__all__ = ["fit_smartphone"]


def fit_smartphone(
    photo_rgb,
    region,
    *,
    ppb=None,
    ppb_mean=None,
    n_observers=None,
    display="iphone5s",
    viewing="paper",
    decoding: str = "gamma2.2",
    n: float = 1.5,
    n_range: tuple[float, float] = (1.4, 1.7),
    seed: int = 0,
    model: AlphaModel | None = None,
    chart: ChartCorrection | None = None,
    **posterior_kwargs,
):
    """Ward parameters of a dielectric surface by the smartphone method.

    Parameters
    ----------
    photo_rgb
        White-balanced, off-specular sRGB photo ``(H, W, 3)`` (uint8/uint16 or floats in [0, 1]).
    region
        ``(y0, y1, x0, x1)`` over the surface.
    ppb
        Individual observers' whole-pixel threshold PPBs (the calibration set-up), or
    ppb_mean, n_observers
        a mean threshold over ``n_observers``.
    display, viewing
        Set-up names in ``calibration/smartphone_setup.toml`` (or ``Display``/``Viewing``).
        Thresholds from another set-up are mapped to the calibration set-up at equal
        cycles/degree and treated as a mean over the observers.
    decoding
        ``"gamma2.2"`` (paper) or ``"srgb"``.
    n, n_range
        Refractive index for ρs, and the plausible range whose spread is quoted as ±2σ.
    seed
        Sampler seed.
    chart
        A camera correction fitted on a ColorChecker (``chart_correction``): ρd is
        corrected by it, and its held-out error joins ρd's σ (``rho_d_color_sigma``).
        One whose median held-out ΔE*ab exceeds ``MAX_HELD_OUT_DELTA_E`` (10) failed
        (a uniform grey photo, patches read in the wrong order) and is refused.

    Returns
    -------
    params : WardParams
        ρd (RGB, sRGB primaries, white E), ρs (grey), ``alpha_x = alpha_y`` = posterior median.
    stderr : dict
        1σ: ``rho_d`` (3,) — the region's standard error and, with ``chart``, the
        correction's colour error in quadrature (both also apart: ``rho_d_region``,
        ``rho_d_color``; without a chart the camera's colour error is unknown and not
        included); ``rho_s`` — a quarter of the ρs spread
        over ``n_range`` (ρs is assumed, not measured); ``alpha_x``/``alpha_y`` — posterior SD;
        also ``alpha_interval_68`` and ``alpha_interval_95``.
    posterior : AlphaPosterior

    Raises
    ------
    ValueError
        :class:`~wardjax.capture.RuleError` when over half the region is black or clipped in a channel,
        or when ``chart``'s held-out ΔE*ab says the correction failed (``check_camera_correction``).
    """
    photo = np.asarray(photo_rgb)
    y0, y1, x0, x1 = region
    top = float(np.iinfo(photo.dtype).max) if np.issubdtype(photo.dtype, np.integer) else 1.0
    check_photo_region("photo_rgb", photo[y0:y1, x0:x1], top)  # a clipped region's ρd is 0 or 1 "± 0"
    rho_d, rho_d_se = diffuse_from_srgb(photo_rgb, region, decoding=decoding, return_stderr=True)
    rho_d_color = np.zeros(3)
    if chart is not None:
        check_camera_correction("chart", chart.delta_E_held_out[chart.usable])  # a failed correction is refused
        rho_d, rho_d_se = _corrected(chart, rho_d, rho_d_se)
        rho_d_color = rho_d_color_sigma(rho_d, chart.held_out_Lab)
    rho_s = specular_from_fresnel(n)
    lo, hi = np.asarray(specular_from_fresnel(np.asarray(n_range, dtype=float)))  # an array in, an array out
    model = model or AlphaModel.from_calibration()
    disp, view = load_display(display), load_viewing(viewing)
    same_setup = disp == model.display and view == model.viewing
    if not same_setup and ppb is not None:
        k = _as_thresholds(ppb, disp.ppb_min, disp.ppb_max)
        ppb_mean, n_observers, ppb = float(np.mean(model.to_model_ppb(k, disp, view))), len(k), None
    elif not same_setup:
        if ppb_mean is None:
            raise ValueError("give either ppb=[...] (individual thresholds) or ppb_mean= with n_observers=")
        ppb_mean = float(model.to_model_ppb(ppb_mean, disp, view))
    post = model.posterior(
        ppb=ppb,
        rho_d=np.clip(rho_d, 0.0, 1.0),
        ppb_mean=ppb_mean,
        n_observers=n_observers,
        seed=seed,
        **posterior_kwargs,
    )
    alpha = post.median
    params = WardParams.from_estimate(rho_d=rho_d, rho_s=rho_s, alpha_x=alpha, alpha_y=alpha)
    stderr = {
        "rho_d": np.sqrt(rho_d_se**2 + rho_d_color**2),
        "rho_d_region": rho_d_se,
        "rho_d_color": rho_d_color,
        "rho_s": float(abs(hi - lo) / 4.0),
        "alpha_x": post.std,
        "alpha_y": post.std,
        "alpha_interval_68": post.interval(0.68),
        "alpha_interval_95": post.interval(0.95),
    }
    return params, stderr, post


def _corrected(chart: ChartCorrection, rho_d, se, step: float = 1e-6):
    """ρd through the chart's correction, its region standard error through the correction's Jacobian."""
    rho = np.asarray(rho_d, dtype=np.float64)
    out = chart.correction.apply(rho[None])[0]
    h = step * np.maximum(rho, 1e-3)
    jac = np.stack([(chart.correction.apply((rho + h[i] * np.eye(3)[i])[None])[0] - out) / h[i] for i in range(3)], 1)
    return out, np.sqrt((jac**2) @ (np.asarray(se) ** 2))
