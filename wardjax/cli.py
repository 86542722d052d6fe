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


if __name__ == "__main__":  # pragma: no cover
    main()

