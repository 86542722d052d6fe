"""The figures of a batch report: errors by model, the ρd texture and a synthesised tile, the batch."""

from __future__ import annotations

import json

import numpy as np
from matplotlib.figure import Figure
from matplotlib.ticker import NullFormatter

from ..effects import gap_figure as effects_gap_figure
from ..texture import TextureModel, read_rho_d, synthesize_texture
from ._collect import PARAMETERS, CaptureResult, load_chains

__all__ = [
    "batch_figure",
    "corner_figure",
    "errors_figure",
    "gap_figure",
    "residual_figure",
    "texture_figure",
    "trace_figure",
]

_LABELS = {"rho_d": r"$\rho_d$ (mean RGB)", "rho_s": r"$\rho_s$", "alpha_x": r"$\alpha_x$", "alpha_y": r"$\alpha_y$"}
_MODELS = (
    ("texture_field", "texture field (reported)"),
    ("scanline_sandwich", "scanline sandwich"),
    ("model", "Gauss–Newton model"),
)


def errors_figure(result: CaptureResult) -> Figure | None:
    """1-σ of the shared parameters by each error model (scanline captures); the α posterior (smartphone)."""
    fit = result.doc["fit"]
    fig = Figure(figsize=(6.4, 2.0 if "posterior" in fit else 3.0), dpi=100)
    ax = fig.add_subplot(1, 1, 1)
    if "posterior" in fit:
        post = fit["posterior"]
        lo95, hi95 = post["alpha_interval_95"]
        lo68, hi68 = post["alpha_interval_68"]
        ax.plot([lo95, hi95], [0, 0], color="C0", lw=2, label="95 % interval")
        ax.plot([lo68, hi68], [0, 0], color="C0", lw=6, label="68 % interval")
        ax.plot([post["alpha_median"]], [0], "o", color="C3", label="median")
        ax.set_yticks([])
        ax.set_xlabel(r"$\alpha$ (posterior; dimensionless)")
        ax.legend(fontsize=8, loc="upper right", frameon=False)
        ax.set_title(f"{result.name}: α posterior", fontsize=9)
        fig.tight_layout()
        return fig
    errors = fit.get("diagnostics", {}).get("errors")
    if not errors:
        return None
    names = fit["covariance"]["parameters"]
    x = np.arange(len(names))
    width = 0.8 / len(_MODELS)
    for k, (key, label) in enumerate(_MODELS):
        ax.bar(x + (k - 1) * width, errors[key], width, label=label, color=f"C{k}")
    ax.set_xticks(x, [r"$\alpha$" if n == "alpha" else _LABELS.get(n, str(n)) for n in names])
    ax.set_yscale("log")
    ax.set_ylabel("1σ (dimensionless, log scale)")
    ax.set_title(f"{result.name}: 1σ of the shared parameters by error model", fontsize=9)
    ax.legend(fontsize=7.5, frameon=False, loc="upper left", bbox_to_anchor=(1.0, 1.0))
    fig.tight_layout()
    return fig


def texture_figure(result: CaptureResult, tile: int = 128, seed: int = 0) -> Figure | None:
    """The measured ρd (mean over RGB, with its colour scale) and a tile synthesised from ``texture.json``."""
    tif, model = result.folder / "rho_d.tif", result.folder / "texture.json"
    if not tif.is_file():
        return None
    rho = read_rho_d(tif)
    grey = np.mean(rho, axis=-1) if rho.ndim == 3 else rho  # NaN where any channel is (off the probe)
    rows, cols = np.flatnonzero(np.isfinite(grey).any(axis=1)), np.flatnonzero(np.isfinite(grey).any(axis=0))
    if rows.size:  # crop to the probe
        grey = grey[rows[0] : rows[-1] + 1, cols[0] : cols[-1] + 1]
    panels = 2 if model.is_file() else 1
    fig = Figure(figsize=(3.4 * panels + 0.6, 3.1), dpi=100)
    ax = fig.add_subplot(1, panels, 1)
    finite = grey[np.isfinite(grey)]
    lo, hi = np.percentile(finite, [1, 99]) if finite.size else (0.0, 1.0)
    im = ax.imshow(np.ma.masked_invalid(grey), cmap="gray", vmin=lo, vmax=hi)
    fig.colorbar(im, ax=ax, label=r"$\rho_d$ (mean RGB, dimensionless)", fraction=0.046)
    ax.set_title("measured ρd over the probe (white: unusable)", fontsize=8.5)
    ax.set_xlabel("x (px, from the probe's first column)")
    ax.set_ylabel("y (px)")
    if panels == 2:
        synth = synthesize_texture(TextureModel.load(model), (tile, tile), seed=seed, iterations=3).image
        ax2 = fig.add_subplot(1, 2, 2)
        g2 = np.mean(np.asarray(synth), axis=-1) if np.ndim(synth) == 3 else np.asarray(synth)
        im2 = ax2.imshow(g2, cmap="gray", vmin=lo, vmax=hi)
        fig.colorbar(im2, ax=ax2, label=r"$\rho_d$ (mean RGB, dimensionless)", fraction=0.046)
        ax2.set_title(f"synthesised {tile}×{tile} tile (texture.json)", fontsize=8.5)
        ax2.set_xlabel("x (px)")
        ax2.set_ylabel("y (px)")
    fig.tight_layout()
    return fig


def gap_figure(result: CaptureResult) -> Figure | None:
    """The missing-effect gap after each step, when ``wardjax diagnose`` wrote ``report.json`` beside the fit."""
    found = sorted(result.folder.glob("**/report.json"))
    if not found:
        return None
    rep = json.loads(found[0].read_text(encoding="utf-8"))
    gaps = rep.get("gap")
    if not gaps:
        return None
    names = ["baseline", *(f"+ {n}" for n in rep.get("found", []))]
    return effects_gap_figure(gaps, names, title=f"{result.name}: missing-effect discovery")


def residual_figure(result: CaptureResult) -> Figure | None:
    """Measured ``f_r`` and the residual (measured − joint fit) over the image, from ``residuals.npz``.

    Both at the fit's binning, placed at their image pixels; the residual's
    colour scale is symmetric about 0 (red: the model is too low).
    """
    path = result.folder / "residuals.npz"
    if not path.is_file():
        return None
    with np.load(path) as z:
        f_r, model, b, (r0, c0) = z["f_r"], z["model"], int(z["binning"]), z["origin"]
    meas = np.mean(f_r, axis=-1)  # NaN where a bin was not fitted
    res = np.mean(f_r - model, axis=-1)  # NaN where any channel was not fitted
    rows, cols = meas.shape
    extent = (c0 - 0.5, c0 + b * cols - 0.5, r0 + b * rows - 0.5, r0 - 0.5)  # image pixels
    fig = Figure(figsize=(9.6, 3.4), dpi=100)
    ax = fig.add_subplot(1, 2, 1)
    finite = meas[np.isfinite(meas)]
    hi = float(np.percentile(finite, 99.5)) if finite.size else 1.0
    im = ax.imshow(np.ma.masked_invalid(meas), cmap="magma", vmin=0, vmax=hi, extent=extent, aspect="equal")
    fig.colorbar(im, ax=ax, label=r"$f_r$ (sr$^{-1}$, mean RGB)", fraction=0.046)
    ax.set_title("measured BRDF over the probe", fontsize=8.5)
    ax.set_xlabel("image column (px)")
    ax.set_ylabel("image row (px)")
    ax2 = fig.add_subplot(1, 2, 2)
    ok = np.isfinite(res)
    lim = float(np.percentile(np.abs(res[ok]), 99)) if ok.any() else 1.0
    lim = lim if lim > 0 else 1.0
    im2 = ax2.imshow(np.ma.masked_invalid(res), cmap="RdBu_r", vmin=-lim, vmax=lim, extent=extent, aspect="equal")
    fig.colorbar(im2, ax=ax2, label=r"measured − fit (sr$^{-1}$)", fraction=0.046)
    rms = float(np.sqrt(np.mean(res[ok] ** 2))) if ok.any() else float("nan")
    mean_f = float(np.mean(meas[ok])) if ok.any() else float("nan")
    ax2.set_title(f"residual of the joint fit (RMS {rms / mean_f:.1%} of the mean $f_r$)", fontsize=8.5)
    ax2.set_xlabel("image column (px)")
    ax2.set_yticks([])
    fig.suptitle(f"{result.name}: fit over the image ({b}×{b} px bins; white: not fitted)", fontsize=9)
    fig.tight_layout()
    return fig


# (chain, axis label with its unit, title above the column)
_CORNER = (
    ("alpha", r"$\alpha$ (dimensionless)", r"$\alpha$"),
    ("sigma_obs", r"$\sigma_\mathrm{obs}$ (SD of ln PPB)", r"$\sigma_\mathrm{obs}$"),
    ("ppb_median", "median PPB (px per bar)", "PPB"),
)


def corner_figure(result: CaptureResult) -> Figure | None:
    """The α posterior's corner plot (α, observer noise, median threshold), from ``posterior.npz``.

    Drawn by the ``corner`` package over the central 99.5 % of each parameter;
    the dashed lines are the 16/50/84 % quantiles, quoted above each column.
    """
    chains = load_chains(result)
    if chains is None:
        return None
    import corner

    keys = [k for k, _, _ in _CORNER if k in chains]
    labels = {k: (label, title) for k, label, title in _CORNER}
    draws = np.column_stack([chains[k].ravel() for k in keys]).astype(np.float64)
    fig = Figure(figsize=(6.4, 6.4), dpi=100)
    corner.corner(
        draws,
        fig=fig,
        labels=[labels[k][0] for k in keys],
        titles=[labels[k][1] for k in keys],
        range=[0.995] * len(keys),  # the central 99.5 % of each parameter: the long tails would squash the rest
        quantiles=[0.16, 0.5, 0.84],
        show_titles=True,
        title_fmt=".3g",  # three significant digits: α's unequal arms (skew) stay visible
        title_kwargs={"fontsize": 9},
        label_kwargs={"fontsize": 9},
        bins=30,
        smooth=1.0,
    )
    return fig


def trace_figure(result: CaptureResult, walkers: int = 8) -> Figure | None:
    """α along the chain for a few walkers: a chain diagnostic (mixing, no drift)."""
    chains = load_chains(result)
    if chains is None:
        return None
    a = chains["alpha"]
    thin = int(chains.get("thin", 1))
    fig = Figure(figsize=(6.4, 2.4), dpi=100)
    ax = fig.add_subplot(1, 1, 1)
    steps = np.arange(a.shape[0]) * thin
    for w in range(min(walkers, a.shape[1])):
        ax.plot(steps, a[:, w], lw=0.6, alpha=0.8)
    ax.set_xlabel("step (after burn-in)")
    ax.set_ylabel(r"$\alpha$ (dimensionless)")
    ax.set_title(f"{result.name}: α chains of {min(walkers, a.shape[1])} of {a.shape[1]} walkers", fontsize=9)
    fig.tight_layout()
    return fig


def batch_figure(results: list[CaptureResult], flags: dict[str, set[str]]) -> Figure:
    """Each parameter across the batch (left) and its relative 1σ (right, log scale); outliers in red.

    Between captures the values differ far more than their σ, so bars of ± 1σ
    on the values' axis are thinner than the markers; the right column shows
    each σ at its own scale, as a percentage of the value (smartphone α: half
    the 68 % interval's width).
    """
    n = len(PARAMETERS)
    fig = Figure(figsize=(8.4, 1.0 + 1.25 * n), dpi=100)
    x = np.arange(len(results))
    for k, key in enumerate(PARAMETERS):
        ax = fig.add_subplot(n, 2, 2 * k + 1)
        v, err = _value_and_bar(results, key)
        rel = np.array([_relative_sigma(r, key) for r in results])
        bad = np.array([key in flags[r.name] for r in results])
        ax.errorbar(x[~bad], v[~bad], yerr=err[:, ~bad], fmt="o", color="C0", ms=4, capsize=3)
        if bad.any():
            ax.errorbar(x[bad], v[bad], yerr=err[:, bad], fmt="o", color="C3", ms=5, capsize=3, label="outlier")
            ax.legend(fontsize=7, frameon=False, loc="upper right")
        ax.set_ylabel(_LABELS[key], fontsize=8)
        last = k == n - 1
        ax.set_xticks(x, [r.name for r in results] if last else [], fontsize=7, rotation=30)
        ax2 = fig.add_subplot(n, 2, 2 * k + 2)
        ax2.bar(x, rel, color=np.where(bad, "C3", "C0"))
        for xi, rv in zip(x, rel):
            ax2.annotate(f"{rv:.2g} %", (xi, rv), textcoords="offset points", xytext=(0, 2), ha="center", fontsize=7)
        ax2.set_yscale("log")
        ax2.set_ylim(np.nanmin(rel) / 3, np.nanmax(rel) * 5)
        ax2.yaxis.set_minor_formatter(NullFormatter())
        ax2.set_ylabel("1σ / value (%)", fontsize=8)
        ax2.set_xticks(x, [r.name for r in results] if last else [], fontsize=7, rotation=30)
    fig.suptitle(
        "parameters across the batch (dimensionless). Left: value ± 1σ (a posterior α: median and 68 % interval;\n"
        "bars hidden by the marker where σ is small). Right: 1σ relative to the value, log scale",
        fontsize=8.5,
    )
    fig.tight_layout()
    return fig


def _value_and_bar(results: list[CaptureResult], key: str) -> tuple[np.ndarray, np.ndarray]:
    """Values ``(N,)`` and error bars ``(2, N)`` (below, above): ± 1σ, or a posterior α's 68 % interval."""
    v, err = np.empty(len(results)), np.empty((2, len(results)))
    for i, r in enumerate(results):
        post = r.doc["fit"].get("posterior")
        if post is not None and key.startswith("alpha"):
            lo, hi = post["alpha_interval_68"]
            v[i], err[:, i] = post["alpha_median"], (post["alpha_median"] - lo, hi - post["alpha_median"])
        else:
            v[i], e = r.value(key)
            err[:, i] = e
    return v, err


def _relative_sigma(result: CaptureResult, key: str) -> float:
    """1σ as a percentage of the value; a posterior α: half its 68 % interval over the median."""
    post = result.doc["fit"].get("posterior")
    if post is not None and key.startswith("alpha"):
        lo, hi = post["alpha_interval_68"]
        return 100.0 * 0.5 * (hi - lo) / post["alpha_median"]
    v, e = result.value(key)
    return 100.0 * e / abs(v) if v else float("nan")
