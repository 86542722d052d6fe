"""Smartphone capture folders: load, validate, fit through ``wardjax fit``, one clear error when bad."""

import json

import imageio.v3 as iio
import numpy as np
import pytest
import tomli_w
from click.testing import CliRunner

import wardjax as wj
from wardjax.capture import CaptureError, load_capture
from wardjax.run import main


def _write(folder, *, toml=None, photo=None, **edits):
    folder.mkdir(parents=True, exist_ok=True)
    if photo is None:
        # A neutral, NCS-white-like surface: sRGB code 237 ≈ ρd 0.85 with γ 2.2.
        photo = np.full((96, 128, 3), 237, np.uint8)
    iio.imwrite(folder / "photo.png", photo)
    cfg = {
        "method": "smartphone",
        "name": "ncs-white-gloss50",
        "photo": {"file": "photo.png", "region": [20, 80, 30, 100], "decoding": "gamma2.2"},
        # Table 1b: NCS white, gloss 50 → threshold 11 PPB (mean of three observers).
        "thresholds": {"ppb": [10, 11, 12]},
        "specular": {"n": 1.5},
    }
    for key, value in edits.items():
        section, _, field = key.partition("__")
        if field:
            if value is None:
                cfg[section].pop(field, None)
            else:
                cfg[section][field] = value
        elif value is None:
            cfg.pop(section, None)
        else:
            cfg[section] = value
    (folder / "capture.toml").write_text(toml if toml is not None else tomli_w.dumps(cfg))
    return folder


def test_smartphone_capture_fits_through_the_cli(tmp_path):
    src = _write(tmp_path / "caps" / "white")
    cap = load_capture(src)
    assert cap.method == "smartphone" and cap.photo.shape == (96, 128, 3)
    out = tmp_path / "out"
    res = CliRunner().invoke(main, ["fit", str(tmp_path / "caps"), "--out", str(out), "--quiet"])
    assert res.exit_code == 0, res.output + res.stderr
    doc = json.loads((out / "white" / "params.json").read_text())
    assert doc["schema"] == "wardjax.params/1" and doc["method"] == "smartphone"
    # ρd from the photo, through the library's colour path on the same region.
    expected = wj.diffuse_from_srgb(cap.photo, (20, 80, 30, 100), decoding="gamma2.2")
    np.testing.assert_allclose(doc["params"]["rho_d"], expected, rtol=1e-9)
    assert doc["params"]["rho_d"][1] == pytest.approx(0.85, abs=0.02)
    # ρs from Fresnel for n = 1.5 (the paper's 0.050).
    assert doc["params"]["rho_s"] == pytest.approx(0.050, abs=5e-4)
    # Table 1c gives α = 0.020 for this surface: inside the posterior's 95 % interval.
    lo, hi = doc["fit"]["posterior"]["alpha_interval_95"]
    assert lo < 0.020 < hi
    assert doc["params"]["alpha_x"] == doc["params"]["alpha_y"] == pytest.approx(0.020, rel=0.25)
    assert doc["inputs"].keys() == {"capture.toml", "photo.png"}
    rad = (out / "white" / "material.rad").read_text()
    assert "plastic" in rad
    # Rerunning skips the finished capture and keeps its result.
    res2 = CliRunner().invoke(main, ["fit", str(tmp_path / "caps"), "--out", str(out), "--quiet"])
    assert res2.exit_code == 0
    assert json.loads((out / "white" / "params.json").read_text()) == doc


def test_published_mean_form(tmp_path):
    src = _write(tmp_path / "c", thresholds={"ppb_mean": 11.0, "n_observers": 3})
    cap = load_capture(src)
    assert cap.config.thresholds.ppb_mean == 11.0


BAD = {
    "non_integer_ppb": (dict(thresholds={"ppb": [10, 11.5, 12]}), "capture.toml", "thresholds.ppb"),
    "negative_ppb": (dict(thresholds={"ppb": [-3, 11]}), "capture.toml", "thresholds.ppb"),
    "both_forms": (dict(thresholds={"ppb": [11], "ppb_mean": 11.0, "n_observers": 1}), "capture.toml", "either ppb"),
    "mean_without_count": (dict(thresholds={"ppb_mean": 11.0}), "capture.toml", "needs n_observers"),
    "empty_region": (dict(photo__region=[20, 20, 30, 100]), "capture.toml", "photo.region"),
    "region_outside": (dict(photo__region=[20, 80, 30, 500]), "capture.toml", "photo.region"),
    "missing_photo_file": (dict(photo__file="nope.jpg"), "capture.toml", "photo.file"),
    "unknown_display": (dict(setup={"display": "galaxy99"}), "capture.toml", "setup.display"),
    "n_outside_range": (dict(specular={"n": 1.9, "n_range": [1.4, 1.7]}), "capture.toml", "specular.n"),
    "extra_field": (dict(photo__gamma=2.2), "capture.toml", "photo.gamma: unknown field"),
}


@pytest.mark.parametrize("case", sorted(BAD))
def test_bad_smartphone_capture_is_one_clear_error(tmp_path, case):
    edits, file, text = BAD[case]
    src = _write(tmp_path / case, **edits)
    with pytest.raises(CaptureError) as info:
        load_capture(src)
    msg = str(info.value)
    assert "\n" not in msg and msg.startswith(f"{file}: ") and text in msg, msg


def test_grey_photo_is_refused(tmp_path):
    src = _write(tmp_path / "grey")
    iio.imwrite(src / "photo.png", np.full((96, 128), 200, np.uint8))
    # A grey-scale file is read as RGB by repetition; a corrupt one is one clear error.
    (src / "photo.png").write_bytes(b"not a png")
    with pytest.raises(CaptureError, match=r"photo.png: cannot be read as an image"):
        load_capture(src)
