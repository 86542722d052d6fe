"""The report's sections, displayed from its notebook: the batch table and one section per capture."""

from __future__ import annotations

import html
import io

from matplotlib.figure import Figure

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

__all__ = ["batch_section", "capture_section"]


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


def batch_section(results: list[CaptureResult]) -> None:
    """The table across captures (outliers flagged: > 3.5 robust σ from the batch median) and its plot."""
    flags = flag_outliers(results)
    head = "".join(
        f"<th>{html.escape(k)}</th>" for k in ("capture", "method", "model", "status", *PARAMETERS, "χ²/dof")
    )
    rows = []
    for r in results:
        cells = [r.name, r.doc["method"], r.doc["model"], r.doc["fit"].get("status", "")]
        vals = []
        for key in PARAMETERS:
            v, e = r.value(key)
            style = ' style="color:#c00;font-weight:bold" title="outlier"' if key in flags[r.name] else ""
            vals.append(f"<td{style}>{_pm(v, e)}</td>")
        chi = r.doc["fit"].get("reduced_chi2")
        rows.append(
            "<tr>"
            + "".join(f"<td>{html.escape(str(c))}</td>" for c in cells)
            + "".join(vals)
            + f"<td>{'' if chi is None else f'{chi:.3g}'}</td></tr>"
        )
    n_out = sum(bool(f) for f in flags.values())
    _display(
        _html(
            f"<h2>Batch: {len(results)} captures, {n_out} with an outlying parameter</h2>"
            f"<table class='batch'><tr>{head}</tr>{''.join(rows)}</table>"
        )
    )
    _display(_png(batch_figure(results, flags)))


_SHARED = {"rho_s": "ρs", "alpha": "α", "alpha_x": "αx", "alpha_y": "αy"}
_MODEL_COLUMNS = (
    ("texture_field", "texture field (reported)"),
    ("scanline_sandwich", "scanline sandwich"),
    ("model", "Gauss–Newton model"),
)


def _errors_table(result: CaptureResult) -> str:
    """The shared parameters ± 1σ by each error model (a scanline capture's ``fit.diagnostics.errors``)."""
    fit = result.doc["fit"]
    errors = fit.get("diagnostics", {}).get("errors")
    names = fit.get("covariance", {}).get("parameters")
    if not errors or not names:
        return ""
    p = result.doc["params"]
    head = "".join(f"<th>{html.escape(label)}</th>" for _, label in _MODEL_COLUMNS)
    rows = []
    for i, n in enumerate(names):
        v = float(p["alpha_x"] if n == "alpha" else p[n])
        cells = "".join(f"<td>{_pm(v, float(errors[key][i]))}</td>" for key, _ in _MODEL_COLUMNS)
        rows.append(f"<tr><td>{html.escape(_SHARED.get(n, n))}</td>{cells}</tr>")
    return (
        "<h3>Parameters ± 1σ by error model</h3>"
        f"<table class='errors'><tr><th>parameter</th>{head}</tr>{''.join(rows)}</table>"
        "<p>The texture field is what the fit reports: it adds the ρd texture's aliasing into ρs and α, "
        "which no residual-based error sees.</p>"
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


def capture_section(result: CaptureResult) -> None:
    """One capture: parameters ± σ (by error model), the α posterior, scanline, residuals, texture, gap chart.

    Every figure comes under its own ``<h3>`` heading; a figure whose input the
    capture's folder lacks (no posterior for a scanline capture, no
    ``report.json`` without ``wardjax diagnose``) is left out with its heading.
    """
    doc = result.doc
    p, e = doc["params"], doc["stderr"]
    items = "".join(f"<li>{html.escape(k)} = {_pm(*result.value(k))}</li>" for k in PARAMETERS)
    rgb = ", ".join(f"{v:.4f}" for v in p["rho_d"])
    rgb_e = ", ".join(f"{v:.2g}" for v in e["rho_d"])
    _display(
        _html(
            f"<h2 id='capture-{html.escape(result.name)}'>Capture {html.escape(result.name)}</h2>"
            f"<p>{html.escape(doc['method'])}, {html.escape(doc['model'])}, normalisation "
            f"{html.escape(doc['normalization'])}; fit status {html.escape(str(doc['fit'].get('status')))}</p>"
            f"<ul>{items}<li>ρd RGB = ({rgb}) ± ({rgb_e})</li></ul>" + _errors_table(result) + _chain_table(result)
        )
    )
    post = "posterior" in doc["fit"]
    figures = (
        ("α posterior: 68 and 95 % intervals" if post else "Errors by error model", lambda: errors_figure(result)),
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
