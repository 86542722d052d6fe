"""``wardjax import``: a photograph dataset in the rectified layout written as a multiview capture folder."""

from __future__ import annotations

from pathlib import Path

import click
from rich.console import Console
from rich.markup import escape

from ._cli_checks import _check_out_dir, _fail, choice_option, out_dir_option

__all__ = ["import_cmd"]


@click.command("import")
@click.argument("src", type=click.Path(path_type=Path))
@out_dir_option("The capture folder to write (new or empty).")
@choice_option("--layout", ("rectified",))
@choice_option("--encoding", ("srgb", "gamma2.2", "linear"), "How the images encode light (MaterialGAN's: gamma2.2).")
@choice_option(
    "--units",
    ("cm", "mm", "m"),
    "Length unit of camera_pos.txt, light_pos.txt, image_size.txt (and of light_power.txt's distances).",
)
@click.option("--name", default=None, help="The capture's name [default: the --out folder's name].")
def import_cmd(src: Path, out_dir: Path, layout: str, encoding: str, units: str, name: str | None) -> None:
    """Write a multiview capture folder from a dataset in the rectified layout (see docs/photographs.md)."""
    if not src.is_dir():
        _fail(f"{src}: no such dataset folder")
    _check_out_dir(out_dir)
    from ..capture import PhotoCapture, import_capture

    try:
        cap: PhotoCapture = import_capture(src, out_dir, layout=layout, encoding=encoding, units=units, name=name)
    except (ValueError, OSError) as e:
        _fail(str(e).splitlines()[0])
        return
    h, w, k, _ = cap.f_r.shape
    Console(emoji=False).print(
        f"wrote capture [bold]{escape(cap.name)}[/]: {k} photos {w}×{h}, {cap.pixel_mm:.3g} mm a pixel, "
        f"{int(cap.mask.any(axis=-1).sum())} pixels observed, to {escape(str(out_dir))}/",
        highlight=False,
        soft_wrap=True,
    )
