"""``wardjax report``: the report notebook executed on a folder of fits, as one self-contained HTML file."""

from __future__ import annotations

import os
import re
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

from .._files import check_writable_file, write_bytes_atomic
from ._collect import load_fits
from ._validate import validate_fits_dir

__all__ = ["REPORT_SUFFIXES", "write_report"]

REPORT_SUFFIXES = (".html", ".ipynb")
TEMPLATE = Path(__file__).with_name("template.ipynb")


def _kernel_manager_class() -> dict[str, Any]:
    """The kernel's sockets as IPC files on POSIX (the kernel talks to this process only, never over the network).

    Over TCP without encryption ipykernel prints a warning on every start;
    over IPC there is nothing to warn about. Elsewhere (Windows has no IPC
    transport) papermill's default manager is kept.
    """
    if os.name != "posix":
        return {}
    from jupyter_client.manager import AsyncKernelManager
    from traitlets import default

    class IPCKernelManager(AsyncKernelManager):
        @default("transport")
        def _default_transport(self) -> str:
            return "ipc"

    return {"kernel_manager_class": IPCKernelManager}


def write_report(fits_dir, out, *, timeout: int = 900, progress: Callable[[str], None] | None = None) -> Path:
    """Execute the report notebook on ``fits_dir`` and write it to ``out`` (``.html`` or ``.ipynb``).

    The template (``wardjax/report/template.ipynb``) is run by papermill with
    ``fits_dir`` as its parameter; ``.html`` is converted by nbconvert with the
    code hidden and every image embedded, so the file opens in a browser with
    no server and no other file.

    ``progress``, if given, is called with each stage's name as it begins
    (``wardjax report`` shows them on the terminal).

    Raises
    ------
    ValueError
        ``fits_dir`` holds no finished capture, or ``out`` has another suffix or
        cannot be written; before any notebook runs.
    """
    out = Path(out)
    if out.suffix.lower() not in REPORT_SUFFIXES:
        raise ValueError(f"{out}: unknown report type {out.suffix!r}, expected .html or .ipynb")
    check_writable_file(out)  # a name too long, a folder: before the notebook runs
    parent = out.resolve().parent
    if parent.exists() and not (parent.is_dir() and os.access(parent, os.W_OK)):
        raise ValueError(f"{out}: cannot write there ({parent} is not a writable folder)")
    say = progress or (lambda _: None)
    fits = Path(fits_dir).resolve()
    say("reading the fits")
    validate_fits_dir(fits)  # every file the notebook reads, field by field, before a kernel starts
    load_fits(fits)  # one clear error for an empty or broken folder, before the kernel starts

    import nbformat
    import papermill

    with tempfile.TemporaryDirectory() as tmp:
        say("running the report notebook in a Python kernel")
        executed = Path(tmp) / "report.ipynb"
        papermill.execute_notebook(
            str(TEMPLATE),
            str(executed),
            parameters={"fits_dir": str(fits)},
            kernel_name="python3",
            progress_bar=False,
            execution_timeout=timeout,
            cwd=tmp,
            **_kernel_manager_class(),
        )
        nb = nbformat.read(executed, as_version=4)
    if out.suffix.lower() == ".ipynb":
        write_bytes_atomic(out, nbformat.writes(nb).encode())
        return out
    say("converting to one self-contained HTML file")
    from nbconvert import HTMLExporter

    exporter = HTMLExporter(
        exclude_input=True, exclude_input_prompt=True, exclude_output_prompt=True, embed_images=True
    )
    body, _ = exporter.from_notebook_node(nb)
    # Nothing from the network: the report has no code to run and no maths to typeset.
    body = re.sub(r'<script[^>]*src="https?://[^"]*"[^>]*>\s*</script>', "", body)
    write_bytes_atomic(out, body.encode("utf-8"))
    return out
