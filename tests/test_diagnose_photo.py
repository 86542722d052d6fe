"""``diagnose`` on flash photographs: a hidden radial effect (or none) is found blind, by name, with its size.

Each test renders one flash photo with wardjax's own Ward code through the
observation model ``v = G · P · f_r · cos θi / d²`` — the geometry written
out here from the pinhole's definition, not taken from the loader — with ρd
constant over each block of 4 × 4 pixels (the paper's model), pixel noise
of known σ, and a gain ``G`` that the loader does not know of: none, the
lens's vignetting ``1 + a₁ r² + a₂ r⁴`` (``r`` the radius over the
half-diagonal) or the lamp's falloff ``cos^n ψ`` (``ψ`` from the lamp's axis,
parallel to the lens's). The lamp sits 80 mm beside the lens, so the two
radial effects are told apart. The discovery, run on the radial candidates,
must name what was hidden (nothing, vignetting, falloff), recover its
parameters within their σ, and bring the gap to the noise.
"""

from __future__ import annotations

import json

import jax
import numpy as np
import pytest
from click.testing import CliRunner

import wardjax as wj
from wardjax._files import encode_image, write_image
from wardjax.effects import discover_photo
from wardjax.run import photo_data
from wardjax.run._cli import main

RADIAL = ("vignetting", "flash_falloff")
SIZE, F_PX, DIST, LAMP_X, NOISE = 48, 45.0, 200.0, 80.0, 0.002


def _flash_capture(folder, *, vignetting=None, falloff=None, seed=0, block=4, rho_s=0.05, rho_d=(0.5, 0.3, 0.2)):
    """A flash photo of a flat Ward sample (ρd per block, α 0.15), with a hidden radial gain; returns the folder."""
    folder.mkdir(parents=True)
    rng = np.random.default_rng(seed)
    v, u = np.mgrid[0:SIZE, 0:SIZE].astype(float)
    c = (SIZE - 1) / 2
    pts = np.stack([(u - c) / F_PX * DIST, -(v - c) / F_PX * DIST, np.zeros_like(u)], -1)
    cam, lamp = np.array([0.0, 0.0, DIST]), np.array([LAMP_X, 0.0, DIST])
    wi = (lamp - pts) / np.linalg.norm(lamp - pts, axis=-1, keepdims=True)
    wo = (cam - pts) / np.linalg.norm(cam - pts, axis=-1, keepdims=True)
    d2 = np.sum((lamp - pts) ** 2, -1)
    tex = 1.0 + 0.3 * rng.uniform(-1, 1, (SIZE // block, SIZE // block, 1))
    rho_d = np.array(rho_d) * np.repeat(np.repeat(tex, block, 0), block, 1)
    with jax.enable_x64(True):
        p = wj.WardParams(rho_d=rho_d, rho_s=rho_s, alpha_x=0.15, alpha_y=0.15)
        f = np.asarray(wj.ward_brdf(p, wi, wo), np.float64)
    shade = f * (wi[..., 2] / d2)[..., None]
    power = 0.5 / float(shade.max())
    lin = power * shade
    r2 = ((u - c) ** 2 + (v - c) ** 2) / (2 * c * c)  # radius over the half-diagonal, squared
    if vignetting is not None:
        lin = lin * (1 + vignetting[0] * r2 + vignetting[1] * r2**2)[..., None]
    if falloff is not None:
        lin = lin * ((DIST / np.sqrt(d2)) ** falloff)[..., None]  # cos ψ from the lamp's axis (−z)
    lin = lin + NOISE * rng.standard_normal(lin.shape)
    write_image(folder / "lit.png", encode_image(lin, "linear", 16))
    (folder / "capture.toml").write_text(
        'method = "flash"\nencoding = "linear"\n[photo]\nfile = "lit.png"\n'
        f"[camera]\ndistance = {DIST}\nfocal_px = {F_PX}\n[lamp]\noffset = [{LAMP_X}, 0.0, 0.0]\n"
        f"[light]\npower = {power}\n[noise]\nread = {NOISE}\n[fit]\nblock = {block}\n"
    )
    return folder


def _within_noise(gap: float, dof: int) -> bool:
    return (gap - 1.0) * dof <= 2.0 * np.sqrt(2.0 * dof)


def test_01_null_names_nothing(tmp_path):
    cap = wj.load_capture(_flash_capture(tmp_path / "null"))
    rep = discover_photo(photo_data(cap), candidates=RADIAL, name="null")
    assert rep.found == [] and rep.steps == []
    assert rep.verdict() == "nothing needed: the gap is within the noise"
    assert _within_noise(rep.gap[0], rep.final_dof)
    # the paper's lobe comes back from the one photo
    assert rep.lobes[0]["alpha"] == pytest.approx(0.15, rel=0.03)
    assert rep.baseline["rho_s"] == pytest.approx(0.05, rel=0.05)


def test_02_hidden_vignetting_is_named_and_measured(tmp_path):
    cap = wj.load_capture(_flash_capture(tmp_path / "vig", vignetting=(-0.3, 0.05)))
    rep = discover_photo(photo_data(cap), candidates=RADIAL, name="vig")
    assert rep.found == ["vignetting"] and rep.ambiguous == []
    step = rep.steps[0]
    for k, truth in (("a1", -0.3), ("a2", 0.05)):
        assert abs(step.params[k] - truth) < 4 * step.stderr[k], (k, step.params, step.stderr)
    assert step.evidence.holdout is not None and step.evidence.holdout.passed
    assert rep.gap[0] > 1.1 and _within_noise(rep.gap[1], rep.final_dof)
    assert rep.verdict() == "found vignetting; the gap is within the noise"
    # the report: the named effect, the gap before and after, the label image over the fitted pixels
    paths = rep.save(tmp_path / "out")
    doc = json.loads(paths["report.json"].read_text())
    assert doc["found"] == ["vignetting"] and doc["gap"] == pytest.approx(rep.gap)
    assert np.load(paths["labels.npy"]).shape == (SIZE, SIZE)
    assert "| 1 | + vignetting |" in paths["report.md"].read_text()


def test_03_hidden_flash_falloff_is_named_and_measured(tmp_path):
    cap = wj.load_capture(_flash_capture(tmp_path / "fall", falloff=3.0, seed=1))
    rep = discover_photo(photo_data(cap), candidates=RADIAL, name="fall")
    assert rep.found == ["flash_falloff"] and rep.ambiguous == []
    step = rep.steps[0]
    assert abs(step.params["n"] - 3.0) < 4 * step.stderr["n"], (step.params, step.stderr)
    assert step.gap_after < step.gap_before and _within_noise(rep.gap[-1], rep.final_dof)
    assert rep.lobes[0]["alpha"] == pytest.approx(0.15, rel=0.03)  # the lobe no longer stands in for the falloff


def test_04_cli_refuses_a_block_larger_than_the_photo_and_writes_nothing(tmp_path):
    folder = _flash_capture(tmp_path / "cap")
    toml = folder / "capture.toml"
    toml.write_text(toml.read_text().replace("block = 4", "block = 64"))
    r = CliRunner().invoke(main, ["diagnose", str(folder), "--out", str(tmp_path / "out")])
    assert r.exit_code == 2
    errors = [x for x in r.output.splitlines() if x.startswith("error:")]
    assert errors == [f"error: capture.toml: fit.block: 64 is larger than the {SIZE}×{SIZE} pixels fitted"]
    assert not (tmp_path / "out").exists()
