"""``wardjax simulate`` writes a folder the loader reads; ``wardjax fit`` refuses a missing path in one line."""

import json
import os
import subprocess
import sys

import numpy as np
import pytest
from click.testing import CliRunner

import wardjax as wj
from wardjax.run import main


def test_simulate_writes_a_loadable_capture(tmp_path):
    res = CliRunner().invoke(
        main,
        [
            "simulate",
            str(tmp_path / "c"),
            "--rho-d",
            "0.35",
            "0.35",
            "0.35",
            "--rho-s",
            "0.013",
            "--alpha-x",
            "0.041",
            "--alpha-y",
            "0.056",
            "--encoding",
            "linear",
            "--bit-depth",
            "16",
            "--format",
            "tif",
            "--size",
            "64",
            "48",
            "--seed",
            "4",
        ],
    )
    assert res.exit_code == 0, res.output + res.stderr
    cap = wj.load_capture(tmp_path / "c")
    assert cap.config.images.encoding == "linear" and cap.config.images.bit_depth == 16
    assert cap.config.fit.model == "anisotropic" and cap.lit.shape == (48, 64, 3)
    assert 0.5 < float(np.max(cap.lit)) < 1.0


def test_fit_missing_path_is_one_line(tmp_path):
    res = CliRunner().invoke(main, ["fit", str(tmp_path / "nope"), "--out", str(tmp_path / "o")])
    assert res.exit_code == 2
    assert res.stderr.strip().splitlines() == [f"error: {tmp_path / 'nope'}: no such capture folder"]


@pytest.mark.slow
def test_fit_keeps_compiled_kernels_between_runs(tmp_path):
    """A second ``wardjax fit`` process reads the compiled kernels the first wrote, with identical results."""
    cap = tmp_path / "c"
    wj.simulate_capture(
        wj.WardParams(rho_d=0.4, rho_s=0.03, alpha_x=0.08, alpha_y=0.08), out=cap, seed=2, image_size=(160, 120)
    )
    env = {k: v for k, v in os.environ.items() if k != "WARDJAX_NO_CACHE"}
    cache = tmp_path / "xla"
    outs = []
    for run in ("cold", "warm"):
        out = tmp_path / run
        cmd = [sys.executable, "-m", "wardjax.run._cli", "--cache-dir", str(cache), "fit", str(cap), "--out", str(out)]
        res = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=600)
        assert res.returncode == 0, res.stderr
        if run == "cold":
            cached = sorted(p.name for p in cache.iterdir())
            assert any("search_chunk" in n for n in cached), cached
        outs.append(json.loads((out / "c" / "params.json").read_text()))
    assert outs[0]["params"] == outs[1]["params"] and outs[0]["stderr"] == outs[1]["stderr"]
    # which standard errors each scanline fit reports (docs/engine.md), one kind per scanline
    scan = outs[0]["fit"]["diagnostics"]["scanlines"]
    assert set(scan["errors"]) == {"gauss_newton", "sandwich", "profile"}
    assert sum(scan["errors"].values()) == scan["count"]
