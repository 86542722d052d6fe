"""Soak: 200 simulated captures fitted in one process — no memory growth, no compiled-program growth, same results.

Runs ``benchmarks/soak.py`` in a process of its own (pytest's own memory and
the suite's type-checking import hook stay out of the figures). The captures
are our own renders (:func:`wardjax.simulate_capture`), three image sizes
cycled. The criteria:

* memory: the resident set size, sampled after every capture, grows by less
  than 5 MB per 100 captures over captures 20–200 (least-squares slope). One
  64 × 48 capture's lit and dark images as float32 are 74 KB: a fit that kept
  its capture's images alive would grow by 7.4 MB per 100 captures, one that
  kept its outputs by more;
* compiled programs: XLA compiles only at the first capture of each image size
  (its shape buckets, :mod:`wardjax._shapes`), nothing after;
* results: every sampled capture's ``params.json`` equals, value for value, the
  one a fresh process writes fitting that capture alone (``created`` aside).
"""

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.slow  # ~10 min on a loaded 2-core machine
def test_two_hundred_captures_in_one_process(tmp_path):
    out = tmp_path / "soak.json"
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    cmd = [sys.executable, "-m", "benchmarks.soak", "--n", "200", "--reference", "12", "--json", str(out)]
    subprocess.run(cmd, check=True, cwd=ROOT, env=env, timeout=3600)
    fig = json.loads(out.read_text())
    assert fig["captures"] == 200
    assert fig["rss_slope_mb_per_100"] < 5.0, fig["rss_slope_mb_per_100"]
    assert fig["rss_last_mb"] - fig["rss_at_warm_mb"] < 10.0, fig
    assert fig["captures_that_compiled"] == [0, 1, 2], fig["captures_that_compiled"]  # the first of each size
    assert fig["compiles_after_first_of_each_size"] == 0
    assert fig["reference_fitted_alone"] == 12 and fig["reference_identical"] == 12, fig
