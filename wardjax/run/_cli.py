"""The ``wardjax`` command line (click + rich).

Each subcommand is a thin shell over a library function: it parses, calls,
prints, and turns a bad input into one clear line on stderr (exit code 2)
rather than a traceback.
"""

from __future__ import annotations

import sys
from pathlib import Path

import click
from rich.console import Console

from ._cli_checks import (
    _check_name_length,
    _check_out_dir,
    _check_out_file,
    _fail,
    _parse_region,
    _parse_size,
    check_out_outside,
    out_dir_option,
)
from ._cli_import import import_cmd

__all__ = ["main"]

# emoji=False: a path or a value such as ``a:b:`` is printed as typed, not with ``:b:`` turned into an emoji.
console = Console(emoji=False)

# Where the traceback of a failure the code did not foresee is kept (the user sees one line naming it).
ERROR_LOG_NAME = "error.log"


# Click ≥ 8.2 raises this (a UsageError whose message is the whole help) for a group called without a command.
_NO_ARGS_IS_HELP = getattr(click.exceptions, "NoArgsIsHelpError", ())


class _Group(click.Group):
    """The ``wardjax`` group: every refusal one line on stderr, never a usage block or a traceback.

    Click's usage errors (a bad option value, an unknown command) become one
    ``error: …`` line with the command's help hint on it; a failure the code
    did not foresee is written with its traceback to :func:`_error_log_path`
    and reported as one line naming that file.
    """

    def main(self, args=None, prog_name=None, complete_var=None, standalone_mode=True, **extra):  # type: ignore[override]
        if not standalone_mode:
            return super().main(args, prog_name, complete_var, standalone_mode=False, **extra)
        try:
            rv = super().main(args, prog_name, complete_var, standalone_mode=False, **extra)
        except _NO_ARGS_IS_HELP as e:  # `wardjax`, `wardjax texture`: asked for nothing, shown the help (not an error)
            click.echo(e.ctx.get_help() if e.ctx is not None else e.format_message())
            sys.exit(0)
        except click.ClickException as e:
            hint = ""
            if isinstance(e, click.UsageError) and e.ctx is not None:
                hint = f" (see '{e.ctx.command_path} -h')"
            _fail(e.format_message() + hint, code=e.exit_code)
        except click.Abort:
            _fail("aborted", code=1)
        except Exception as e:  # the unforeseen: one line for the user, the traceback in a file
            _fail_unexpected(e)
        sys.exit(rv if isinstance(rv, int) else 0)


def _error_log_path() -> Path:
    import platformdirs

    return Path(platformdirs.user_log_dir("wardjax")) / ERROR_LOG_NAME


def _fail_unexpected(exc: BaseException) -> None:
    """Log ``exc`` with its traceback to :func:`_error_log_path` and exit with one line pointing at it."""
    import tempfile
    import traceback

    text = "".join(traceback.format_exception(exc)).encode()
    where = None
    for path in (_error_log_path(), Path(tempfile.gettempdir()) / f"wardjax-{ERROR_LOG_NAME}"):
        try:
            from .._files import write_bytes_atomic

            write_bytes_atomic(path, text)
            where = path
            break
        except OSError:
            continue
    first = (str(exc).strip().splitlines() or [""])[0]
    kept = f"; traceback in {where}" if where else ""
    _fail(f"unexpected failure ({type(exc).__name__}{': ' + first if first else ''}){kept}", code=1)


@click.group(cls=_Group, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(package_name="wardjax")
@click.option(
    "--cache-dir",
    type=click.Path(file_okay=False, path_type=Path),
    envvar="WARDJAX_CACHE_DIR",
    default=None,
    show_envvar=True,
    help="Where compiled kernels are kept between runs [default: the user cache folder].",
)
@click.option(
    "--no-cache",
    is_flag=True,
    envvar="WARDJAX_NO_CACHE",
    show_envvar=True,
    help="Compile afresh and keep nothing between runs.",
)
@click.pass_context
def main(ctx: click.Context, cache_dir: Path | None, no_cache: bool) -> None:
    """Measure Ward BRDF parameters from photographs, with honest uncertainties."""
    ctx.obj = {"cache_dir": None if no_cache else str(cache_dir or "")}  # for cluster workers: see fit --scheduler
    if not no_cache:
        from ._cache import enable_compile_cache

        enable_compile_cache(cache_dir)


def _pm(value: float | None, err: float | None) -> str:
    """``value ± err``; an error that rounds to zero at 4 decimals is printed in scientific notation."""
    if value is None or err is None:
        return "–"
    e = f"{err:.4f}" if abs(err) >= 5e-5 else f"{err:.1e}"
    return f"{value:.4f} ± {e}"


def _progress_option(f):
    """``--progress/--no-progress``: one line per stage on stderr [default: when stderr is a terminal]."""
    return click.option(
        "--progress/--no-progress",
        default=None,
        help="Show each stage and its time on stderr [default: when stderr is a terminal].",
    )(f)


# --------------------------------------------------------------------------- demo


@main.command()
@click.option(
    "--out",
    "out_dir",
    type=click.Path(file_okay=False, path_type=Path),
    default=Path("demo-output"),
    show_default=True,
    help="Folder for the simulated captures and the results.",
)
@click.option("--seed", type=click.IntRange(min=0), default=0, show_default=True)
def demo(out_dir: Path, seed: int) -> None:
    """Simulate the desk and marble captures of the paper's Table 1, fit them with the smartphone example, compare."""
    from ._demo import run_capture_demo

    run_capture_demo(out_dir, seed=seed, console=console)


# --------------------------------------------------------------------------- gratings (smartphone method)


@main.command()
@click.option(
    "--display",
    "display_name",
    default="iphone5s",
    show_default=True,
    help="Display in calibration/smartphone_setup.toml.",
)
@click.option(
    "--viewing",
    "viewing_name",
    default="paper",
    show_default=True,
    help="Viewing geometry in calibration/smartphone_setup.toml (for the CPD column).",
)
@click.option(
    "--out",
    "out_dir",
    type=click.Path(file_okay=False, path_type=Path),
    required=True,
    help="Folder for the PNG set and gratings.csv.",
)
@click.option("--orientation", type=click.Choice(["vertical", "horizontal"]), default="vertical", show_default=True)
def gratings(display_name: str, viewing_name: str, out_dir: Path, orientation: str) -> None:
    """Write the square-wave grating PNGs (1 PNG per whole PPB) to load onto the phone."""
    _check_out_dir(out_dir)
    from ..smartphone import write_gratings

    try:
        paths = write_gratings(out_dir, display_name, viewing_name, orientation=orientation)
    except (ValueError, OSError) as exc:
        _fail(str(exc))
    console.print(f"wrote {len(paths)} gratings and gratings.csv to {out_dir}")


# --------------------------------------------------------------------------- end gratings


# --------------------------------------------------------------------------- fitting and simulating captures


@main.command("fit")
@click.argument("paths", nargs=-1, required=True, type=click.Path(path_type=Path))
@click.option(
    "--out",
    "out_dir",
    type=click.Path(file_okay=False, path_type=Path),
    required=True,
    help="Folder for the results: one subfolder per capture and summary.csv.",
)
@click.option("--force", is_flag=True, help="Refit captures whose results are already complete.")
@click.option(
    "--max-steps",
    type=click.IntRange(1, 1000),
    default=None,
    help="Levenberg–Marquardt steps of each scanline's own fit [default: 4]; a scanline stopped at the limit "
    "keeps its best point (status max_steps), the joint material has its own convergence test.",
)
@click.option("--quiet", is_flag=True, help="No progress bar or table.")
@click.option(
    "--scheduler",
    default=None,
    metavar="ADDRESS|local[:N]",
    help="Fit each capture as a task on a dask.distributed cluster: a scheduler's address, or local:N to start "
    "N worker processes here [default: one capture after another in this process].",
)
@click.option("--hold-out", type=click.IntRange(min=0), metavar="K", help="Photograph captures: fit all photos but "
              "photo K (0-based), predict it: heldout.png (photo | prediction | residual), RMSE, PSNR.")  # fmt: skip
@_progress_option
@click.pass_context
def fit_cmd(
    ctx: click.Context,
    paths: tuple[Path, ...],
    out_dir: Path,
    force: bool,
    quiet: bool,
    scheduler: str | None,
    hold_out: int | None,
    max_steps: int | None,
    progress: bool | None,
) -> None:
    """Fit capture folders (or folders of them): params.json, ρd texture, scanline plot, material.rad.

    A capture that cannot be used is reported with one line and the batch goes
    on; the exit status is 2 if any capture failed. Rerunning skips finished
    captures unless --force.
    """
    import contextlib

    from ._batch import color_note, held_out_note, scanline_note
    from ._fit_progress import fit_with_progress

    err = Console(stderr=True, emoji=False)
    for path in paths:
        _check_name_length(path)
    missing = [str(p) for p in paths if not p.exists()]
    if missing:
        _fail(f"{missing[0]}: no such capture folder")
    _check_out_dir(out_dir)
    from ._batch import _names, check_outputs_apart, find_captures

    try:  # outputs never touch inputs: refused before anything is written
        captures = find_captures(paths, out_dir)
        check_outputs_apart(captures, _names(captures), out_dir)
    except ValueError as exc:
        _fail(str(exc))
    with contextlib.ExitStack() as stack:
        client = None
        if scheduler is not None:
            from ._distributed import open_scheduler

            try:
                client = stack.enter_context(open_scheduler(scheduler, cache_dir=(ctx.obj or {}).get("cache_dir", "")))
            except ValueError as exc:
                return _fail(str(exc))
            if not quiet:
                err.print(f"dask dashboard: {client.dashboard_link}", highlight=False, soft_wrap=True)
        items = fit_with_progress(paths, out_dir, force, quiet, client, err, progress, max_steps, hold_out)
    if not quiet:
        from rich.table import Table

        t = Table(title=f"{len(items)} capture(s) → {out_dir}/summary.csv")
        for col in ("capture", "status", "ρs", "αx", "αy", "fit quality"):
            t.add_column(col)
        for it in items:
            if it.params:
                p, e = it.params["params"], it.params["stderr"]
                pm = lambda k: _pm(p[k], e[k])
                if post := it.params["fit"].get("posterior"):  # a skewed posterior: median [68 % interval]
                    lo, hi = post["alpha_interval_68"]
                    pm = lambda k: f"{p[k]:.4f} [{lo:.4f}, {hi:.4f}]" if k.startswith("alpha") else _pm(p[k], e[k])
                from ..export import fit_quality  # weighted χ²/dof, or a unit-weight fit's RMS residual

                q = fit_quality(it.params["fit"])
                chi, rms = q["weighted_chi2_per_dof"], q["residual_rms_sr-1"]
                t.add_row(
                    it.name,
                    "skipped (done)" if it.skipped else "not physical" if it.params["fit"].get("verdict") else "ok",
                    pm("rho_s"),
                    pm("alpha_x"),
                    pm("alpha_y"),
                    f"χ²/dof {chi:.3g}" if chi is not None else f"RMS {rms:.2g} sr⁻¹" if rms is not None else "–",
                )
            else:
                t.add_row(it.name, "[red]error[/]", "", "", "", "")
        console.print(t)
        for it in items:  # limits that were hit are said, not left in params.json alone
            if note := scanline_note(it.params):
                console.print(f"note: {it.name}: {note}", highlight=False, soft_wrap=True)
            if note := color_note(it.params):
                console.print(f"colour: {it.name}: {note}", highlight=False, soft_wrap=True)
            if note := held_out_note(it.params):
                console.print(f"{it.name}: {note}", highlight=False, soft_wrap=True)
            if verdict := (it.params or {}).get("fit", {}).get("verdict"):  # a photo fit no material has
                console.print(verdict, highlight=False, soft_wrap=True)
    if any(it.status == "error" for it in items):
        sys.exit(2)


@main.command("simulate")
@click.argument("out_dir", type=click.Path(file_okay=False, path_type=Path))
@click.option(
    "--material",
    type=click.Choice(["desk", "marble"]),
    default=None,
    help="Take the parameters of the image-based paper's Table 1.",
)
@click.option("--rho-d", nargs=3, type=float, default=(0.6, 0.5, 0.4), show_default=True)
@click.option("--rho-s", type=float, default=0.04, show_default=True)
@click.option("--alpha-x", type=float, default=0.12, show_default=True)
@click.option("--alpha-y", type=float, default=0.15, show_default=True)
@click.option("--texture", type=click.Choice(["wood", "marble", "noise", "none"]), default="wood", show_default=True)
@click.option("--encoding", type=click.Choice(["srgb", "gamma2.2", "linear"]), default="srgb", show_default=True)
@click.option("--bit-depth", type=click.Choice(["8", "16"]), default="8", show_default=True)
@click.option("--format", "image_format", type=click.Choice(["png", "tif", "jpg"]), default="png", show_default=True)
@click.option(
    "--size",
    nargs=2,
    type=click.IntRange(16, 20000),
    default=(320, 240),
    show_default=True,
    help="Image width and height in pixels.",
)
@click.option("--seed", type=click.IntRange(min=0), default=0, show_default=True)
@click.option(
    "--renderer",
    type=click.Choice(["wardjax", "radiance"]),
    default="wardjax",
    show_default=True,
    help="Who draws the images: wardjax's forward model, or Radiance (rtrace) from the exported material.",
)
@click.option("--force", is_flag=True, help="Replace the files of an existing capture in OUT_DIR.")
def simulate_cmd(
    out_dir,
    material,
    rho_d,
    rho_s,
    alpha_x,
    alpha_y,
    texture,
    encoding,
    bit_depth,
    image_format,
    size,
    seed,
    renderer,
    force,
) -> None:
    """Write a simulated capture folder (lit/dark images + capture.toml + truth) to OUT_DIR."""
    from .._data import table1_materials
    from ..capture import CAPTURE_FILE, RuleError, check_ward_params
    from ..ward import WardParams

    _check_name_length(out_dir)
    if not material:
        try:  # the same rules as capture.toml and the Python API, named as the options are typed
            check_ward_params(rho_d, rho_s, alpha_x, alpha_y)
        except RuleError as e:
            _fail(f"--{e.field.replace('_', '-')}: {e.message}")
    if out_dir.is_dir() and not force and any(out_dir.iterdir()):
        what = "holds a capture" if (out_dir / CAPTURE_FILE).exists() else "is not empty"
        _fail(f"{out_dir}: {what}; choose another folder or add --force to replace its files")
    _check_out_dir(out_dir)
    from ..simulate import simulate_capture

    p = (
        table1_materials()[material]
        if material
        else WardParams(rho_d=rho_d, rho_s=rho_s, alpha_x=alpha_x, alpha_y=alpha_y)
    )
    try:
        cap = simulate_capture(
            p,
            out_dir,
            seed=seed,
            image_size=tuple(size),
            texture=texture,
            encoding=encoding,
            bit_depth=int(bit_depth),
            image_format=image_format,
            renderer=renderer,
        )
    except (ValueError, OSError) as e:
        _fail(str(e).splitlines()[0])
    console.print(
        f"wrote capture [bold]{cap.name}[/] ({cap.rig.camera.width}×{cap.rig.camera.height}, "
        f"{encoding} {bit_depth}-bit {image_format}, drawn by {renderer}) to {out_dir}/"
    )


# --------------------------------------------------------------------------- end capture pipeline


# --------------------------------------------------------------------------- import (photograph datasets)


main.add_command(import_cmd)


# --------------------------------------------------------------------------- end import


# --------------------------------------------------------------------------- texture


@main.group()
def texture() -> None:
    """Parametric ρd texture: analyse a ρd map, synthesise any size from it (Heeger–Bergen)."""


@texture.command("analyze")
@click.argument("rho_d_path", metavar="RHO_D", type=click.Path(path_type=Path))
@click.option(
    "-o",
    "--out",
    "out_path",
    type=click.Path(dir_okay=False, path_type=Path),
    required=True,
    help="Texture description to write: .json or .npz.",
)
@click.option(
    "--region",
    default=None,
    metavar="Y0:Y1,X0:X1",
    help="Pixels to analyse (default: the largest rectangle of valid pixels).",
)
@click.option("--height", type=int, default=None, help="Pyramid levels (default: up to 4, as the region allows).")
@click.option(
    "--quantiles", type=click.IntRange(2, 4097), default=129, show_default=True, help="Entries per quantile table."
)
@click.option(
    "--rho-s",
    type=float,
    default=0.0,
    show_default=True,
    help="Specular reflectance; synthesis clamps ρd to [0, 1 − ρs].",
)
def texture_analyze(
    rho_d_path: Path, out_path: Path, region: str | None, height: int | None, quantiles: int, rho_s: float
) -> None:
    """Describe the ρd texture in RHO_D (a linear .tif/.npy, NaN = no data) by its subband histograms."""
    if out_path.suffix.lower() not in (".json", ".npz"):
        _fail(f"{out_path}: unknown texture file type {out_path.suffix!r}, expected .json or .npz")
    if not 0 <= rho_s < 1:
        _fail(f"--rho-s: must lie in [0, 1), got {rho_s}")
    _check_out_file(out_path)
    from ..texture import analyze_texture, read_rho_d

    try:
        model = analyze_texture(
            read_rho_d(rho_d_path), region=_parse_region(region), height=height, n_quantiles=quantiles, rho_s=rho_s
        )
        model.save(out_path)
    except (ValueError, OSError) as e:
        line = (str(e).splitlines() or [type(e).__name__])[0].replace("rho_s: ", f"--rho-s {rho_s:g}: ", 1)
        _fail(line if str(rho_d_path) in line or str(out_path) in line else f"{rho_d_path}: {line}")
    console.print(f"analysed {model.describe_region()}", highlight=False, soft_wrap=True)
    console.print(
        f"{model.channels} channel(s), {model.height} pyramid levels, {len(model.band_names)} subbands, "
        f"{model.n_quantiles} quantiles each; wrote {out_path} ({out_path.stat().st_size / 1024:.0f} KiB)",
        highlight=False,
        soft_wrap=True,
    )


@texture.command("synthesize")
@click.argument("model_path", metavar="TEXTURE", type=click.Path(path_type=Path))
@click.option("--size", required=True, metavar="WIDTHxHEIGHT", help="Output size in pixels, e.g. 2048x1024.")
@click.option("--seed", type=click.IntRange(min=0), default=0, show_default=True)
@click.option("--iterations", type=click.IntRange(1, 100), default=5, show_default=True)
@click.option(
    "--match",
    type=click.Choice(["binned", "exact"]),
    default="binned",
    show_default=True,
    help="Histogram matching: Heeger & Bergen's binned CDFs and lookup (O(N)), or exact by sorting.",
)
@click.option(
    "-o",
    "--out",
    "out_path",
    type=click.Path(dir_okay=False, path_type=Path),
    required=True,
    help=".tif: linear float ρd; .png: 8-bit sRGB view.",
)
def texture_synthesize(model_path: Path, size: str, seed: int, iterations: int, match: str, out_path: Path) -> None:
    """Synthesise a seamlessly tiling ρd texture of any size from a TEXTURE description."""
    from ..texture import TextureModel, synthesize_texture, write_texture_image

    shape = _parse_size(size)
    if out_path.suffix.lower() not in (".tif", ".tiff", ".png"):
        _fail(f"{out_path}: unknown image type {out_path.suffix!r}, expected .tif, .tiff or .png")
    _check_out_file(out_path)
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

    try:
        model = TextureModel.load(model_path)
    except (ValueError, OSError) as e:
        _fail(str(e).splitlines()[0])
    need = 2 ** (model.height + 2)  # the smallest side the model's pyramid can be synthesised at
    if min(shape) < need:
        _fail(
            f"--size {size}: each side must be at least {need} pixels for a texture analysed with "
            f"{model.height} pyramid level(s) (analyse with fewer levels, --height, for smaller tiles)"
        )
    try:
        with Progress(
            TextColumn("synthesising"),
            BarColumn(),
            MofNCompleteColumn(),
            TimeElapsedColumn(),
            console=Console(stderr=True, emoji=False),
            transient=True,
        ) as bar:
            task = bar.add_task("", total=iterations)
            result = synthesize_texture(
                model,
                shape,
                seed=seed,
                iterations=iterations,
                match=match,
                progress=lambda k, n: bar.update(task, completed=k),
            )
        write_texture_image(out_path, result.image)
    except (ValueError, OSError) as e:  # the library speaks of shape=(height, width); the user typed --size WxH
        _fail(str(e).splitlines()[0].replace(f"shape={shape!r}", f"--size {size}"))
    dist = " ".join(f"{d:.3f}" for d in result.distance)
    console.print(
        f"subband KS distance: start {result.initial_distance:.3f}, per iteration {dist}",
        highlight=False,
        soft_wrap=True,
    )
    console.print(f"wrote {out_path} ({shape[1]}x{shape[0]}, seed {seed})", highlight=False, soft_wrap=True)


# --------------------------------------------------------------------------- end texture


# --------------------------------------------------------------------------- diagnose: missing effects

# pixels per channel the probe is binned to, with the texture carried or not. With it, each LM step whitens every
# scanline by a dense (3 N)² matrix: 6,000 (a 320 × 240 capture binned to 56 × 98, the size the textured bench
# measures at) keeps diagnose within 15 s warm; at 20,000 (112 × 195) it took 80 s.
_DIAGNOSE_SAMPLES = {True: 6_000, False: 20_000}


@main.command("diagnose")
@click.argument("capture", type=click.Path(path_type=Path))
@out_dir_option("Folder for report.json, report.md and the PNGs.")
@click.option(
    "--max-steps", type=click.IntRange(0, 10), default=4, show_default=True, help="At most this many effects are added."
)
@click.option(
    "--max-samples",
    type=click.IntRange(100, 10_000_000),
    default=None,
    help=f"Bin the probe to at most this many pixels per channel [default: {_DIAGNOSE_SAMPLES[True]:,} with the "
    f"texture carried, whose covariance costs (3 N)² per scanline of N values; {_DIAGNOSE_SAMPLES[False]:,} with "
    "--no-texture].",
)
@click.option(
    "--texture/--no-texture",
    default=True,
    show_default=True,
    help="Carry the probe's ρd texture in the model where the baseline's residuals show one (a Gaussian process "
    "with its measured covariance along the scanline and between channels; what neighbouring columns share "
    "discounts the evidence). Without it a textured probe's texture swamps every effect.",
)
@_progress_option
def diagnose_cmd(
    capture: Path, out_dir: Path, max_steps: int, max_samples: int | None, texture: bool, progress: bool | None
) -> None:
    """Find the effects a capture needs beyond the Ward model: report.json, report.md, residual plots."""
    from ._progress import Stages

    _check_name_length(capture)
    if not capture.exists():
        _fail(f"{capture}: no such capture folder")
    _check_out_dir(out_dir)
    try:  # outputs never touch inputs
        check_out_outside(capture, out_dir)
    except ValueError as exc:
        _fail(str(exc))
    with Stages(progress) as stages:
        stages.advance("loading the capture and JAX")
        from ..capture import CAPTURE_FILE, Capture, CaptureError, PhotoCapture, load_capture
        from ..effects import ScanlineModel, discover
        from ..effects._capture import capture_data

        try:
            cap = load_capture(capture)
            if isinstance(cap, PhotoCapture):  # flash, multiview: discovery on photographs: its own model and report
                from ._diagnose_photo import diagnose_photo_cli

                rep = diagnose_photo_cli(cap, out_dir, max_steps=max_steps, progress=stages.advance)
            elif not isinstance(cap, Capture):
                raise CaptureError(
                    CAPTURE_FILE, "method", f"diagnose reads 'scanline', 'flash' or 'multiview', got {cap.method!r}"
                )
            else:
                n = _DIAGNOSE_SAMPLES[texture] if max_samples is None else max_samples
                stages.advance(f"reconstructing the probe's BRDF values (binned to ≤ {n:,} pixels per channel)")
                data = capture_data(cap, max_samples=n)
                model = ScanlineModel(cap.config.fit.normalization)
                stages.advance("baseline fit (the model alone)")
                rep = discover(model, data, max_steps=max_steps, texture=texture, progress=stages.advance)
                stages.advance("writing report.json, report.md and the plots")
                rep.save(out_dir, extra={"capture": cap.name})
        except (CaptureError, ValueError, OSError) as exc:
            stages.fail()  # the failed stage's line first, then the error
            _fail(str(exc).splitlines()[0])
    gaps = " → ".join(f"{g:.3f}" for g in rep.gap)
    console.print(f"{cap.name}: {rep.verdict()}; gap {gaps}; report in {out_dir}/", highlight=False)


# --------------------------------------------------------------------------- report


@main.command("report")
@click.argument("fits_dir", metavar="FITS_DIR", type=click.Path(path_type=Path))
@click.option(
    "-o",
    "--out",
    "out_path",
    type=click.Path(dir_okay=False, path_type=Path),
    required=True,
    help="report.html (one self-contained file) or report.ipynb (the executed notebook).",
)
@_progress_option
def report_cmd(fits_dir: Path, out_path: Path, progress: bool | None) -> None:
    """Write a batch report of the fits in FITS_DIR (the --out folder of wardjax fit): an executed notebook."""
    from ._progress import Stages

    _check_name_length(fits_dir)
    _check_out_file(out_path)
    with Stages(progress, compiles=False) as stages:  # the notebook's kernel compiles in its own process
        stages.advance("loading the report's libraries")
        from ..report import write_report

        try:
            write_report(fits_dir, out_path, progress=stages.advance)
        except (ValueError, OSError) as exc:
            stages.fail()
            _fail(str(exc).splitlines()[0])
    console.print(f"wrote {out_path}", highlight=False)


if __name__ == "__main__":  # pragma: no cover
    main()
