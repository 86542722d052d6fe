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

__all__ = ["main"]

console = Console()


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(package_name="wardjax")
def main() -> None:
    """Measure Ward BRDF parameters from photographs, with honest uncertainties."""


def _fail(message: str) -> None:
    Console(stderr=True).print(f"[bold red]error:[/] {message}", highlight=False)
    sys.exit(2)


# --------------------------------------------------------------------------- demo


@main.command()
@click.option("--out", "out_dir", type=click.Path(file_okay=False, path_type=Path), default=Path("demo-output"),
              show_default=True, help="Folder for the results.")
@click.option("--scanlines", type=click.IntRange(8, 100_000), default=64, show_default=True,
              help="Scanlines per material.")
@click.option("--seed", type=int, default=0, show_default=True)
def demo(out_dir: Path, scanlines: int, seed: int) -> None:
    """Simulate the desk and marble of the paper's Table 1, fit them, compare with the truth."""
    from .demo import run_scanline_demo

    run_scanline_demo(out_dir, scanlines=scanlines, seed=seed, console=console)


# --------------------------------------------------------------------------- gratings (smartphone method)


@main.command()
@click.option("--display", "display_name", default="iphone5s", show_default=True,
              help="Display in calibration/smartphone_setup.toml.")
@click.option("--viewing", "viewing_name", default="paper", show_default=True,
              help="Viewing geometry in calibration/smartphone_setup.toml (for the CPD column).")
@click.option("--out", "out_dir", type=click.Path(file_okay=False, path_type=Path), required=True,
              help="Folder for the PNG set and gratings.csv.")
@click.option("--orientation", type=click.Choice(["vertical", "horizontal"]), default="vertical",
              show_default=True)
def gratings(display_name: str, viewing_name: str, out_dir: Path, orientation: str) -> None:
    """Write the square-wave grating PNGs (1 PNG per whole PPB) to load onto the phone."""
    from .psychophysics import write_gratings

    try:
        paths = write_gratings(out_dir, display_name, viewing_name, orientation=orientation)
    except (ValueError, OSError) as exc:
        _fail(str(exc))
    console.print(f"wrote {len(paths)} gratings and gratings.csv to {out_dir}")


# --------------------------------------------------------------------------- end gratings


if __name__ == "__main__":  # pragma: no cover
    main()

