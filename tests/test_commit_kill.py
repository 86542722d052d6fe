"""A run killed while it moves a capture's outputs into place: the rerun resumes, never refuses or misreads.

A batch writes a capture's outputs into a staging folder and moves them into
``OUT/<name>/`` with ``params.json`` last (:func:`wardjax._files.commit_folder`).
A kill between two of those moves leaves ``OUT/<name>/`` holding some new files
beside nothing (a first fit) or beside an earlier fit's files. The rerun must
then neither refuse the folder as someone else's nor take the mixture for a
finished fit: it writes the capture afresh, or keeps a commit that had finished.

The fast tests stop the move at each point in process (an exception no handler
catches leaves exactly what a kill leaves: no cleanup runs); the slow one kills
a real ``wardjax fit`` with SIGKILL in the middle of its moves.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import textwrap
from pathlib import Path

import imageio.v3 as iio
import numpy as np
import pytest
import tomli_w

from wardjax._files import COMMIT_JOURNAL, write_bytes_atomic
from wardjax.run import _batch
from wardjax.run._batch import fit_one

OUTPUTS = ("material.rad", "rho_d.png", "params.json")  # params.json is moved last


class _Killed(BaseException):
    """Stands for SIGKILL: not an ``Exception``, so no handler of the code under test runs."""


def _phone(folder: Path) -> Path:
    """A smartphone capture: it loads in milliseconds (the fitter is replaced below)."""
    folder.mkdir(parents=True)
    rng = np.random.default_rng(0)
    iio.imwrite(folder / "photo.png", np.clip(rng.normal(200, 3, (48, 64, 3)), 0, 255).astype(np.uint8))
    photo = {"file": "photo.png", "region": [8, 40, 8, 56]}
    cfg = {"method": "smartphone", "photo": photo, "thresholds": {"ppb": [12]}}
    (folder / "capture.toml").write_text(tomli_w.dumps(cfg))
    return folder


def _fitter(cap, out_dir: Path, *, created: str) -> dict:
    """Writes what a fitter writes, each file carrying the run (``created``) that wrote it."""
    for name in OUTPUTS[:-1]:
        write_bytes_atomic(out_dir / name, f"{created}:{name}".encode())
    doc = {
        "software": {"name": "wardjax"},
        "created": created,
        "inputs": dict(cap.checksums),
        "files": {n: n for n in OUTPUTS[:-1]},
    }
    write_bytes_atomic(out_dir / "params.json", json.dumps(doc).encode())
    return doc


def _stop_at(monkeypatch, k: int) -> None:
    """Stop the commit after ``k`` of its moves out of the staging folder (``len(OUTPUTS)``: after all)."""
    real_replace, real_unlink = os.replace, os.unlink
    moved = []

    def replace(src, dst):
        if Path(src).parent != Path(dst).parent:  # a move out of the staging folder (not an atomic write)
            if len(moved) == k:
                raise _Killed
            moved.append(dst)
        return real_replace(src, dst)

    def unlink(path, *a, **kw):
        if Path(path).name == COMMIT_JOURNAL and len(moved) == k:
            raise _Killed
        return real_unlink(path, *a, **kw)

    monkeypatch.setattr(os, "replace", replace)
    monkeypatch.setattr(os, "unlink", unlink)


@pytest.mark.parametrize("earlier", [False, True], ids=["first-fit", "over-an-earlier-fit"])
@pytest.mark.parametrize("k", range(len(OUTPUTS) + 1))
def test_a_kill_during_the_final_move_resumes_cleanly(tmp_path, monkeypatch, k, earlier):
    monkeypatch.setitem(_batch.FITTERS, "smartphone", _fitter)
    cap, out = _phone(tmp_path / "caps" / "p"), tmp_path / "fits"
    if earlier:
        assert fit_one(cap, "p", out, "run-1")[0].status == "ok"
    with monkeypatch.context() as m:
        _stop_at(m, k)
        with pytest.raises(_Killed):
            fit_one(cap, "p", out, "run-2", force=earlier)
    assert list(out.glob(".p.*.partial")), "the kill left the staging folder, as a real one does"
    item, tb = fit_one(cap, "p", out, "run-3")
    assert item.status == "ok" and tb is None, item.error
    assert sorted(p.name for p in (out / "p").iterdir()) == sorted(OUTPUTS)  # no journal, no stray file
    doc = json.loads((out / "p" / "params.json").read_text())
    # one run's files, never a mixture: a commit that had finished is kept, any other is written afresh
    assert doc["created"] == ("run-2" if k == len(OUTPUTS) else "run-3")
    for name in OUTPUTS[:-1]:
        assert (out / "p" / name).read_text() == f"{doc['created']}:{name}"
    assert not list(out.glob(".p.*.partial"))
    assert fit_one(cap, "p", out, "run-4")[0].skipped  # and then it is finished


def test_an_import_killed_during_its_final_move_runs_again(tmp_path, monkeypatch):
    """``import_capture`` commits the same way, ``capture.toml`` last: a kill leaves a folder it imports into again."""
    import wardjax as wj

    src = tmp_path / "src"
    src.mkdir()
    ramp = np.linspace(60, 200, 48 * 64 * 3).reshape(48, 64, 3).astype(np.uint8)
    for i in range(2):
        iio.imwrite(src / f"{i:02d}.png", ramp + 10 * i)
    (src / "camera_pos.txt").write_text("0 0 30\n8 0 28\n")
    (src / "light_power.txt").write_text("900\n")
    (src / "image_size.txt").write_text("12\n")
    with monkeypatch.context() as m:
        _stop_at(m, 1)
        with pytest.raises(_Killed):
            wj.capture.import_capture(src, tmp_path / "cap")
    cap = wj.capture.import_capture(src, tmp_path / "cap")
    assert len(cap.config.photos) == 2
    assert sorted(p.name for p in (tmp_path / "cap").iterdir()) == ["00.png", "01.png", "capture.toml"]


_KILL_SCRIPT = textwrap.dedent(
    """
    import os, signal, sys
    from pathlib import Path

    real, moved = os.replace, []

    def replace(src, dst):  # SIGKILL itself after the second move of the commit, params.json still to come
        if Path(src).parent != Path(dst).parent:
            if len(moved) == 2:
                os.kill(os.getpid(), signal.SIGKILL)
            moved.append(dst)
        return real(src, dst)

    os.replace = replace
    from wardjax.run import main

    main(["fit", sys.argv[1], "--out", sys.argv[2], "--quiet"])
    """
)


@pytest.mark.slow
def test_a_fit_killed_by_sigkill_during_its_final_move_reruns(tmp_path):
    from click.testing import CliRunner

    from wardjax.run import main

    cap, out = _phone(tmp_path / "caps" / "p"), tmp_path / "fits"
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[1])}
    proc = subprocess.run([sys.executable, "-c", _KILL_SCRIPT, str(cap), str(out)], env=env, timeout=600)
    assert proc.returncode == -signal.SIGKILL
    assert (out / "p" / COMMIT_JOURNAL).is_file() and not (out / "p" / "params.json").exists()
    res = CliRunner().invoke(main, ["fit", str(cap), "--out", str(out), "--quiet"])
    assert res.exit_code == 0, res.output
    doc = json.loads((out / "p" / "params.json").read_text())
    assert all((out / "p" / f).is_file() for f in doc["files"].values())
    assert not (out / "p" / COMMIT_JOURNAL).exists() and not list(out.glob(".p.*"))
