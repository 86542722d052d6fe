"""The dark frame's check of the texture term: a texture in both frames stands, a misfit in the lit frame alone is
refused, and a dark frame too dark to show either changes nothing.

The levels are written here from their definitions (``y = (L_p − D_p)/span``, the room's light ``R`` under the dark
frame), not by the capture code: a probe of relative texture ``t`` lit by the lamp (``f̂ (1 + t)``) and the room
(``R (1 + t)``), each frame with its own noise.
"""

from types import SimpleNamespace

import numpy as np
import pytest

from wardjax.effects._dark_texture import dark_refutes

S, N, C = 40, 64, 3
PRED, ROOM = 0.1, 0.01


def _smooth_field(rng, amplitude, rho=0.9):
    """``(S, N, C)`` AR(1) along each scanline with correlation ``rho`` per sample and SD ``amplitude``."""
    x = np.empty((S, N, C))
    x[:, 0] = rng.standard_normal((S, C))
    for j in range(1, N):
        x[:, j] = rho * x[:, j - 1] + np.sqrt(1 - rho**2) * rng.standard_normal((S, C))
    return amplitude * x


def _case(rng, *, texture=0.0, misfit=0.0, room=ROOM, dark_sd=0.002, lit_sd=0.002):
    """``(data, resid, off, pred, claim)``: the baseline's residual holds the texture and a lit-only misfit."""
    t, m = _smooth_field(rng, texture), _smooth_field(rng, misfit)
    pred = np.full((S, N, C), PRED)
    lit = (PRED + room) * (1 + t) + PRED * m + lit_sd * rng.standard_normal((S, N, C))
    dark = room * (1 + t) + dark_sd * rng.standard_normal((S, N, C))
    span = 1.0
    resid = (lit - dark) / span - pred
    ones = np.ones((S, N, C))
    data = SimpleNamespace(
        dark=(dark, np.full((S, N, C), room)),
        pixels={"lit_std": 2 * ones, "dark_std": ones, "ref": ones},  # span = (2 − 1)/1
    )
    claim = np.var(resid / pred, axis=(0, 1)) - (lit_sd**2 + dark_sd**2) / PRED**2  # what the term would read
    return data, resid, np.ones((S, N, C), bool), pred, claim


def test_a_texture_in_both_frames_stands():
    got = dark_refutes(*_case(np.random.default_rng(1), texture=0.04))
    assert got is not None and not got["refuted"]
    # the lit-only residual holds the texture under both lights: t (1 + R/f̂), so about 1.1 of the claim
    assert got["shown"] == pytest.approx(1 + ROOM / PRED, abs=4 * got["se"] + 0.05)


def test_a_misfit_of_the_lit_frame_alone_is_refused():
    got = dark_refutes(*_case(np.random.default_rng(2), misfit=0.04))
    assert got is not None and got["refuted"]
    assert abs(got["shown"]) < 4 * got["se"]  # the dark frame shows nothing of it, by its own SE


def test_a_dark_frame_without_light_decides_nothing():
    """Room light at 1e-4 of full scale under noise of 2e-3: the dark frame cannot show a 4 % texture, so a
    misfit is not refused (the texture term stands as it was) — and without a dark frame there is no reading."""
    data, resid, off, pred, claim = _case(np.random.default_rng(3), misfit=0.04, room=1e-4)
    got = dark_refutes(data, resid, off, pred, claim)
    assert got is not None and not got["refuted"] and got["se"] > 0.25
    data.dark = None
    assert dark_refutes(data, resid, off, pred, claim) is None


def test_too_few_values_off_the_highlight_decide_nothing():
    data, resid, off, pred, claim = _case(np.random.default_rng(4), misfit=0.04)
    off[:] = False
    off[:4, :10] = True
    assert dark_refutes(data, resid, off, pred, claim) is None


def test_a_refused_texture_is_reported_with_the_dark_frames_reading(tmp_path):
    """An untextured capture whose lit frame alone carries a smooth 3 % field (edited into the image file): the
    residuals claim a texture of about that amplitude, the dark frame shows none of it, and the report says so —
    the claimed amplitude and the dark frame's share in report.json's settings, a sentence in report.md — rather
    than reading as if no texture had been looked for."""
    import tomllib

    from scipy.ndimage import gaussian_filter

    import wardjax as wj
    from wardjax._files import decode_image, encode_image, read_image, write_image
    from wardjax.effects import ScanlineModel, discover
    from wardjax.effects._capture import capture_data

    p = wj.WardParams(rho_d=(0.5, 0.45, 0.4), rho_s=0.04, alpha_x=0.1, alpha_y=0.1)
    folder = tmp_path / "cap"
    wj.simulate_capture(p, folder, seed=0, image_size=(120, 90), texture="none")
    cfg = tomllib.loads((folder / "capture.toml").read_text())
    enc, bits = cfg["images"]["encoding"], int(cfg["images"]["bit_depth"])
    lit = folder / cfg["images"]["lit"]
    v = decode_image(read_image(lit), enc, bits).astype(np.float64)
    g = gaussian_filter(np.random.default_rng(0).standard_normal(v.shape[:2]), 3.0)
    write_image(lit, encode_image(np.clip(v * (1 + 0.03 * g / g.std())[..., None], 0, 1), enc, bits))
    cap = wj.load_capture(folder)
    rep = discover(ScanlineModel(cap.config.fit.normalization), capture_data(cap), texture=True, max_steps=0)
    tex = rep.settings["texture"]
    assert tex is not None and tex["refused"] == "dark frame"
    assert all(0.02 < a < 0.045 for a in tex["amplitude"]), tex["amplitude"]
    shown, se = tex["dark_shown"]
    assert abs(shown) < 4 * se < 0.5
    assert "taken for the model's misfit, not texture" in rep.to_markdown()
