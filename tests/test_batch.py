"""Batches: bad captures do not sink good ones; a killed batch, rerun, ends as if never interrupted."""

import csv
import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import jax
import pytest

import wardjax as wj
from wardjax.run import find_captures, run_batch

DESK = wj.WardParams(rho_d=(0.676,) * 3, rho_s=0.039, alpha_x=0.137, alpha_y=0.150)
NAMES = ("a_desk", "b_desk")


@pytest.fixture(scope="module")
def captures(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("batch") / "captures"
    for i, name in enumerate(NAMES):
        wj.simulate_capture(DESK, root / name, seed=i, image_size=(160, 120), texture="wood")
    return root


def _tree(folder: Path) -> dict[str, bytes]:
    out = {}
    for f in sorted(folder.rglob("*")):
        if f.is_file():
            data = f.read_bytes()
            if f.name == "params.json":
                doc = json.loads(data)
                assert isinstance(doc.pop("created"), str)
                data = json.dumps(doc, sort_keys=True).encode()
            out[str(f.relative_to(folder))] = data
    return out


def test_bad_captures_do_not_sink_the_batch(captures, tmp_path):
    root = tmp_path / "mixed"
    shutil.copytree(captures / "a_desk", root / "good")
    shutil.copytree(captures / "b_desk", root / "nan_lamp")
    p = root / "nan_lamp" / "capture.toml"
    p.write_text(p.read_text().replace("lamp = [0.0, 300.0", "lamp = [0.0, nan"))
    (root / "empty").mkdir()
    items = run_batch([root], tmp_path / "out")
    assert [(it.name, it.status) for it in items] == [("empty", "error"), ("good", "ok"), ("nan_lamp", "error")]
    assert items[0].error.startswith("capture.toml: missing")
    assert items[2].error == "capture.toml: rig.lamp[1]: Input should be a finite number, got nan"
    out = tmp_path / "out"
    assert {f.name for f in (out / "good").iterdir()} >= {
        "params.json",
        "rho_d.tif",
        "rho_d.png",
        "scanline.png",
        "material.rad",
        "scanlines.csv",
    }
    assert not (out / "nan_lamp").exists() and not (out / "empty").exists()
    with open(out / "summary.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert [r["status"] for r in rows] == ["error", "ok", "error"]
    assert rows[2]["error"] == items[2].error and rows[1]["rho_s"] != ""
    # fit quality named by what it is: a unit-weight scanline fit has an RMS residual (sr⁻¹), no χ²/dof
    res = json.loads((out / "good" / "params.json").read_text())["fit"]["diagnostics"]["residuals"]
    assert "reduced_chi2" not in rows[1] and rows[1]["weighted_chi2_per_dof"] == ""
    assert float(rows[1]["residual_rms_sr-1"]) == pytest.approx(res["rms"], rel=1e-5)
    assert float(rows[1]["residual_rms_relative"]) == pytest.approx(res["relative_rms"], rel=1e-5)


def test_find_captures(captures, tmp_path):
    assert [p.name for p in find_captures([captures])] == list(NAMES)
    assert find_captures([captures / "b_desk"]) == [captures / "b_desk"]
    (tmp_path / "lonely").mkdir()
    assert find_captures([tmp_path / "lonely"]) == [tmp_path / "lonely"]


@pytest.mark.slow
def test_killed_batch_reruns_to_the_uninterrupted_result(captures, tmp_path):
    # The killed run is a separate process with JAX's default settings; run the
    # in-process ones alike (tests/conftest.py raises on rank promotion, which
    # wardjax.texture.analyze_texture, behind texture.json, still relies on).
    with jax.numpy_rank_promotion("allow"):
        _killed_batch_reruns(captures, tmp_path)


def _killed_batch_reruns(captures, tmp_path):
    ref = tmp_path / "ref"
    run_batch([captures], ref)
    killed = tmp_path / "killed"
    cmd = [
        sys.executable,
        "-c",
        "from wardjax.run import main; main()",
        "fit",
        str(captures),
        "--out",
        str(killed),
        "--quiet",
    ]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 240
        while not (killed / NAMES[0] / "params.json").exists():
            assert proc.poll() is None, "the batch ended before it could be killed"
            assert time.monotonic() < deadline
            time.sleep(0.02)
        os.kill(proc.pid, signal.SIGKILL)
    finally:
        proc.wait()
    done = [n for n in NAMES if (killed / n / "params.json").exists()]
    assert NAMES[0] in done and len(done) < len(NAMES), done
    # What a kill in the middle of a write leaves behind: a temporary file.
    (killed / NAMES[-1]).mkdir(exist_ok=True)
    (killed / NAMES[-1] / ".rho_d.x1y2.tif.tmp").write_bytes(b"half a file")
    first = (killed / NAMES[0] / "params.json").stat().st_mtime_ns
    items = run_batch([captures], killed)
    assert [it.skipped for it in items][0] is True
    assert (killed / NAMES[0] / "params.json").stat().st_mtime_ns == first
    tree = _tree(killed)
    assert tree == _tree(ref)
    assert f"{NAMES[0]}/texture.json" in tree and "summary.csv" in tree


def test_rerun_skips_unless_forced_and_notices_changed_inputs(captures, tmp_path):
    out = tmp_path / "out"
    run_batch([captures / "a_desk"], out)
    pj = out / "a_desk" / "params.json"
    t0 = pj.stat().st_mtime_ns
    assert run_batch([captures / "a_desk"], out)[0].skipped
    assert pj.stat().st_mtime_ns == t0
    assert not run_batch([captures / "a_desk"], out, force=True)[0].skipped
    # A changed input makes the capture unfinished again.
    changed = tmp_path / "changed"
    shutil.copytree(captures / "a_desk", changed / "a_desk")
    toml = changed / "a_desk" / "capture.toml"
    toml.write_text(toml.read_text().replace("noise_floor = 0.002", "noise_floor = 0.003"))
    assert not run_batch([changed / "a_desk"], out)[0].skipped
    assert json.loads(pj.read_text())["inputs"]["capture.toml"] != json.loads(
        (tmp_path / "out" / "a_desk" / "params.json").read_text()
    ).get("never", "x")
