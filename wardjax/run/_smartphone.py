"""A smartphone capture, end to end: the method on the photo and thresholds, then its outputs."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .._rules import RuleError, check_camera_correction
from ..capture import CAPTURE_FILE, CaptureError, SmartphoneCapture
from ..export import write_smartphone_outputs
from ..smartphone import chart_correction, fit_smartphone
from ..ward import WardParams

__all__ = ["fit_smartphone_capture"]


def fit_smartphone_capture(cap: SmartphoneCapture, out_dir: Path, *, created: str) -> dict:
    """Fit a smartphone capture and write ``params.json`` and ``material.rad`` into ``out_dir``.

    ``params.json`` follows the one schema (``wardjax.params/1``); the α
    posterior's 68/95 % intervals, autocorrelation time and acceptance go
    under ``fit.posterior``.
    """
    cfg = cap.config
    t = cfg.thresholds
    chart, cc = None, cfg.color_correction
    if cc is not None:
        try:
            chart = chart_correction(
                cap.photo,
                cc.regions(),
                decoding=cfg.photo.decoding,
                surface=tuple(cfg.photo.region),
                method=cc.method,
                degree=cc.degree,
                terms=cc.terms,
            )
            # a correction whose held-out ΔE says it failed (a grey photo, a reversed layout) is not applied
            check_camera_correction(cfg.photo.file, chart.delta_E_held_out[chart.usable])
        except RuleError as e:
            raise CaptureError(CAPTURE_FILE, "color_correction", e.message) from None
        except ValueError as e:  # too few usable patches for the method's terms
            raise CaptureError(CAPTURE_FILE, "color_correction", str(e).splitlines()[0]) from None
    try:
        params, stderr, post = fit_smartphone(
            cap.photo,
            tuple(cfg.photo.region),
            ppb=t.ppb,
            ppb_mean=t.ppb_mean,
            n_observers=t.n_observers,
            display=cfg.setup.display,
            viewing=cfg.setup.viewing,
            decoding=cfg.photo.decoding,
            n=cfg.specular.n,
            n_range=cfg.specular.n_range,  # validated into a (lo, hi) tuple
            seed=cfg.fit.seed,
            chart=chart,
        )
    except ValueError as e:  # thresholds out of the display's range, a region of one colour…
        raise CaptureError(CAPTURE_FILE, "thresholds", str(e).splitlines()[0]) from None
    err = WardParams.from_estimate(
        rho_d=np.asarray(stderr["rho_d"]), rho_s=stderr["rho_s"], alpha_x=stderr["alpha_x"], alpha_y=stderr["alpha_y"]
    )
    return write_smartphone_outputs(
        out_dir,
        name=cap.name,
        params=params,
        stderr=err,
        posterior=post,
        rho_s_source=f"Fresnel, n = {cfg.specular.n} (range {list(cfg.specular.n_range)})",
        inputs=cap.checksums,
        created=created,
        color_correction=None if chart is None else _color_summary(chart, stderr),
    )


def _color_summary(chart, stderr: dict) -> dict:
    """``fit.color_correction``: the chart's ΔE*ab and ρd's σ split into the region's and the colour error's."""
    return {
        **chart.summary(),
        "rho_d_sigma_region": [float(v) for v in stderr["rho_d_region"]],
        "rho_d_sigma_color": [float(v) for v in stderr["rho_d_color"]],
    }
