"""``wardjax fit``'s display: a progress bar over the captures, the stages of each capture, one line per failure."""

from __future__ import annotations

from pathlib import Path

from rich.console import Console
from rich.markup import escape

from ._batch import run_batch
from ._progress import Stages

__all__ = ["fit_with_progress"]


def fit_with_progress(
    paths,
    out_dir: Path,
    force: bool,
    quiet: bool,
    client,
    err: Console,
    stages: bool | None = None,
    max_steps: int | None = None,
    hold_out: int | None = None,
) -> list:
    """``wardjax fit``: :func:`~wardjax.run_batch` under a rich progress bar; each failed capture one line on ``err``.

    Within a capture fitted here, each stage is one line with its time (``stages``: see :class:`Stages`).
    """
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

    with Progress(
        TextColumn("{task.description}"),
        BarColumn(),
        MofNCompleteColumn(),
        TimeElapsedColumn(),
        console=err,
        disable=quiet,
        transient=True,
    ) as bar:
        task = bar.add_task("fitting", total=None)

        def on_start(i, n, name):
            bar.update(task, total=n, completed=i, description=f"fitting {name}")

        def progress(i, n, item):
            bar.update(task, completed=i + 1)
            if item.status == "error":  # the capture named once: by its output name, unless the error names its path
                named = item.error.startswith(str(item.source))
                text = item.error if named else f"{item.name}: {item.error}"
                err.print(f"[bold red]error:[/] {escape(text)}", highlight=False, soft_wrap=True)

        def on_stage(name):
            bar.update(task, description=escape(name))

        with Stages(False if quiet else stages, err, on_begin=on_stage):
            return run_batch(
                paths,
                out_dir,
                force=force,
                progress=progress,
                on_start=on_start,
                scheduler=client,
                max_steps=max_steps,
                hold_out=hold_out,
            )
