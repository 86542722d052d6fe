"""Folders of captures: fit each, write its outputs, keep a ``summary.csv``; survive bad input and kills.

:func:`run_batch` takes capture folders and folders of capture folders. For
each capture it loads, fits and writes ``OUT/<name>/`` (see
:func:`wardjax.export.write_capture_outputs`). A capture that fails is
recorded in ``summary.csv`` with its one-line error and the batch goes on;
a failure the code did not foresee (not a ``ValueError``) keeps its traceback
in ``OUT/errors.log``.

Restartable: every file is written atomically and ``params.json`` is written
last, so a capture is finished exactly when its ``params.json`` exists and
records the checksums of the current inputs. A rerun skips finished captures
(unless ``force``), removes temporary files a killed run left behind and
redoes the rest (a capture's outputs are written into a hidden staging
folder and moved into place only when all are written, so a fit that fails
mid-way writes nothing for that capture); its outputs are identical to those of an uninterrupted run,
the ``created`` timestamp aside. ``summary.csv`` is rebuilt from the
``params.json`` files, so it does not depend on which run made them.
"""

from __future__ import annotations

import csv
import dataclasses
import datetime
import glob
import io
import json
import re
import secrets
import shutil
import traceback
from collections.abc import Callable
from pathlib import Path

from .._files import commit_folder, recover_commit, remove_temporaries, sha256, write_bytes_atomic
from ..capture import CAPTURE_FILE, CaptureError, load_capture
from ..export import FIT_QUALITY_COLUMNS, fit_quality, write_capture_outputs
from ._fit_capture import fit_capture
from ._fit_photo import fit_photo_outputs
from ._progress import stage
from ._smartphone import fit_smartphone_capture

__all__ = ["BatchItem", "check_outputs_apart", "find_captures", "fit_one", "run_batch", "SUMMARY_COLUMNS"]

SUMMARY_COLUMNS = (
    "capture",
    "status",
    "method",
    "model",
    "normalization",
    "rho_d_r",
    "rho_d_g",
    "rho_d_b",
    "rho_s",
    "alpha_x",
    "alpha_y",
    "rho_d_r_err",
    "rho_d_g_err",
    "rho_d_b_err",
    "rho_s_err",
    "alpha_x_err",
    "alpha_y_err",
    "fit_status",
    *FIT_QUALITY_COLUMNS,
    "valid_pixels",
    "error",
    "source",
)


def _fit_scanline(cap, out_dir: Path, created: str, max_steps: int | None = None) -> dict:
    fitted = fit_capture(cap, max_steps=max_steps)
    stage(f"{cap.name}: writing params.json, the texture, plots and material")
    return write_capture_outputs(fitted, out_dir, created=created)


# Fitters by capture method (``method`` in capture.toml): each fits a loaded capture and writes its outputs.
FITTERS: dict[str, Callable] = {
    "scanline": _fit_scanline,
    "smartphone": fit_smartphone_capture,
    "flash": fit_photo_outputs,
    "multiview": fit_photo_outputs,
}


@dataclasses.dataclass(frozen=True)
class BatchItem:
    """One capture of a batch: its folder, output name, and the outcome."""

    source: Path
    name: str
    status: str  # "ok" | "error"
    error: str = ""
    skipped: bool = False
    params: dict | None = None


def _is_output_folder(folder: Path, out: Path | None) -> bool:
    """``folder`` is the batch's output folder, or a folder a wardjax fit wrote (a ``summary.csv``
    beside fitted subfolders): never a capture."""
    if out is not None and folder.resolve() == out.resolve():
        return True
    return (folder / "summary.csv").is_file() and not (folder / CAPTURE_FILE).exists()


def find_captures(paths, out=None) -> list[Path]:
    """Capture folders among ``paths``.

    A path holding ``capture.toml`` is a capture. A folder without one is a
    folder of captures if it has subfolders (each non-hidden subfolder is a
    capture, broken or not), else it is itself a (broken) capture. Order:
    as given, subfolders sorted by name. The output folder ``out`` (and any
    folder of fits, one holding a ``summary.csv``) is skipped when a folder
    of captures is scanned.
    """
    out = None if out is None else Path(out)
    found: list[Path] = []
    for p in map(Path, paths):
        if (p / CAPTURE_FILE).exists() or not p.is_dir():  # a capture, even if its capture.toml is broken
            found.append(p)
            continue
        subs = sorted(
            d for d in p.iterdir() if d.is_dir() and not d.name.startswith(".") and not _is_output_folder(d, out)
        )
        found.extend(subs if subs else [p])
    return found


def _overlap(a: Path, b: Path) -> bool:
    return a == b or a.is_relative_to(b) or b.is_relative_to(a)


def check_outputs_apart(captures: list[Path], names: list[str], out) -> None:
    """Refuse a batch whose outputs could touch its inputs: ``OUT/<name>/`` that is, holds or lies in a capture folder.

    Outputs go to ``OUT/<name>/`` under names an input may hold (``rho_d.png``,
    ``params.json``), so a capture folder and an output folder must not overlap;
    ``OUT`` itself may lie among the captures (it is skipped when they are scanned).

    Raises
    ------
    ValueError
        One line naming ``--out``, the capture and the folder they share.
    """
    out = Path(out)
    sources = [c.resolve() for c in captures]
    for name in names:
        dest = (out / name).resolve()
        for src, given in zip(sources, captures):
            if _overlap(dest, src):
                raise ValueError(
                    f"--out {out}: the outputs of {name} would go to {out / name}, which "
                    f"{'is' if dest == src else 'overlaps'} the capture folder {given}; "
                    "choose an output folder outside every capture folder"
                )


def _names(captures: list[Path]) -> list[str]:
    names, seen = [], {}
    for c in captures:
        base = c.resolve().name or "capture"
        k = seen.get(base, 0) + 1
        seen[base] = k
        names.append(base if k == 1 else f"{base}-{k}")
    return names


def _finished(source: Path, out_dir: Path) -> dict | None:
    """The ``params.json`` document if ``out_dir`` holds a finished fit of the current inputs."""
    pj = out_dir / "params.json"
    if not pj.is_file():
        return None
    try:
        doc = json.loads(pj.read_text())
        inputs = doc["inputs"]
        for fname, digest in inputs.items():
            f = source / fname
            if not f.is_file() or sha256(f) != digest:
                return None
        files = doc.get("files", {})
        if not all((out_dir / f).is_file() for f in files.values()):
            return None
    except (OSError, ValueError, KeyError, TypeError, AttributeError):
        return None
    return doc


def _row(item: BatchItem) -> dict:
    row = {k: "" for k in SUMMARY_COLUMNS}
    row.update(capture=item.name, status=item.status, error=item.error, source=str(item.source))
    d = item.params
    if d:
        p, e = d["params"], d["stderr"]
        row.update(
            method=d["method"],
            model=d["model"],
            normalization=d["normalization"],
            fit_status=d["fit"]["status"],
            # weighted χ²/dof, or a unit-weight fit's RMS residual; none for the smartphone method
            **{k: _num(v) for k, v in fit_quality(d["fit"]).items()},
            valid_pixels=d["fit"].get("diagnostics", {}).get("pixels", {}).get("valid", ""),
        )
        for src, suffix in ((p, ""), (e, "_err")):
            for i, ch in enumerate("rgb"):
                row[f"rho_d_{ch}{suffix}"] = _num(src["rho_d"][i])
            for k in ("rho_s", "alpha_x", "alpha_y"):
                row[f"{k}{suffix}"] = _num(src[k])
    return row


def scanline_note(doc: dict | None) -> str | None:
    """One line on the scanlines of a finished fit that stopped at the step limit, or ``None`` if none did.

    Such a scanline's parameters are the best point found, not certified
    (:class:`~wardjax.Status` ``MAX_STEPS``); the count is in ``params.json``
    ``fit.diagnostics.scanlines.status`` and is said, never left silent.
    """
    if not doc:
        return None
    scan = doc.get("fit", {}).get("diagnostics", {}).get("scanlines", {})
    stopped, total = int(scan.get("status", {}).get("max_steps", 0)), int(scan.get("count", 0))
    if stopped == 0:
        return None
    return (
        f"{stopped} of {total} scanlines stopped at the step limit (status max_steps): their own parameters are the "
        f"best point found, not certified a minimum. The material reported is the joint fit to every scanline's "
        f"data, whose own status is {doc['fit'].get('status', '?')}; the limit moves only the per-scanline values "
        f"and the joint fit's start (raise it with wardjax fit --max-steps)"
    )


def color_note(doc: dict | None) -> str | None:
    """One line on a smartphone fit's colour: the chart correction's ΔE*ab, or that none was asked for."""
    if not doc or doc.get("method") != "smartphone":
        return None
    cc = doc.get("fit", {}).get("color_correction")
    if cc is None:
        return (
            "no [color_correction] in capture.toml: ρd's σ is the region's standard error only; "
            "the camera's colour error (ΔE*ab often 5–20) is not in it"
        )
    loo, raw = cc["delta_E_held_out"], cc["delta_E_uncorrected"]
    return (
        f"ColorChecker correction ({cc['method']}, {cc['patches_used']} patches): leave-one-out ΔE*ab (D50) "
        f"mean {loo['mean']:.1f}, max {loo['max']:.1f} (uncorrected mean {raw['mean']:.1f}); ρd's σ includes it"
    )


def held_out_note(doc: dict | None) -> str | None:
    """One line on the held-out photo of a finished photograph fit (``wardjax fit --hold-out``), or ``None``."""
    ho = (doc or {}).get("fit", {}).get("held_out")
    if not ho:
        return None
    return (
        f"held-out photo {ho['photo']} ({ho['file']}): RMSE {ho['rmse_linear']:.4g} linear "
        f"(noise {ho['rmse_noise']:.3g}), {ho['rmse_display']:.4g} display, PSNR {ho['psnr_db']:.2f} dB"
    )


def _num(x) -> str:
    return "" if x is None else f"{float(x):.6g}"


def _earlier_fits(out: Path, names: set[str]) -> list[BatchItem]:
    """The finished fits in ``out`` from earlier batches: every ``<name>/params.json`` not in ``names``."""
    found = []
    for pj in sorted(out.glob("*/params.json")):
        name = pj.parent.name
        if name in names or name.startswith("."):
            continue
        try:
            doc = json.loads(pj.read_text())
            _row(BatchItem(pj.parent, name, "ok", params=doc))  # a document a summary row can be made of
        except (OSError, ValueError, KeyError, TypeError, AttributeError, IndexError):
            continue
        found.append(BatchItem(pj.parent, name, "ok", params=doc))
    return found


def write_summary(path: Path, items: list[BatchItem]) -> None:
    """``summary.csv``: one row per capture of this batch, in batch order, then one per finished fit an
    earlier batch left in the same folder (every ``params.json``, by name); atomic."""
    buf = io.StringIO()
    wr = csv.DictWriter(buf, fieldnames=SUMMARY_COLUMNS, lineterminator="\n")
    wr.writeheader()
    for it in [*items, *_earlier_fits(path.parent, {it.name for it in items})]:
        wr.writerow(_row(it))
    write_bytes_atomic(path, buf.getvalue().encode())


# Tracebacks of the failures the code did not foresee, one file per batch output folder.
ERROR_LOG = "errors.log"


def _one_line(e: BaseException, log: Path | None = None) -> str:
    """The error as the user reads it: foreseen errors (``ValueError``: a capture, a rule) as they are;
    anything else as its type and first line, pointing at ``log`` where its traceback is kept."""
    text = str(e).strip().splitlines()
    first = text[0] if text else ""
    if isinstance(e, ValueError) and first:
        return first
    where = f"; traceback in {log}" if log is not None else ""
    return f"unexpected failure ({type(e).__name__}{': ' + first if first else ''}){where}"


# The tail of a staging folder's name after ``.<name>``: this attempt's token (or none, from older runs).
_STAGING = re.compile(r"(\.[0-9a-f]{8})?\.partial")


def fit_one(
    source: Path,
    name: str,
    out: Path,
    created: str,
    force: bool = False,
    hold_out: int | None = None,
    max_steps: int | None = None,
) -> tuple[BatchItem, str | None]:
    """Fit one capture of a batch into ``out/<name>/``: the unit of work, locally or as a cluster task.

    Skips a capture already finished with the current inputs (unless
    ``force``). The outputs are written into a staging folder of this attempt
    (``out/.<name>.<token>.partial``) and committed with ``params.json`` last,
    so a killed attempt leaves no file in ``out/<name>/`` and its rerun (a
    retried task) starts afresh from what it left (one killed while the files
    moved is settled by the commit's journal, :func:`~wardjax._files.recover_commit`); a capture an earlier
    attempt of *this* batch (same ``created``) already committed is not
    written again.

    Returns
    -------
    BatchItem, str or None
        The outcome, and the traceback of a failure the code did not foresee
        (for ``errors.log``), else ``None``.
    """
    out_dir = out / name
    remove_temporaries(out_dir)
    recover_commit(out_dir)  # a kill during an earlier commit's moves: its half-moved files go, then it reruns
    for stale in out.glob(f".{glob.escape(name)}.*partial"):  # what a killed attempt left behind
        if _STAGING.fullmatch(stale.name[len(name) + 1 :]):
            shutil.rmtree(stale, ignore_errors=True)
    doc = _finished(source, out_dir)
    if doc is not None and (not force or doc.get("created") == created):
        return BatchItem(source, name, "ok", skipped=doc.get("created") != created, params=doc), None
    staging = out / f".{name}.{secrets.token_hex(4)}.partial"
    try:
        cap = load_capture(source)
        fitter = FITTERS.get(cap.method)
        if fitter is None:
            raise CaptureError(CAPTURE_FILE, "method", f"no fitter for method {cap.method!r}")
        if hold_out is not None and cap.method not in ("flash", "multiview"):
            raise CaptureError(CAPTURE_FILE, "method", f"--hold-out needs a photograph capture, got {cap.method!r}")
        kw: dict = {} if hold_out is None else {"hold_out": hold_out}
        # the step limit is the scanline fits' (the other methods have none)
        if max_steps is not None and cap.method == "scanline":
            kw["max_steps"] = max_steps
        doc = fitter(cap, staging, created=created, **kw)
        commit_folder(staging, out_dir, last="params.json")
        return BatchItem(source, name, "ok", params=doc), None
    except Exception as e:  # a bad capture must not sink the batch, nor leave half its outputs
        shutil.rmtree(staging, ignore_errors=True)
        line = _one_line(e, out / ERROR_LOG)
        tb = None
        if line.startswith("unexpected failure"):
            tb = f"{name} ({source}):\n{''.join(traceback.format_exception(e))}"
        return BatchItem(source, name, "error", error=line), tb


def run_batch(
    paths,
    out,
    *,
    force: bool = False,
    progress: Callable[[int, int, BatchItem], None] | None = None,
    on_start: Callable[[int, int, str], None] | None = None,
    scheduler=None,
    hold_out: int | None = None,
    max_steps: int | None = None,
) -> list[BatchItem]:
    """Fit every capture under ``paths`` into ``out``; write ``out/summary.csv``.

    Parameters
    ----------
    paths
        Capture folders or folders of them (see :func:`find_captures`).
    out
        Output folder; each capture gets ``out/<name>/``. It must not overlap a
        capture folder (:func:`check_outputs_apart`, ``ValueError`` before anything
        is written); it may lie among the captures.
    force
        Refit captures that are already finished.
    progress, on_start
        Callbacks ``(index, total, item)`` after and ``(index, total, name)``
        before each capture (the CLI draws its progress bar with them). On a
        cluster ``progress`` is called as captures finish, ``index`` counting
        them, and ``on_start`` once, before the first, with the cluster's name.
    scheduler
        ``None``: fit here, one capture after another. Otherwise a
        ``dask.distributed`` cluster fits one capture per task: a
        ``distributed.Client``, a scheduler address (``"tcp://host:8786"``) or
        ``"local[:N]"`` (a ``LocalCluster`` of ``N`` worker processes); see
        :func:`wardjax.run.open_scheduler`. The outputs are the same files.
    hold_out
        Photograph captures: leave photo ``hold_out`` out of each fit and predict it.
    max_steps
        Levenberg–Marquardt steps of each scanline's own fit (see
        :func:`wardjax.fit_capture`); default 4.

    Returns
    -------
    list of BatchItem
        In batch order; ``status`` is ``"ok"`` or ``"error"`` with the one-line error.
    """
    out = Path(out)
    captures = find_captures(paths, out)
    names = _names(captures)
    check_outputs_apart(captures, names, out)
    out.mkdir(parents=True, exist_ok=True)
    # Microseconds: ``created`` also tells this batch's commits from an earlier batch's (a retried task
    # skips what this batch already wrote, a rerun skips what an earlier one did), even a second apart.
    created = datetime.datetime.now(datetime.UTC).isoformat(timespec="microseconds").replace("+00:00", "Z")
    jobs = [(src, name, out, created, force, hold_out, max_steps) for src, name in zip(captures, names)]
    done: dict[int, BatchItem] = {}
    log: list[str] = []

    def record(i: int, item: BatchItem, tb: str | None) -> None:
        done[i] = item
        if tb is not None:
            log.append(tb)
            write_bytes_atomic(out / ERROR_LOG, "\n".join(log).encode())
        write_summary(out / "summary.csv", [done[k] for k in sorted(done)])
        if progress:
            progress(len(done) - 1 if scheduler is not None else i, len(jobs), item)

    if scheduler is None:
        for i, job in enumerate(jobs):
            if on_start:
                on_start(i, len(jobs), job[1])
            record(i, *fit_one(*job))
    else:
        from ._distributed import map_on_cluster

        def fail(i: int, why: str) -> None:
            record(i, BatchItem(jobs[i][0], jobs[i][1], "error", error=why), None)

        map_on_cluster(fit_one, jobs, scheduler, record, fail, on_start=on_start)
    items = [done[i] for i in range(len(jobs))]
    write_summary(out / "summary.csv", items)
    return items
