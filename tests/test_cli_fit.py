"""``wardjax simulate`` writes a folder the loader reads; ``wardjax fit`` refuses a missing path in one line."""

import numpy as np
from click.testing import CliRunner

import wardjax as wj
from wardjax.cli import main


def test_simulate_writes_a_loadable_capture(tmp_path):
    res = CliRunner().invoke(main, ["simulate", str(tmp_path / "c"), "--rho-d", "0.35", "0.35", "0.35", "--rho-s", "0.013", "--alpha-x", "0.041", "--alpha-y", "0.056", "--encoding", "linear",
                                    "--bit-depth", "16", "--format", "tif", "--size", "64", "48", "--seed", "4"])
    assert res.exit_code == 0, res.output + res.stderr
    cap = wj.load_capture(tmp_path / "c")
    assert cap.config.images.encoding == "linear" and cap.config.images.bit_depth == 16
    assert cap.config.fit.model == "anisotropic" and cap.lit.shape == (48, 64, 3)
    assert 0.5 < float(np.max(cap.lit)) < 1.0


def test_fit_missing_path_is_one_line(tmp_path):
    res = CliRunner().invoke(main, ["fit", str(tmp_path / "nope"), "--out", str(tmp_path / "o")])
    assert res.exit_code == 2
    assert res.stderr.strip().splitlines() == [f"error: {tmp_path / 'nope'}: no such capture folder"]
