"""``diagnose`` on photographs: a lobe no material has, what one photo cannot tell, where the residual lives.

The flash photos are those of ``test_diagnose_photo`` (wardjax's own Ward
code, ρd per block, noise of known σ, the lamp 80 mm from the lens):

* a matte sample (ρs = 0) under strong vignetting: the paper's model fits
  the vignetting with a lobe whose ρs breaks energy conservation; discovery
  must say so, try the radial effects first, name the vignetting and bring
  the gap to the noise with a lobe that is no lobe (ρs near 0);
* one photo: a normal per block is not tried, and the report says why;
* the radial gains fitted on a held structure (:mod:`wardjax.effects._photo_held`)
  reproduce the χ² of the fit they hold, and read a Δχ² no larger than a
  full refit gives (the evidence is conservative);
* where the residual lives: shares that add up, and with one photo a ρd per
  pixel absorbing all of it.
"""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest
from test_diagnose_photo import _flash_capture

import wardjax as wj
from wardjax.effects import discover_photo
from wardjax.effects._photo_checks import residual_where, unphysical
from wardjax.effects._photo_held import HeldStructure, fit_gains_held
from wardjax.effects._photo_model import fit_shared
from wardjax.effects._photo_states import PhotoState, fit_state
from wardjax.run import photo_data

RADIAL = ("vignetting", "flash_falloff")


@pytest.mark.slow  # compiles and runs a whole discovery (about 30 s); test_05 checks the rules fast
def test_01_a_lobe_no_material_has_is_named_and_the_radial_effect_found(tmp_path):
    folder = _flash_capture(tmp_path / "matte", vignetting=(-0.8, 0.1), seed=2, rho_s=0.0, rho_d=(0.75, 0.7, 0.6))
    rep = discover_photo(photo_data(wj.load_capture(folder)), candidates=RADIAL, name="matte")
    assert rep.baseline["rho_s"] > 1  # the paper's model: the vignetting taken for a broad lobe
    (u,) = rep.unphysical
    assert u["step"] == 0 and "exceeds 1 (energy conservation)" in u["why"]
    assert rep.found == ["vignetting"] and rep.within_noise
    assert rep.lobes[0]["rho_s"] < 0.05  # the matte sample has no lobe
    assert rep.verdict().startswith("found vignetting; the gap is within the noise; the paper's model has a lobe")
    assert "## A lobe no material has" in rep.to_markdown()


def test_02_one_photo_does_not_try_normals_and_says_why(tmp_path):
    data = photo_data(wj.load_capture(_flash_capture(tmp_path / "null")))
    assert data.n_photos == 1
    rep = discover_photo(data, candidates=("vignetting", "normals"), name="null")
    assert rep.found == [] and rep.settings["candidates"] == ["vignetting"]
    assert list(rep.not_identifiable) == ["normals"] and "one photo" in rep.not_identifiable["normals"]
    assert rep.verdict() == (
        "nothing needed: the gap is within the noise; normals not tried "
        "(one photo: a normal per block and ρd varying inside the block make the same picture)"
    )
    paths = rep.save(tmp_path / "out")
    doc = json.loads(paths["report.json"].read_text())
    assert doc["not_identifiable"] == rep.not_identifiable and doc["residual"]["map"] == "residual.png"
    assert paths["residual.png"].is_file() and "## Not identifiable" in paths["report.md"].read_text()
    assert doc["refused"] == [] and "## Refused" not in paths["report.md"].read_text()
    # a radial effect refused after the structure's refit is recorded as the accepted ones are
    no = {"step": 1, "effect": "vignetting", "why": "refitted with the structure it does not lower the gap (χ²/dof)"}
    no |= {"gap_before": 1.31, "gap_after": 1.32, "delta_bic_held": 40.5}
    no |= {"params": {"a1": -0.2, "a2": 0.01}, "stderr": {"a1": 0.01, "a2": 0.02}}
    paths = dataclasses.replace(rep, refused=[no]).save(tmp_path / "refused")
    assert json.loads(paths["report.json"].read_text())["refused"] == [no]
    md = paths["report.md"].read_text()
    assert "## Refused: no lower gap once the structure is refitted (not named)" in md
    assert "- step 1: vignetting (a1 = -0.2 ± 0.01, a2 = 0.01 ± 0.02; ΔBIC 40.5 on the held structure): " in md
    assert "gap 1.31 → 1.32 refitted" in md


@pytest.fixture(scope="module")
def vignetted(tmp_path_factory):
    folder = _flash_capture(tmp_path_factory.mktemp("vig") / "cap", vignetting=(-0.3, 0.05))
    return photo_data(wj.load_capture(folder))


@pytest.mark.slow  # two wj.fit_pixels fits, compiled in the worker (about 50 s)
def test_03_gains_on_a_held_structure_are_conservative(vignetted):
    data = vignetted
    cur = fit_state(PhotoState(), data, pixels=True)  # the shared lobe through wj.fit_pixels: a structure to hold
    held = HeldStructure.of(cur.pixel, data)
    same = fit_gains_held((), data, held, cur.shared)
    assert same.chi2 == pytest.approx(cur.chi2, rel=1e-6)  # the held structure is the fit it came from
    new = fit_gains_held(("vignetting",), data, held, cur.shared)
    full = fit_state(PhotoState(radial=("vignetting",)), data, pixels=True)
    assert 0 < same.chi2 - new.chi2 <= (cur.chi2 - full.chi2) * (1 + 1e-6)
    a1, a2 = new.effects["vignetting"]
    assert a1 < -0.1 and abs(a2) < 1  # the vignetting's sign read on the held structure


def test_04_where_the_residual_lives(vignetted):
    state = PhotoState()
    fit = fit_state(state, vignetted)
    where = residual_where(fit, state, vignetted)
    assert sum(b["chi2_share"] for b in where["bands"]) == pytest.approx(1)
    assert sum(b["obs_share"] for b in where["bands"]) == pytest.approx(1)
    assert where["pixel_rho_d_share"] == pytest.approx(1)  # one photo: each pixel's one value fitted exactly
    rows, cols, _ = vignetted.grid
    n = np.sum(vignetted.w > 0, (1, 2)).reshape(rows, cols)
    assert where["chi2_map"].shape == (rows, cols)
    assert np.sum(where["chi2_map"] * n) == pytest.approx(fit.chi2, rel=1e-9)


def test_05_the_physical_rules_on_a_fitted_lobe(vignetted):
    state = PhotoState()
    fit = fit_state(state, vignetted)
    assert unphysical(fit, state, vignetted) is None  # the renders' lobe: ρs 0.05, α 0.15

    def with_lobe(rho_s, alpha):
        x = np.array([np.log(alpha)])
        return fit._replace(shared=fit.shared._replace(rho_s=rho_s, alpha=alpha, x=x))

    assert "exceeds 1 (energy conservation)" in unphysical(with_lobe(1.2, 0.15), state, vignetted)
    assert unphysical(with_lobe(0.05, 1.5), state, vignetted) == "the lobe: α = 1.5 outside (0.00101, 1]"


@pytest.mark.slow  # a per-cluster fit through wj.fit_pixels, compiled in the worker (about 40 s)
def test_06_a_radial_step_on_a_model_with_structure_is_scored_held_then_refitted(vignetted):
    from wardjax.effects._photo_discover import _step

    state = PhotoState(structural=("varying_specular",))
    cur = fit_state(state, vignetted)
    lines = []
    found = _step(state, cur, ["vignetting"], False, vignetted, np.log(vignetted.n_obs), 0.01, 1, lines.append)
    assert found.chosen is not None and found.chosen.effect == "vignetting" and found.fit is not None
    assert "step 1: vignetting refitted with the structure" in lines
    assert found.fit.pixel is not None and found.fit.chi2 < cur.chi2 - found.chosen.delta_chi2 / 2
    a1, _ = found.fit.shared.effects["vignetting"]
    assert a1 < -0.1  # the hidden 1 − 0.3 r² + 0.05 r⁴: darker at the edge
    # the renders hold one material: its lobes per cluster stood in for the vignetting, and with the gain in the
    # model one lobe is left (the gains refitted on it, not kept as fitted for the three it had)
    assert cur.pixel.evidence["clusters"]["n_clusters"] > 1
    assert found.fit.pixel.evidence["clusters"]["n_clusters"] == 1
    assert found.fit.gap < 1 + 3 * np.sqrt(2 / found.fit.dof)  # the noise: ρd per block, one lobe, the gain


@pytest.mark.slow  # two wj.fit_pixels fits with normals and clusters, compiled in the worker (about 60 s)
def test_07_lobes_per_cluster_are_scored_at_the_current_normals(vignetted):
    from wardjax.effects._photo_discover import _normals_held

    state = PhotoState(structural=("normals",))
    cur = fit_state(state, vignetted)
    held = _normals_held("varying_specular", state, cur)
    assert held is cur and _normals_held("vignetting", state, cur) is None
    new = fit_state(state.plus("varying_specular"), vignetted, start=cur.shared, normals_from=held)
    np.testing.assert_allclose(new.pixel.normals, cur.pixel.normals, atol=1e-12)  # held, not refitted
    kept = cur.pixel.evidence["normals"]["n_pixels"]
    assert new.dof == new.pixel.dof - 2 * kept  # the held normals still counted as parameters
    assert new.chi2 <= cur.chi2 * (1 + 1e-3)  # lobes per cluster at the same normals fit no worse


@pytest.mark.slow  # a 16² × 9 bumpy render, two normal-map fits and their hold-out (about 3 min)
def test_08_a_bumpy_multiview_sample_takes_its_normals_on_one_height_field(tmp_path):
    from benchmarks.photo_diagnose import NOISE_GAIN, NOISE_READ
    from wardjax.render import flash_views
    from wardjax.simulate import FlashNoise, simulate_flash_views

    one = ((0.4, 0.3, 0.2), (0.4, 0.3, 0.2))  # one material, bumps of slope up to ±0.15
    scene = flash_views((16, 16), rho_d=one, rho_s=(0.08, 0.08), alpha=(0.12, 0.12), bump_amplitude=0.6)
    simulate_flash_views(scene, tmp_path / "src", noise=FlashNoise(NOISE_READ, NOISE_GAIN), seed=0)
    wj.import_capture(tmp_path / "src", tmp_path / "cap")
    with open(tmp_path / "cap" / "capture.toml", "a") as fh:
        fh.write(f"\n[noise]\nread = {NOISE_READ}\nshot = {NOISE_GAIN}\n")
    data = photo_data(wj.load_capture(tmp_path / "cap"))
    rep = discover_photo(data, candidates=("normals", "height_field"), name="bumps")
    # the bumps are a height field: its normals cost a height per pixel (255), free ones two slopes (512)
    assert rep.found == ["height_field"] and rep.within_noise, rep.verdict()
    step = rep.steps[0]
    ks = {c.effect: c.k for c in step.candidates}
    assert ks == {"height_field": 16 * 16 - 1, "normals": 2 * 16 * 16}
    assert step.evidence.holdout is not None and step.evidence.holdout.passed  # and it predicts the other views


def test_09_the_shared_fit_agrees_with_scipy(vignetted):
    """:func:`fit_shared` (optimistix LM, padded to a size bucket) against SciPy's bounded trust-region fit
    of the same projected residuals, written here apart: the same optimum, χ² and σ."""
    from scipy.optimize import least_squares

    data, names = vignetted, ("vignetting",)
    fit = fit_shared(data, names)
    u, v, n = data.lobe_geometry
    sw = data.w.sum(1)

    def residuals(x):
        g = (1.0 + data.radius2 * (x[1] + x[2] * data.radius2))[..., None]
        f, w = data.f / g, data.w * g * g
        lobe = (n * np.exp(-(u + v) / np.exp(2 * x[0])) / np.exp(2 * x[0]))[..., None]
        sw = w.sum(1)[:, None]
        ft, lt = f - (w * f).sum(1)[:, None] / sw, lobe - (w * lobe).sum(1)[:, None] / sw
        s = max(np.sum(w * ft * lt), 0.0) / np.sum(w * lt * lt)
        return (np.sqrt(w) * (ft - s * lt)).ravel()

    assert np.all(sw > 0)
    ref = least_squares(residuals, fit.x + [0.1, 0.05, -0.05], bounds=([-7, -3, -3], [0.7, 3, 3]), xtol=1e-12)
    sd = np.sqrt(np.diag(np.linalg.inv(ref.jac.T @ ref.jac)))
    assert fit.x == pytest.approx(ref.x, abs=1e-3 * sd.max())
    assert fit.chi2 == pytest.approx(2 * ref.cost, rel=1e-9)
    assert fit.sigma["vignetting"] == pytest.approx(tuple(sd[1:]), rel=1e-3)
    assert fit.alpha_sigma == pytest.approx(fit.alpha * sd[0], rel=1e-3)
    assert abs(fit.effects["vignetting"][0] + 0.3) < 4 * fit.sigma["vignetting"][0]  # the truth within 4σ
