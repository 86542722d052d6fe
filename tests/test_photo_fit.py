"""Photograph captures fitted end to end: library and CLI, with a photo held out.

A multiview capture rendered by wardjax's own Ward code (known ρd, ρs, α, and
pixel noise of known σ) is imported from the rectified layout, fitted on all
photos but one, and the held-out photo predicted: the lobe must come back
within its tolerance and the held-out error must sit at the noise (a fit that
only interpolated its own photos would not predict a new view). The real
flash photos of ``tests/data/flash/`` go through ``wardjax fit`` and leave
their report.
"""

from __future__ import annotations

import csv
import json
import shutil
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from test_photo_capture import CAMS, LIGHTS, TRUTH, _grid, _render

import wardjax as wj
from wardjax._files import encode_image, read_image, write_image
from wardjax.run._cli import main
from wardjax.run._heldout_figure import heldout_figure
from wardjax.run._photo_verdict import physical_verdict

DATA = Path(__file__).parent / "data" / "flash"
NOISE = 0.004


def _noisy_layout(folder: Path, rng, h=24, w=32) -> None:
    folder.mkdir(parents=True)
    pts = _grid(h, w, 120.0)
    for k, (c, lt) in enumerate(zip(CAMS, LIGHTS)):
        v, _, _ = _render(pts, np.asarray(c) * 10, np.asarray(lt) * 10, 900.0 * 100)
        write_image(folder / f"{k}.png", encode_image(v + rng.normal(0, NOISE, v.shape), "linear", 16))
    np.savetxt(folder / "camera_pos.txt", np.asarray(CAMS))
    np.savetxt(folder / "light_pos.txt", np.asarray(LIGHTS))
    (folder / "light_power.txt").write_text("900\n")
    (folder / "image_size.txt").write_text("12\n")


@pytest.fixture
def multiview(tmp_path, rng):
    _noisy_layout(tmp_path / "src", rng)
    cap = wj.import_capture(tmp_path / "src", tmp_path / "cap", encoding="linear")
    with open(tmp_path / "cap" / "capture.toml", "a") as fh:  # the noise the photos were drawn with
        fh.write(f"\n[noise]\nread = {NOISE}\n")
    del cap
    return tmp_path / "cap"


def test_01_multiview_lobe_and_held_out_photo(multiview):
    cap = wj.load_capture(multiview)
    out = wj.fit_capture(cap, hold_out=0)
    assert isinstance(out, wj.PhotoFit) and out.photos_fitted == (1, 2, 3)
    res = out.result
    assert float(res.rho_s[0]) == pytest.approx(TRUTH.rho_s, rel=0.05)
    assert float(res.alpha_x[0]) == pytest.approx(TRUTH.alpha_x, rel=0.05)
    ok = np.isfinite(out.rho_d[..., 0])
    assert ok.mean() > 0.9
    z = (out.rho_d[ok] - np.asarray(TRUTH.rho_d)) / out.rho_d_stderr[ok]
    assert 0.7 < np.std(z) < 1.4  # the per-pixel σ of ρd is the spread of its errors
    ho = out.held_out
    assert ho is not None and ho.k == 0 and ho.pixels > 0.9 * 24 * 32
    # the new view predicted to the noise: its own noise plus that of ρd from the other 3 photos, √(1 + 1/3) = 1.15
    assert ho.rmse_linear / ho.rmse_noise == pytest.approx(np.sqrt(1 + 1 / 3), abs=0.1)
    assert ho.psnr == pytest.approx(20 * np.log10(1 / ho.rmse_display))
    # heldout.png: each panel has pixel axes, a title and a colour bar with its unit; photo and prediction on one scale
    fig = heldout_figure(ho)
    panels = [ax for ax in fig.axes if ax.get_images()]
    assert len(panels) == 3 and len(fig.axes) == 6  # three images, three colour bars
    for ax in panels:
        assert ax.get_xlabel() == "x (pixels)" and ax.get_ylabel() == "y (pixels)" and ax.get_title()
    units = [ax.get_ylabel() for ax in fig.axes if not ax.get_images()]
    assert units[0] == units[1] == "linear value (mean of channels, full scale 1)" and "noise σ" in units[2]
    (photo,), (pred,), (resid,) = (ax.get_images() for ax in panels)
    assert photo.get_clim() == pred.get_clim() and -resid.get_clim()[0] == resid.get_clim()[1] >= 3
    # the residual panel in noise σ: about unit spread where the prediction is right
    assert 0.8 < np.nanstd(resid.get_array()) < 1.5


def test_02_cli_fit_hold_out_writes_the_panel(multiview, tmp_path):
    r = CliRunner().invoke(main, ["fit", str(multiview), "--out", str(tmp_path / "fits"), "--hold-out", "2"])
    assert r.exit_code == 0, r.output
    assert "held-out photo 2 (2.png): RMSE" in r.output and "PSNR" in r.output
    d = tmp_path / "fits" / "cap"
    doc = json.loads((d / "params.json").read_text())
    assert doc["method"] == "multiview" and doc["fit"]["held_out"]["photo"] == 2
    assert doc["fit"]["photos_fitted"] == [0, 1, 3]
    # weights 1/σ² from the noise model: summary.csv gives a χ²/dof, about 1 for data made with that noise
    with open(tmp_path / "fits" / "summary.csv", newline="") as fh:
        row = next(csv.DictReader(fh))
    assert doc["fit"]["weighted"] is True and row["residual_rms_sr-1"] == ""
    assert float(row["weighted_chi2_per_dof"]) == pytest.approx(doc["fit"]["reduced_chi2"], rel=1e-5)
    assert 0.8 < float(row["weighted_chi2_per_dof"]) < 1.25
    panel = read_image(d / "heldout.png")
    assert panel.ndim == 3 and panel.shape[1] > 2 * panel.shape[0]  # photo | prediction | residual, side by side
    assert read_image(d / "rho_d_sigma.tif", rgb=False).shape == (24, 32, 3)
    assert "Held-out photo 2" in (d / "report.md").read_text()


@pytest.mark.parametrize(
    ("edit", "args", "line"),
    [
        (
            None,
            ["--hold-out", "0"],
            "towel: capture.toml: photos: --hold-out needs two photos or more; green_towel has 1",
        ),
        (
            lambda t: t.replace('file = "point.jpg"', 'file = "point.jpg"\niso = 400'),
            [],
            "towel: capture.toml: photo.iso: 400 contradicts the EXIF of point.jpg (ISOSpeedRatings = 100); "
            "correct or remove the field",
        ),
        (
            lambda t: t + '\nnormals = "height_field"\n',  # [fit] is the file's last table
            [],
            "towel: capture.toml: fit.normals: 'height_field' needs two photos or more fitted; green_towel has 1: "
            "a normal per pixel and ρd varying across pixels make the same picture in one",
        ),
    ],
    ids=["hold-out of one photo", "EXIF contradicts", "normals from one photo"],
)
def test_03_cli_bad_photo_capture_is_one_line_and_writes_nothing(tmp_path, edit, args, line):
    src = tmp_path / "towel"
    shutil.copytree(DATA / "green_towel", src)
    if edit is not None:
        (src / "capture.toml").write_text(edit((src / "capture.toml").read_text()))
    r = CliRunner().invoke(main, ["fit", str(src), "--out", str(tmp_path / "fits"), *args])
    assert r.exit_code == 2
    assert [x for x in r.output.splitlines() if x.startswith("error:")] == [f"error: {line}"]
    assert not (tmp_path / "fits" / "towel").exists()


# The towel's fit is no material (docs/photographs.md): a diffuse cloth whose lobe stands in for the vignetting
# and the flash's falloff, with a mean ρd below 0 in two channels. The others are materials.
NOT_PHYSICAL = {"green_towel"}


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(p.name for p in DATA.iterdir() if (p / "capture.toml").is_file()))
def test_04_each_real_photo_fitted_from_the_cli(tmp_path, name):
    r = CliRunner().invoke(main, ["fit", str(DATA / name), "--out", str(tmp_path)])
    assert r.exit_code == 0, r.output  # a verdict on the capture is no failure of the run
    doc = json.loads((tmp_path / name / "params.json").read_text())
    assert doc["method"] == "flash" and doc["fit"]["dof"] > 0
    report = (tmp_path / name / "report.md").read_text()
    assert report.startswith(f"# {name} (flash, 1 photo)") and "| lobe | ρs | αx | αy |" in report
    assert np.load(tmp_path / name / "maps.npz")["rho_d"].shape[2] == 3  # the estimate's maps, kept either way
    if name in NOT_PHYSICAL:
        # one line naming the capture, its photo, the parameters out of range with value ± σ; the report says the
        # same; the material (ρd texture, params.json's radiance block) is not written with impossible values
        (line,) = [x for x in r.output.splitlines() if "not a physical material" in x]
        assert line == doc["fit"]["verdict"] and line in report
        assert line.startswith(f"{name} (point.jpg): not a physical material: α = 1.28")
        assert "mean ρd R = -0.12 ± " in line and "mean ρd B = -0.25" in line and line.endswith("no material exported")
        assert doc["fit"]["status"] == "not_physical" and doc["params"]["rho_d"][0] < 0  # the estimate, as measured
        assert doc["radiance"]["params"]["rho_s"] is None and "not a physical material" in doc["radiance"]["status"]
        assert not (tmp_path / name / "rho_d.tif").exists() and "rho_d" not in doc["files"]
        return
    assert doc["fit"]["status"] == "converged" and doc["fit"]["verdict"] is None
    assert not [x for x in r.output.splitlines() if "not a physical material" in x]
    assert all(0 <= v <= 1 for v in doc["radiance"]["params"]["rho_d"])
    rho = read_image(tmp_path / name / "rho_d.tif", rgb=False)
    assert rho.shape[2] == 3 and np.isfinite(rho).mean() > 0.8


def _lobe(rho_s, alpha, err=0.001):
    return {
        "rho_s": [rho_s],
        "alpha_x": [alpha],
        "alpha_y": [alpha],
        **{k: [err] for k in ("rho_s_err", "alpha_x_err", "alpha_y_err")},
    }


def test_05_a_fit_out_of_the_physical_range_is_a_verdict_within_noise_a_bound():
    rd, err = np.array([0.5, 0.3, 0.2]), np.full(3, 0.001)
    v = physical_verdict(rd, err, _lobe(0.05, 0.15))
    assert v.physical and not v.notes and v.material is not None
    np.testing.assert_array_equal(v.material.rho_d, rd)
    # 2 σ below 0: noise; the material takes the bound, and a note says so
    v = physical_verdict(np.array([0.5, 0.3, -0.002]), err, _lobe(0.05, 0.15))
    assert v.physical and v.material is not None and float(v.material.rho_d[2]) == 0.0
    assert v.notes == ("mean ρd B = -0.002 ± 0.001 lies within 3 σ of 0: the material takes 0",)
    # 5 σ below 0: a verdict naming the parameter with its value and σ, and nothing to export
    v = physical_verdict(np.array([0.5, 0.3, -0.005]), err, _lobe(1.2, 0.15))
    assert not v.physical and v.material is None
    assert v.why == "ρs = 1.2 ± 0.001 > 1; mean ρd B = -0.005 ± 0.001 < 0"
    assert v.line("towel", ["a.jpg"]).startswith("towel (a.jpg): not a physical material: ρs = 1.2")
    # the σ hold only if the model fits: χ²/dof = 4 doubles them, and 5 σ become 2.5
    v = physical_verdict(np.array([0.5, 0.3, -0.005]), err, _lobe(0.05, 0.15), chi2_per_dof=4.0)
    assert v.physical and v.notes[0].startswith("mean ρd B = -0.005 ± 0.002 lies within 3 σ")
    v = physical_verdict(rd, err, _lobe(0.05, 1.5))
    assert not v.physical and v.why == "α = 1.5 ± 0.001 > 1"
    # a ρd map below 0 beyond noise in more than a tenth of its values
    m = np.broadcast_to(rd, (10, 10, 3)).copy()
    m[:4, :, 0] = -0.1  # 40 of 300 values
    v = physical_verdict(rd, err, _lobe(0.05, 0.15), rho_d_map=m, rho_d_map_err=np.full_like(m, 0.01))
    assert not v.physical and v.why == "ρd < 0 beyond 3 σ in 13 % of the pixel values"
