"""The command line's boundary checks: one refusal line, output paths, the small argument parsers."""

from __future__ import annotations

import os
import sys
from pathlib import Path

import click
from rich.console import Console
from rich.markup import escape

__all__ = [
    "_check_name_length",
    "_check_out_dir",
    "_check_out_file",
    "_fail",
    "_one_line",
    "_parse_region",
    "_parse_size",
    "check_out_outside",
    "choice_option",
    "out_dir_option",
]


def _fail(message: str, code: int = 2) -> None:
    """Print one unwrapped ``error: …`` line on stderr and exit with status ``code`` (2: bad input).

    ``soft_wrap`` keeps a long message (a deep path) on one line, and the
    message is escaped so that text like ``[y0, y1, x0, x1]`` is not read as
    rich markup.
    """
    text = _one_line(message)
    if len(text) > _MAX_LINE:  # a huge value echoed from the input: the line stays readable
        text = f"{text[: _MAX_LINE - 40]}… ({len(text):,} characters)"
    Console(stderr=True, soft_wrap=True, emoji=False).print(f"[bold red]error:[/] {escape(text)}", highlight=False)
    sys.exit(code)


# The longest refusal line printed (characters); the rest of a longer one is cut.
_MAX_LINE = 600


def _one_line(text: str) -> str:
    """``text`` with line breaks and control characters escaped (an argument typed as ``$'\\x85'`` stays on the line).

    The rule of :func:`wardjax.capture.one_line`, here so that a refusal does not import the library (and JAX).
    """
    import unicodedata

    return "".join(
        ch.encode("unicode_escape").decode("ascii") if unicodedata.category(ch) in ("Cc", "Zl", "Zp") else ch
        for ch in text
    )


def _check_name_length(path: Path) -> None:
    """Refuse a path with a component longer than file systems allow (255 bytes), before it is looked up."""
    if any(len(os.fsencode(part)) > 255 for part in path.parts):
        _fail(f"{path}: a path component is longer than the 255 bytes file systems allow")


def _check_out_dir(path: Path) -> None:
    """Refuse, before any computation, an output folder that cannot be written (one line, exit 2)."""
    from .._files import check_writable_dir

    try:
        check_writable_dir(path)
    except ValueError as e:
        _fail(str(e))


def check_out_outside(capture, out) -> None:
    """Refuse an output folder that is, or lies inside, the capture folder ``capture`` (``wardjax diagnose --out``).

    Its files (``report.json``, ``report.md``, the PNGs) are written straight into ``out``, under
    names a capture folder may hold; a folder that holds the capture cannot collide with it.
    """
    out, capture = Path(out), Path(capture)
    dest, src = out.resolve(), capture.resolve()
    if dest == src or dest.is_relative_to(src):
        raise ValueError(
            f"--out {out}: {'is' if dest == src else 'lies inside'} the capture folder {capture}; "
            "choose an output folder outside it"
        )


def _check_out_file(path: Path) -> None:
    """Refuse, before any computation, an output file that cannot be written (one line, exit 2)."""
    from .._files import check_writable_file

    try:
        check_writable_file(path)
    except ValueError as e:
        _fail(str(e))


def _parse_region(text: str | None) -> tuple[int, int, int, int] | None:
    """``"Y0:Y1,X0:X1"`` → ``(y0, y1, x0, x1)``."""
    if text is None:
        return None
    try:
        rows, cols = text.split(",")
        y0, y1 = (int(v) for v in rows.split(":"))
        x0, x1 = (int(v) for v in cols.split(":"))
    except ValueError:
        _fail(f"--region {text!r}: expected Y0:Y1,X0:X1 (rows then columns, half-open), e.g. 0:512,100:612")
    return y0, y1, x0, x1


def _parse_size(text: str) -> tuple[int, int]:
    """``"WIDTHxHEIGHT"`` → ``(height, width)``."""
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        _fail(f"--size {text!r}: expected WIDTHxHEIGHT in pixels, e.g. 2048x1024")
    if w < 1 or h < 1:
        _fail(f"--size {text!r}: width and height must be positive")
    return h, w


def out_dir_option(help: str):
    """The required ``--out DIR`` option: the folder a command writes (``help`` says what goes in it)."""
    return click.option("--out", "out_dir", type=click.Path(file_okay=False, path_type=Path), required=True, help=help)


def choice_option(flag: str, choices: tuple[str, ...], help: str | None = None):
    """An option ``flag`` taking one of ``choices``, the first the default (shown in ``--help``)."""
    return click.option(flag, type=click.Choice(choices), default=choices[0], show_default=True, help=help)
