"""The report's sections, displayed from its notebook: the batch table and one section per capture."""

from __future__ import annotations

import html
import io

from matplotlib.figure import Figure

from ._collect import PARAMETERS, CaptureResult, flag_outliers
from ._figures import batch_figure, errors_figure, gap_figure, texture_figure

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


def capture_section(result: CaptureResult) -> None:
    """One capture: parameters ± σ, errors by model or the α posterior, scanline plot, texture, gap chart."""
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
            f"<ul>{items}<li>ρd RGB = ({rgb}) ± ({rgb_e})</li></ul>"
        )
    )
    for fig in (errors_figure(result), texture_figure(result), gap_figure(result)):
        if fig is not None:
            _display(_png(fig))
    plot = result.folder / "scanline.png"
    if plot.is_file():
        from IPython.display import Image

        _display(_html("<h3>Fitted vs measured scanline</h3>"), Image(filename=str(plot)))
