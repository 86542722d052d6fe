"""The veiling-glare effect on captures: a veil and a share of the lit frame blurred wide, written into the lit
image file of a simulated capture (16-bit linear, so that re-quantising the edit adds no error of its own), is
named ``glare`` with its two parameters read back, and the fit under it puts ρs and α on the truth; the same
capture untouched names nothing."""

import tomllib

import numpy as np
import pytest
from scipy.ndimage import gaussian_filter

import wardjax as wj
from wardjax._files import decode_image, encode_image, read_image, write_image
from wardjax.effects import ScanlineModel, discover
from wardjax.effects._capture import capture_data
from wardjax.effects._pixel_levels import GLARE_WIDTH

TRUTH = wj.WardParams(rho_d=(0.2, 0.3, 0.5), rho_s=0.06, alpha_x=0.09, alpha_y=0.09)


def _capture(folder, veil: float, share: float):
    wj.simulate_capture(TRUTH, folder, seed=1, image_size=(160, 120), texture="none", encoding="linear", bit_depth=16)
    if veil or share:
        cfg = tomllib.loads((folder / "capture.toml").read_text())
        lit = folder / cfg["images"]["lit"]
        v = decode_image(read_image(lit), "linear", 16).astype(np.float64)
        w = v.shape[1] / GLARE_WIDTH
        v = v + veil + share * gaussian_filter(v, (w, w, 0), mode="nearest")  # written here, not by the effect
        write_image(lit, encode_image(np.clip(v, 0.0, 1.0), "linear", 16))
    cap = wj.load_capture(folder)
    return discover(ScanlineModel(cap.config.fit.normalization), capture_data(cap), texture=True)


@pytest.mark.parametrize("veil, share", [(0.002, 0.02), (0.0, 0.0)])
def test_glare_is_named_and_read_back(tmp_path, veil, share):
    rep = _capture(tmp_path / "cap", veil, share)
    if not share:
        assert rep.found == [], rep.found
        return
    assert rep.found == ["glare"], (rep.found, rep.gap)
    got = rep.steps[0].params
    assert got["g"] == pytest.approx(share, rel=0.2) and got["c"] == pytest.approx(veil, abs=0.0005), got
    assert rep.gap[-1] < 1 + 4 * np.sqrt(2 / rep.final.dof), rep.gap
    for k, truth in (("rho_s", TRUTH.rho_s), ("alpha", TRUTH.alpha_x)):
        v = rep.averaged[k]
        assert abs(v["value"] - truth) < 4 * v["sigma"], (k, v)


@pytest.mark.parametrize("shape", [(240, 320), (90, 121), (600, 800)])
def test_the_glare_field_on_its_coarse_grid_is_the_full_frames_blur(shape):
    """The wide blur taken on block averages and read back bilinearly equals :func:`scipy.ndimage.gaussian_filter`
    of the full frame (edges repeated) to 0.3 % of the blurred frame's range, on a frame with a bright highlight,
    a bright patch against the corner and noise."""
    from wardjax.effects._pixel_levels import glare_at, glare_field

    rng = np.random.default_rng(0)
    h, w = shape
    yy, xx = np.mgrid[0:h, 0:w]
    lit = 0.1 + 0.05 * rng.random((h, w, 3))
    lit += np.exp(-((xx - 0.6 * w) ** 2 + (yy - 0.4 * h) ** 2) / (2 * (0.03 * w) ** 2))[..., None]
    lit[int(0.7 * h) :, : int(0.2 * w)] = 0.9
    sd = w / GLARE_WIDTH
    full = gaussian_filter(lit, (sd, sd, 0), mode="nearest")
    field, step = glare_field(lit)
    got = glare_at(field, step, np.stack([xx, yy], axis=-1).astype(float))
    assert step == max(1, int(sd // 8))
    assert np.max(np.abs(got - full)) < 0.003 * np.ptp(full), np.max(np.abs(got - full)) / np.ptp(full)
