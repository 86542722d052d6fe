"""``params.json``: one document, schema ``wardjax.params/1``, for every method.

Parameter values with 1-σ errors, the normalisation they were fitted in, the
RGB space and white of ρd (linear, sRGB primaries, white E), fit quality, the
Radiance export's parameters, the software version and the inputs' checksums.
The one timestamp is ``created``; everything else depends only on the inputs.
"""

from __future__ import annotations

import numpy as np

from ..ward import WardParams
from ._radiance import RADIANCE_NORMALIZATION, radiance_rgb

__all__ = [
    "FIT_QUALITY_COLUMNS",
    "PARAMS_SCHEMA",
    "capture_fit_document",
    "fit_quality",
    "params_document",
    "smartphone_document",
    "software_version",
]

PARAMS_SCHEMA = "wardjax.params/1"
# What ``fit_quality`` returns, and the columns ``summary.csv`` gives it.
FIT_QUALITY_COLUMNS = ("weighted_chi2_per_dof", "residual_rms_sr-1", "residual_rms_relative")


def fit_quality(fit: dict) -> dict[str, float | None]:
    """A fit's quality, named by what was computed (``params.json``'s ``fit`` section).

    - ``weighted_chi2_per_dof``: ``χ²/dof = Σ w r² / dof`` with ``w = 1/σ²`` from
      the photographs' noise model (``fit.weighted``); about 1 when the model
      fits to the noise. ``None`` for a fit with unit weights, whose
      ``fit.reduced_chi2`` is ``Σ r²/dof``, a residual variance in sr⁻², not a χ².
    - ``residual_rms_sr-1``: the RMS of measured − fitted ``f_r`` (sr⁻¹) of a
      unit-weight fit (``fit.diagnostics.residuals``, else ``√(Σ r²/dof)``).
    - ``residual_rms_relative``: that RMS over the mean measured ``f_r``.

    All three are ``None`` for a method without a least-squares fit (the
    smartphone method's posterior).
    """
    out: dict[str, float | None] = dict.fromkeys(FIT_QUALITY_COLUMNS)
    rc = fit.get("reduced_chi2")
    if fit.get("weighted"):
        out["weighted_chi2_per_dof"] = None if rc is None else float(rc)
        return out
    res = fit.get("diagnostics", {}).get("residuals")
    if res:
        out["residual_rms_sr-1"], out["residual_rms_relative"] = float(res["rms"]), float(res["relative_rms"])
    elif rc is not None:
        out["residual_rms_sr-1"] = float(rc) ** 0.5
    return out


def params_dict(p: WardParams) -> dict:
    """The JSON form of one parameter set (ρd RGB, grey ρs, αx, αy)."""
    return {
        "rho_d": np.broadcast_to(np.asarray(p.rho_d, float), (3,)).tolist(),
        "rho_s": float(np.mean(p.rho_s)),
        "alpha_x": float(p.alpha_x),
        "alpha_y": float(p.alpha_y),
    }


def software_version() -> str:
    """wardjax's version, as written into every output."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("wardjax")
    except PackageNotFoundError:  # run from a source tree that was never installed
        return "0+unknown"


def params_document(
    *,
    name: str,
    method: str,
    model: str,
    normalization: str,
    params: WardParams,
    stderr: WardParams,
    fit: dict,
    radiance: dict,
    files: dict,
    inputs: dict,
    created: str,
    extra: dict | None = None,
) -> dict:
    """The ``params.json`` document; every method's writer calls this one builder.

    ``radiance`` holds the exported material: ``normalization``, ``params``,
    ``stderr`` (:class:`WardParams`), ``status``, ``tangent``; its ``color``
    (Radiance RGB) is added here.
    """
    rad = dict(radiance)
    rad_params = rad["params"]
    rad.update(
        params=params_dict(rad_params), stderr=params_dict(rad["stderr"]), color=radiance_rgb(rad_params.rho_d).tolist()
    )
    doc = {
        "schema": PARAMS_SCHEMA,
        "name": name,
        "method": method,
        "model": model,
        "normalization": normalization,
        "color_space": {"rgb": "linear", "primaries": "sRGB", "white": "E"},
        "params": params_dict(params),
        "stderr": params_dict(stderr),
        "fit": fit,
        "radiance": rad,
        "files": files,
        "software": {"name": "wardjax", "version": software_version()},
        "inputs": dict(sorted(inputs.items())),
        "created": created,
    }
    if extra:
        doc.update(extra)
    return doc


def capture_fit_document(fit, *, created: str, files: dict | None = None, extra: dict | None = None) -> dict:
    """``params.json`` of a scanline capture's fit (:class:`~wardjax.CaptureFit`)."""
    comb, rad = fit.combined, fit.radiance
    return params_document(
        name=fit.name,
        method=fit.method,
        model=fit.model,
        normalization=fit.normalization,
        params=fit.params,
        stderr=fit.stderr,
        fit={
            "status": comb.status.name.lower(),
            "chi2": comb.chi2,
            "dof": comb.dof,
            "reduced_chi2": comb.reduced_chi2,  # unit weights: Σ r²/dof, the residual variance in sr⁻²
            "weighted": False,
            "n_scanlines": comb.n_scanlines,
            "covariance": {
                "parameters": ["rho_s", "alpha"] if fit.model == "isotropic" else ["rho_s", "alpha_x", "alpha_y"],
                "matrix": comb.covariance,
            },
            "diagnostics": fit.diagnostics,
        },
        radiance={
            "normalization": RADIANCE_NORMALIZATION,
            "params": rad.params,
            "stderr": rad.stderr,
            "status": rad.status.name.lower(),
            "tangent": list(fit.tangent),
        },
        files=files or {},
        inputs=fit.checksums,
        created=created,
        extra=extra,
    )


def smartphone_document(
    *,
    name: str,
    params: WardParams,
    stderr: WardParams,
    posterior,
    rho_s_source: str,
    files: dict,
    inputs: dict,
    created: str,
    color_correction: dict | None = None,
) -> dict:
    """``params.json`` of a smartphone capture: α's posterior under ``fit.posterior``.

    ``color_correction`` (the chart's ΔE*ab and ρd's σ split into region and colour
    error) goes under ``fit.color_correction`` when the capture asked for one.

    Radiance's ``plastic`` takes the estimates as they are: the smartphone α
    is a lobe width from a visual model, not a least-squares fit in one
    normalisation, so there is nothing to refit.
    """
    post = posterior
    lo68, hi68 = post.interval(0.68)
    lo95, hi95 = post.interval(0.95)
    return params_document(
        name=name,
        method="smartphone",
        model="isotropic",
        normalization="ward1992",
        params=params,
        stderr=stderr,
        fit={
            "status": "converged",
            "posterior": {
                "alpha_mean": float(post.mean),
                "alpha_median": float(post.median),
                "alpha_interval_68": [float(lo68), float(hi68)],
                "alpha_interval_95": [float(lo95), float(hi95)],
                "autocorrelation_time": float(max(dict(post.tau).values())),  # the slowest parameter
                "acceptance": float(np.mean(post.acceptance)),
                # chain length and effective sample size, N·W/τ (emcee's integrated autocorrelation time)
                "n_steps": int(post.n_steps),
                "n_walkers": int(post.n_walkers),
                "effective_samples": float(post.n_steps * post.n_walkers / max(dict(post.tau).values())),
            },
            "rho_s_source": rho_s_source,
            **({"color_correction": color_correction} if color_correction is not None else {}),
        },
        radiance={
            "normalization": "ward1992",
            "params": params,
            "stderr": stderr,
            "status": "converged",
            "tangent": [1.0, 0.0],
        },
        files=files,
        inputs=inputs,
        created=created,
    )
