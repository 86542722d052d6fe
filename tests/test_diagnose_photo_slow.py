"""``wardjax diagnose`` end to end on photographs: multiview renders with a hidden effect or none, the real photos.

The renders (``benchmarks.photo_diagnose``) are wardjax's forward model of
nine flash photos of a flat one-material sample with sensor noise of known
σ, imported from the rectified layout; a radial gain the layout does not
describe multiplies the photos. Discovery, run blind with every candidate
(the radial gains, per-cluster lobes, normals), must name nothing on the
null and name the hidden gain otherwise — by its own name where the lamp is
far enough from the lens to tell the two apart. Each licensed real photo of
``tests/data/flash/`` goes through the CLI and leaves its report: an
unexplained gap, where it lives, and normals not tried on one photo.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from benchmarks.photo_diagnose import REAL, diagnose, multiview_render
from wardjax.effects import PHOTO_EFFECTS
from wardjax.run._cli import main

pytestmark = pytest.mark.slow

RADIAL = ("vignetting", "flash_falloff")


@pytest.mark.parametrize(
    ("kind", "offset"),
    [(None, 10.0), ("vignetting", 150.0), ("flash_falloff", 150.0), ("vignetting", 10.0)],
    ids=["null", "vignetting", "falloff", "vignetting, lamp at the lens"],
)
def test_01_multiview_render_hidden_effect_named_blind(tmp_path, kind, offset):
    rep = diagnose(multiview_render(tmp_path, kind, offset=offset))
    if kind is None:
        assert rep.found == [], rep.verdict()
        assert rep.verdict() == "nothing needed: the gap is within the noise"
        return
    assert rep.found[:1] == [kind] or (offset < 50 and rep.found[0] in RADIAL), rep.verdict()
    if offset > 50:
        assert rep.ambiguous == [] and rep.found == [kind]
    assert rep.within_noise and rep.gap[-1] < rep.gap[0]
    assert rep.steps[0].evidence.holdout is not None and rep.steps[0].evidence.holdout.passed


@pytest.mark.parametrize("name", sorted(p.name for p in REAL.iterdir() if (p / "capture.toml").is_file()))
def test_02_each_real_photo_diagnosed_from_the_cli(tmp_path, name):
    out = tmp_path / "diag"
    r = CliRunner().invoke(main, ["diagnose", str(REAL / name), "--out", str(out)])
    assert r.exit_code == 0, r.output
    doc = json.loads((out / "report.json").read_text())
    # one photo: normals are not tried, and no real photo comes within its noise — the verdict says so
    assert "normals" not in doc["found"] and doc["verdict"].startswith(("unexplained", "found"))
    assert "unexplained: the gap stays" in doc["verdict"] and "normals not tried (one photo" in doc["verdict"]
    assert (out / "residual.png").is_file() and doc["residual"]["pixel_rho_d_share"] == pytest.approx(1)
    assert doc["capture"] == name and set(doc["found"]) <= set(PHOTO_EFFECTS)
    assert len(doc["gap"]) == len(doc["found"]) + 1 and all(b <= a for a, b in zip(doc["gap"], doc["gap"][1:]))
    for no in doc["refused"]:  # a radial effect refused after the structure's refit: its gaps, not named
        assert no["gap_after"] >= no["gap_before"] and no["effect"] not in doc["found"], no
    assert f"{name}: {doc['verdict']}" in " ".join(r.output.split())  # the console wraps long lines
    labels = np.load(out / "labels.npy")
    rows, cols, block = doc["labels"]["grid"]
    assert labels.shape == (rows * block, cols * block)
    assert labels.max() < len(doc["lobes"])
    assert Path(out / "report.md").read_text().startswith(f"# Missing-effect discovery: {name}")
