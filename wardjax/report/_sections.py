"""The report's sections, displayed from its notebook: the batch table and one section per capture."""

from __future__ import annotations

import html
import io

import numpy as np
from matplotlib.figure import Figure

from ..export._params import FIT_QUALITY_COLUMNS
from ..export._params import fit_quality as export_fit_quality
from ._collect import PARAMETERS, CaptureResult, flag_outliers, load_chains, split_rhat
from ._figures import (
    batch_figure,
    corner_figure,
    errors_figure,
    gap_figure,
    residual_figure,
    texture_figure,
    trace_figure,
)

__all__ = ["batch_section", "capture_section", "fit_quality"]


def _display(*objs) -> None:
    from IPython.display import display

    display(*objs)


def _png(fig: Figure):
    from IPython.display import Image

    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=fig.dpi)
    return Image(data=buf.getvalue(), format="png")


def _html(text: str):
    from IPython.display import HTML

    return HTML(text)


def _pm(value: float, err: float) -> str:
    """``value ± err``, the error in scientific notation when it would round to zero."""
    e = f"{err:.2g}" if err >= 1e-4 or err == 0 else f"{err:.1e}"
    return f"{value:.4f} ± {e}"


def _alpha_cell(r: CaptureResult, key: str) -> str:
    """αx/αy in the batch table: ``median [68 %]`` from a posterior, else ``value ± σ``."""
    post = r.doc["fit"].get("posterior")
    if post is None:
        return _pm(*r.value(key))
    lo, hi = post["alpha_interval_68"]
    return f"{post['alpha_median']:.4f} [{lo:.4f}, {hi:.4f}]"


def fit_quality(doc: dict, *, short: bool = False) -> tuple[str, str]:
    """``(value, what it is)`` of a capture's fit quality, named by what was computed.

    The numbers are `wardjax.export.fit_quality`'s (the same as ``summary.csv``'s
    columns): a weighted fit (``fit.weighted``, 1/σ² from a noise model) gives
    χ²/dof; a unit-weight least-squares fit gives its RMS residual in sr⁻¹ and as
    a share of the mean f_r (its ``reduced_chi2`` is a residual variance in sr⁻²,
    not a χ²); the smartphone method has no least-squares fit. ``short``: the
    value as the batch table gives it (the note under the table says what it is).
    """
    q = export_fit_quality(doc["fit"])
    chi, rms, rel = (q[k] for k in FIT_QUALITY_COLUMNS)
    if chi is not None:
        return f"χ²/dof {chi:.3g}", "weighted χ²/dof (weights 1/σ² from the noise model; ≈ 1 when the model fits)"
    if rms is not None:
        share = "" if rel is None else f" ({rel:.1%})" if short else f" ({rel:.1%} of mean f_r)"
        return (
            f"{'' if short else 'RMS '}{rms:.2g} sr⁻¹{share}",
            "RMS residual, unit weights (no noise σ given, so no χ²)",
        )
    return "–", "no least-squares fit (α from a posterior)"


_NOTE_PARTS = {
    "scanline": "Scanline captures: value ± 1σ (the error model each capture section names); fit quality: RMS of "
    "measured − fitted BRDF in sr⁻¹ and as a share of the mean measured f_r — the fit has unit weights (no noise σ "
    "is measured), so no χ² is quoted.",
    "smartphone": "Smartphone captures: α as posterior median [68 % interval] (the posterior is skewed); no "
    "least-squares fit, so no fit quality.",
    "photo": "Flash and multi-view captures: value ± 1σ; fit quality: χ²/dof with weights 1/σ² from the "
    "photographs' noise model (≈ 1 when the model fits to the noise).",
}


def _units_note(results: list[CaptureResult]) -> str:
    """What the table's numbers are, said only for the methods the batch holds."""
    kinds = {("photo" if r.doc["method"] in ("flash", "multiview") else r.doc["method"]) for r in results}
    parts = " ".join(v for k, v in _NOTE_PARTS.items() if k in kinds)
    return (
        "<p class='units'>ρd: diffuse reflectance, mean over R, G, B (linear sRGB primaries, white E); ρs: specular "
        "reflectance; αx, αy: Ward lobe widths (RMS surface slope, ≈ lobe width in radians). All four are "
        f"dimensionless. {parts} Red bold: more than 3.5 robust σ from the batch median (with ≥ 4 captures).</p>"
    )


def batch_section(results: list[CaptureResult]) -> None:
    """The table across captures (outliers flagged: > 3.5 robust σ from the batch median) and its plot."""
    flags = flag_outliers(results)
    names = ("capture", "method", "model", "status", "ρd (mean RGB)", "ρs", "αx", "αy", "fit quality")
    head = "".join(f"<th>{html.escape(k)}</th>" for k in names)
    rows = []
    for r in results:
        cells = [r.name, r.doc["method"], r.doc["model"], r.doc["fit"].get("status", "")]
        vals = []
        for key in PARAMETERS:
            text = _alpha_cell(r, key) if key.startswith("alpha") else _pm(*r.value(key))
            style = ' style="color:#c00;font-weight:bold" title="outlier"' if key in flags[r.name] else ""
            vals.append(f"<td{style}>{html.escape(text)}</td>")
        q, what = fit_quality(r.doc, short=True)
        rows.append(
            "<tr>"
            + "".join(f"<td>{html.escape(str(c))}</td>" for c in cells)
            + "".join(vals)
            + f"<td title='{html.escape(what)}'>{html.escape(q)}</td></tr>"
        )
    n_out = sum(bool(f) for f in flags.values())
    _display(
        _html(
            f"<h2>Batch: {len(results)} capture{'s' if len(results) != 1 else ''}, {n_out} with an outlying "
            "parameter</h2>"
            "<style>table.batch td { white-space: nowrap; }</style>"
            f"<table class='batch'><tr>{head}</tr>{''.join(rows)}</table>" + _units_note(results)
        )
    )
    _display(_png(batch_figure(results, flags)))


_SHARED = {"rho_s": "ρs", "alpha": "α", "alpha_x": "αx", "alpha_y": "αy"}
_MODEL_COLUMNS = (
    ("texture_field", "texture field"),
    ("scanline_sandwich", "scanline sandwich"),
    ("model", "Gauss–Newton model"),
)
_ERROR_MODELS = (
    "<p class='error-models'><b>Which σ to believe.</b> <i>Texture field</i> (reported): the Gauss–Newton "
    "covariance plus the aliasing of the ρd texture into ρs and α — a texture that varies along a scanline "
    "mimics part of a lobe, and no residual-based error sees that; right for a real, textured surface, where it "
    "is the honest one. <i>Scanline sandwich</i>: clustered by scanline, robust to noise correlated within a "
    "scanline and to a misfit that differs between scanlines; right for a uniform surface whose noise is not "
    "white or whose model is slightly off (needs ≥ 10 scanlines). <i>Gauss–Newton model</i>: the Jacobian "
    "scaled by the residual variance; right only when the residuals are independent noise of one variance (a "
    "uniform surface the model fits) — on a textured surface it is too small. Where they disagree by more than "
    "2×, the data hold structure the smallest one ignores.</p>"
)


def _errors_table(result: CaptureResult) -> str:
    """The shared parameters ± 1σ by each error model (a scanline capture's ``fit.diagnostics.errors``)."""
    fit = result.doc["fit"]
    errors = fit.get("diagnostics", {}).get("errors")
    names = fit.get("covariance", {}).get("parameters")
    if not errors or not names:
        return ""
    p = result.doc["params"]
    reported = errors.get("reported", "texture_field")
    head = "".join(
        f"<th>{html.escape(label + (' (reported)' if key == reported else ''))}</th>" for key, label in _MODEL_COLUMNS
    )
    rows = []
    for i, n in enumerate(names):
        v = float(p["alpha_x"] if n == "alpha" else p[n])
        cells = "".join(f"<td>{_pm(v, float(errors[key][i]))}</td>" for key, _ in _MODEL_COLUMNS)
        rows.append(f"<tr><td>{html.escape(_SHARED.get(n, n))}</td>{cells}</tr>")
    sig = np.array([[float(errors[key][i]) for key, _ in _MODEL_COLUMNS] for i in range(len(names))])
    spread = float(np.max(sig.max(axis=1) / sig.min(axis=1)))
    return (
        "<h3>Parameters ± 1σ by error model (dimensionless)</h3>"
        f"<table class='errors'><tr><th>parameter</th>{head}</tr>{''.join(rows)}</table>"
        f"<p>The three error models differ by up to {spread:.1f}× on this capture.</p>" + _ERROR_MODELS
    )


def _correlation_table(result: CaptureResult) -> str:
    """Correlations of the shared parameters, from ``fit.covariance`` (the reported error model's)."""
    cov = result.doc["fit"].get("covariance")
    if not cov or not cov.get("matrix"):
        if "posterior" in result.doc["fit"]:
            return (
                "<h3>Correlations</h3><p>ρs–α: none — ρs is not fitted here but taken from Fresnel at the assumed "
                "refractive index, independent of the thresholds that give α. α's correlation with the observer "
                "noise and the median threshold is in the corner plot below.</p>"
            )
        return ""
    c = np.asarray(cov["matrix"], float)
    names = [str(_SHARED.get(n, n)) for n in cov["parameters"]]
    d = np.sqrt(np.clip(np.diag(c), 0, None))
    corr = c / np.where(np.outer(d, d) > 0, np.outer(d, d), np.nan)
    head = "".join(f"<th>{html.escape(n)}</th>" for n in names)
    body = "".join(
        f"<tr><td>{html.escape(n)}</td>" + "".join(f"<td>{corr[i, j]:+.2f}</td>" for j in range(len(names))) + "</tr>"
        for i, n in enumerate(names)
    )
    pairs = ", ".join(
        f"{names[i]}–{names[j]} {corr[i, j]:+.2f}" for i in range(len(names)) for j in range(i + 1, len(names))
    )
    return (
        "<h3>Correlations of the shared parameters</h3>"
        f"<table class='correlation'><tr><th></th>{head}</tr>{body}</table>"
        f"<p>Correlation coefficients (−1 to 1) of the reported covariance: {html.escape(pairs)}. "
        "A σ alone understates how far two correlated parameters can move together.</p>"
    )


def _alpha_intervals(result: CaptureResult) -> str:
    """α as median with 68/95 % intervals: the posterior's, or the log-normal of a fit made in log α."""
    doc = result.doc
    post = doc["fit"].get("posterior")
    if post is not None:
        lo68, hi68 = post["alpha_interval_68"]
        lo95, hi95 = post["alpha_interval_95"]
        m = post["alpha_median"]
        skew = (hi95 - m) / (m - lo95) if m > lo95 else float("nan")
        return (
            f"<li>α (αx = αy, dimensionless) = {m:.4f} (posterior median); 68 % [{lo68:.4f}, {hi68:.4f}], "
            f"95 % [{lo95:.4f}, {hi95:.4f}]; mean {post['alpha_mean']:.4f}. Skewed: the upper 95 % arm is "
            f"{skew:.2f}× the lower, so no symmetric ± is quoted.</li>"
        )
    out = []
    iso = doc["model"] == "isotropic"
    for key in ("alpha_x",) if iso else ("alpha_x", "alpha_y"):
        v, e = result.value(key)
        if not (v > 0 and e >= 0):
            continue
        f68, f95 = np.exp(e / v), np.exp(1.96 * e / v)  # the fit is in log α: σ(ln α) = σ/α
        name, unit = ("α", "dimensionless; αx = αy") if iso else (_SHARED[key], "dimensionless")
        out.append(
            f"<li>{name} = {v:.4f} ({unit}); 68 % [{v / f68:.4f}, {v * f68:.4f}], 95 % "
            f"[{v / f95:.4f}, {v * f95:.4f}] (log-normal: the fit is made in ln α; σ/α = {e / v:.1%})</li>"
        )
    return "".join(out)


def _color_block(result: CaptureResult) -> str:
    """A smartphone capture's ρd: where its σ comes from, with the chart correction's ΔE*ab."""
    doc = result.doc
    if doc["method"] != "smartphone":
        return ""
    cc = doc["fit"].get("color_correction")
    if cc is None:
        return (
            "<p>ρd's σ is the region's standard error only: no colour chart was given "
            "(<code>[color_correction]</code> in capture.toml), so the camera's colour error — ΔE*ab 5–20 for "
            "phones — is unknown and not in it.</p>"
        )
    loo, raw = cc["delta_E_held_out"], cc["delta_E_uncorrected"]
    reg = ", ".join(f"{v:.1e}" for v in cc["rho_d_sigma_region"])
    col = ", ".join(f"{v:.2g}" for v in cc["rho_d_sigma_color"])
    return (
        f"<p>ρd is corrected by the ColorChecker in the photo ({html.escape(cc['method'])}, "
        f"{cc['patches_used']} patches, tone exponent {cc['tone_exponent']:.2f}). ΔE*ab (CIE 1976, D50): "
        f"uncorrected mean {raw['mean']:.1f}; corrected, each patch held out of its own fit, mean {loo['mean']:.1f}, "
        f"RMS {loo['rms']:.1f}, max {loo['max']:.1f}. ρd's σ (R, G, B) = colour error ({col}) ⊕ region standard "
        f"error ({reg}): the held-out residuals moved onto this colour.</p>"
    )


def _chain_table(result: CaptureResult) -> str:
    """The α posterior's intervals and chain diagnostics (acceptance, τ, N/τ, effective samples, split-R̂)."""
    post = result.doc["fit"].get("posterior")
    if not post:
        return ""
    chains = load_chains(result)
    rhat = split_rhat(chains["alpha"]) if chains is not None else float("nan")
    lo68, hi68 = post["alpha_interval_68"]
    lo95, hi95 = post["alpha_interval_95"]
    tau = post["autocorrelation_time"]
    rows = [
        ("α median", f"{post['alpha_median']:.4f}"),
        ("68 % interval", f"[{lo68:.4f}, {hi68:.4f}]"),
        ("95 % interval", f"[{lo95:.4f}, {hi95:.4f}]"),
        ("acceptance fraction", f"{post['acceptance']:.2f}"),
        ("autocorrelation time τ (steps, slowest parameter)", f"{tau:.1f}"),
    ]
    if "n_steps" in post:
        rows += [
            ("chain length", f"{post['n_steps']} steps × {post['n_walkers']} walkers = {post['n_steps'] / tau:.0f} τ"),
            ("effective samples (N·W/τ)", f"{post['effective_samples']:.0f}"),
        ]
    rows.append(("split-R̂ of α across walkers", f"{rhat:.3f}"))
    left = ' style="text-align:left"'
    body = "".join(f"<tr><td{left}>{html.escape(k)}</td><td{left}>{html.escape(v)}</td></tr>" for k, v in rows)
    return f"<h3>α posterior: intervals and chain diagnostics</h3><table class='chain'>{body}</table>"


def _scanline_image(result: CaptureResult):
    plot = result.folder / "scanline.png"
    if not plot.is_file():
        return None
    from IPython.display import Image

    return Image(filename=str(plot))


def _rho_s_source(doc: dict) -> str:
    """Where a ρs that was not fitted comes from (the smartphone method's Fresnel assumption)."""
    src = doc["fit"].get("rho_s_source")
    return f" — assumed, not measured: {html.escape(src)}; σ a quarter of that range" if src else ""


def _quality_item(doc: dict) -> str:
    q, what = fit_quality(doc)
    return f"<li>fit quality, {html.escape(what)}" + (f": {html.escape(q)}" if q != "–" else "") + "</li>"


def capture_section(result: CaptureResult) -> None:
    """One capture: parameters with units and intervals, error models, correlations, then the figures.

    Every figure comes under its own ``<h3>`` heading; a figure whose input the
    capture's folder lacks (no posterior for a scanline capture, no
    ``report.json`` without ``wardjax diagnose``) is left out with its heading.
    """
    doc = result.doc
    p, e = doc["params"], doc["stderr"]
    rgb = ", ".join(f"{v:.4f} ± {s:.2g}" for v, s in zip(p["rho_d"], e["rho_d"]))
    items = (
        f"<li>ρd (R, G, B; linear, sRGB primaries, white E; dimensionless) = {rgb}</li>"
        f"<li>ρs (dimensionless) = {_pm(*result.value('rho_s'))}{_rho_s_source(doc)}</li>"
        + _alpha_intervals(result)
        + _quality_item(doc)
    )
    _display(
        _html(
            f"<h2 id='capture-{html.escape(result.name)}'>Capture {html.escape(result.name)}</h2>"
            f"<p>{html.escape(doc['method'])}, {html.escape(doc['model'])}, normalisation "
            f"{html.escape(doc['normalization'])}; fit status {html.escape(str(doc['fit'].get('status')))}</p>"
            f"<ul>{items}</ul>"
            + _color_block(result)
            + _errors_table(result)
            + _correlation_table(result)
            + _chain_table(result)
        )
    )
    post = "posterior" in doc["fit"]
    figures = (
        ("α posterior: 68 and 95 % intervals" if post else "1σ by error model", lambda: errors_figure(result)),
        ("α posterior: corner plot", lambda: corner_figure(result)),
        ("α posterior: chains", lambda: trace_figure(result)),
        ("Fitted vs measured scanline", lambda: _scanline_image(result)),
        ("Residuals over the image", lambda: residual_figure(result)),
        ("ρd texture and a synthesised tile", lambda: texture_figure(result)),
        ("Missing-effect gap", lambda: gap_figure(result)),
    )
    for heading, make in figures:
        fig = make()
        if fig is not None:
            _display(_html(f"<h3>{html.escape(heading)}</h3>"), fig if not isinstance(fig, Figure) else _png(fig))
