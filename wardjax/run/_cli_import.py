"""``wardjax import``: a photograph dataset in the rectified layout written as a multiview capture folder."""

from __future__ import annotations

from pathlib import Path

import click
from rich.console import Console
from rich.markup import escape

__all__ = ["import_cmd"]


class _BadInput(click.ClickException):
    """A refusal: one ``error: …`` line (printed by the ``wardjax`` group) and exit status 2."""

    exit_code = 2


@click.command("import")
@click.argument("src", type=click.Path(path_type=Path))
@click.option(
    "--out",
    "out_dir",
    type=click.Path(file_okay=False, path_type=Path),
    required=True,
    help="The capture folder to write (new or empty).",
)
@click.option("--layout", type=click.Choice(["rectified"]), default="rectified", show_default=True)
@click.option(
    "--encoding",
    type=click.Choice(["srgb", "gamma2.2", "linear"]),
    default="srgb",
    show_default=True,
    help="How the images encode light (MaterialGAN's captures: gamma2.2).",
)
@click.option(
    "--units",
    type=click.Choice(["cm", "mm", "m"]),
    default="cm",
    show_default=True,
    help="Length unit of camera_pos.txt, light_pos.txt, image_size.txt (and of light_power.txt's distances).",
)
@click.option("--name", default=None, help="The capture's name [default: the --out folder's name].")
def import_cmd(src: Path, out_dir: Path, layout: str, encoding: str, units: str, name: str | None) -> None:
    """Write a multiview capture folder from a dataset in the rectified layout (see docs/photographs.md)."""
    from .._files import check_writable_dir

    if not src.is_dir():
        raise _BadInput(f"{src}: no such dataset folder")
    try:
        check_writable_dir(out_dir)
    except ValueError as e:
        raise _BadInput(str(e)) from None
    from ..capture import PhotoCapture, import_capture

    try:
        cap: PhotoCapture = import_capture(src, out_dir, layout=layout, encoding=encoding, units=units, name=name)
    except (ValueError, OSError) as e:
        raise _BadInput(str(e).splitlines()[0]) from None
    h, w, k, _ = cap.f_r.shape
    Console(emoji=False).print(
        f"wrote capture [bold]{escape(cap.name)}[/]: {k} photos {w}×{h}, {cap.pixel_mm:.3g} mm a pixel, "
        f"{int(cap.mask.any(axis=-1).sum())} pixels observed, to {escape(str(out_dir))}/",
        highlight=False,
        soft_wrap=True,
    )
