"""The demo behind ``make demo``: Table 1 captures, simulated, fitted with ``wardjax fit``, compared.

1. Simulate the desk and marble of the image-based paper's Table 1 (both
   anisotropic as tabulated, grey ρd, with a wood-like and a marble-like
   texture) as capture folders in ``OUT/captures/`` — only if not present.
2. Fit them exactly as ``wardjax fit OUT/captures --out OUT/fits`` does
   (:func:`wardjax.run.run_batch`): params.json, ρd texture, scanline plot,
   Radiance material per capture, and ``summary.csv``.
3. Print true vs fitted ± 1σ.
4. Synthesise a 512×512 tile from the marble's ``texture.json`` (section 4.2 of
   the paper) and write it beside the fit as ``texture_synth.png``.
5. Fit the shipped smartphone example (``examples/smartphone/colorchecker-red``,
   a real ColorChecker photo with the chart's colour correction), copied to
   ``OUT/captures/`` beside the others, and print ρd against the chart's own
   colour, α's median and intervals, and the correction's ΔE*ab.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from rich.console import Console
from rich.table import Table

from .._data import example_path, table1_materials
from .._files import write_bytes_atomic, write_json_atomic
from ..capture import CAPTURE_FILE
from ..simulate import simulate_capture
from ..texture import TextureModel, synthesize_texture, write_texture_image
from ._batch import color_note, run_batch, scanline_note

__all__ = ["run_capture_demo", "write_json_atomic"]

TEXTURES = {"desk": "wood", "marble": "marble"}
PHONE_EXAMPLE = "colorchecker-red"  # examples/smartphone/<this>: the chart's red patch, "red" in chart order


def _pm(value, err, digits: int = 4) -> str:
    """``value ± err`` with the error to two significant digits (never a bare ``± 0.0000``)."""
    if value is None:
        return "–"
    if err is None or not np.isfinite(err) or err <= 0:
        return f"{value:.{digits}f}"
    places = max(digits, 1 - int(np.floor(np.log10(err))))
    return f"{value:.{places}f} ± {err:.{places}f}"


def _true_mean_rho_d(capture: Path, fit: Path) -> float | None:
    """The simulated texture averaged the way the fitted ρd is: over scanlines, each the mean of its pixels.

    The fitted ρd is the mean of the per-scanline ρd (image columns), each the
    mean over that column's fitted pixels, so the truth is averaged alike
    (columns with at least 8 fitted pixels). The plain pixel mean weights the
    long columns more and differs by ~3 σ on the marble's texture.
    """
    try:
        import tifffile

        truth = tifffile.imread(capture / "truth_rho_d.tif")
        fitted = tifffile.imread(fit / "rho_d.tif")
    except (OSError, ValueError):
        return None
    if truth.shape != fitted.shape:
        return None
    valid = np.all(np.isfinite(fitted), axis=-1)
    n = valid.sum(axis=0)
    cols = n >= 8
    if not cols.any():
        return None
    col_mean = np.where(valid[..., None], truth, 0.0).sum(axis=0)[cols] / n[cols][:, None]  # (S, 3)
    return float(np.mean(col_mean))


def run_capture_demo(out_dir, *, seed: int = 0, image_size=(480, 360), console: Console | None = None) -> dict:
    """Simulate (if absent), fit and compare the Table 1 captures; return ``{name: params.json document}``."""

    console = console or Console()
    out_dir = Path(out_dir)
    cap_root = out_dir / "captures"
    truth = table1_materials()
    for i, (name, p) in enumerate(truth.items()):
        folder = cap_root / name
        if not (folder / CAPTURE_FILE).is_file():
            console.print(f"simulating capture [bold]{name}[/] → {folder}/")
            simulate_capture(
                p,
                folder,
                seed=seed + i,
                image_size=image_size,
                texture=TEXTURES.get(name, "wood"),
                model="anisotropic",
                name=name,
            )
    phone = _copy_phone_example(cap_root / PHONE_EXAMPLE)
    console.print(f"fitting: wardjax fit {cap_root} --out {out_dir / 'fits'}")
    items = run_batch([*(cap_root / n for n in truth), phone], out_dir / "fits")
    table = Table(title="Table 1 materials: true vs fitted ± 1σ (joint anisotropic fit, Ward 1992 normalisation)")
    for col in ("material", "", "ρd", "ρs", "αx", "αy"):
        table.add_column(col)
    table.add_column("fit", no_wrap=True, min_width=len("converged"))  # the status whole, even at 80 columns
    results = {}
    for it in items:
        if it.name not in truth:
            continue
        t = truth[it.name]
        rd_true = _true_mean_rho_d(cap_root / it.name, out_dir / "fits" / it.name)
        rd_true = float(np.mean(t.rho_d)) if rd_true is None else rd_true
        table.add_row(
            it.name,
            "true",
            f"{rd_true:.4f}",
            f"{float(t.rho_s):.4f}",
            f"{float(t.alpha_x):.4f}",
            f"{float(t.alpha_y):.4f}",
            "",
        )
        doc = it.params  # the params.json document; an "ok" item always carries one
        if it.status != "ok" or doc is None:
            table.add_row("", "[red]error[/]", it.error, "", "", "", "", end_section=True)
            continue
        p, e = doc["params"], doc["stderr"]
        table.add_row(
            "",
            "fitted",
            _pm(float(np.mean(p["rho_d"])), float(np.mean(e["rho_d"]))),
            _pm(p["rho_s"], e["rho_s"]),
            _pm(p["alpha_x"], e["alpha_x"]),
            _pm(p["alpha_y"], e["alpha_y"]),
            doc["fit"]["status"],
            end_section=True,
        )
        results[it.name] = doc
    console.print(table)
    _print_phone([it for it in items if it.name not in truth], console)
    for name, doc in results.items():
        if note := scanline_note(doc):
            console.print(f"note: {name}: {note}", highlight=False, soft_wrap=True)
    console.print(
        f"Results in [bold]{out_dir / 'fits'}/[/] (per capture: params.json, rho_d.tif/.png, "
        "scanline.png, material.rad; summary.csv)."
    )
    write_json_atomic(
        out_dir / "demo.json", {k: {"params": v["params"], "stderr": v["stderr"]} for k, v in results.items()}
    )
    if "marble" in results:
        _demo_texture(out_dir / "fits" / "marble", console)
    return results


def _demo_texture(fit_dir: Path, console: Console, size: int = 512) -> Path:
    """Synthesise a ``size``² tile from the capture's ``texture.json``; write ``texture_synth.png`` (sRGB view)."""

    model = TextureModel.load(fit_dir / "texture.json")
    res = synthesize_texture(model, (size, size), seed=0)
    out = write_texture_image(fit_dir / "texture_synth.png", res.image)
    console.print(
        f"texture: wardjax texture synthesize {fit_dir / 'texture.json'} --size {size}x{size} -o {out} "
        f"(subband KS {res.initial_distance:.3f} → {res.distance[-1]:.3f} over {res.distance.size} "
        "iterations; it tiles seamlessly)",
        highlight=False,
        soft_wrap=True,
    )
    return out


def _copy_phone_example(dst: Path) -> Path:
    """Copy the shipped smartphone example capture to ``dst`` (file by file, atomically) unless present."""
    src = example_path(f"smartphone/{PHONE_EXAMPLE}")
    if not (dst / CAPTURE_FILE).is_file():
        for f in sorted(src.iterdir()):
            write_bytes_atomic(dst / f.name, f.read_bytes())
    return dst


def _print_phone(items, console: Console) -> None:
    """The smartphone example: ρd ± σ against the chart's published colour, α's median and intervals, ΔE."""
    from ..smartphone import Lab_to_diffuse, colorchecker_reference_Lab

    chart = np.asarray(Lab_to_diffuse(colorchecker_reference_Lab()[14], "D50"))  # patch 15, "red"
    for it in items:
        if it.status != "ok" or it.params is None:
            console.print(f"smartphone example {it.name}: [red]error[/] {it.error}", highlight=False)
            continue
        p, e, post = it.params["params"], it.params["stderr"], it.params["fit"]["posterior"]
        rgb = ", ".join(_pm(v, s) for v, s in zip(p["rho_d"], e["rho_d"]))
        console.print(
            f"smartphone example {it.name}: ρd (RGB, linear, white E) = ({rgb}); "
            f"the chart's red: ({', '.join(f'{v:.4f}' for v in chart)}). α median {post['alpha_median']:.4f}, "
            f"68 % [{post['alpha_interval_68'][0]:.4f}, {post['alpha_interval_68'][1]:.4f}], "
            f"95 % [{post['alpha_interval_95'][0]:.4f}, {post['alpha_interval_95'][1]:.4f}] "
            "(observers drawn at α = 0.071).",
            highlight=False,
            soft_wrap=True,
        )
        if note := color_note(it.params):
            console.print(f"colour: {it.name}: {note}", highlight=False, soft_wrap=True)
