"""The ColorChecker correction's colour error carried into the smartphone ρd σ, on the real PlantCV photo.

The reference is independent of the σ: each patch in turn plays the surface,
its ρd is corrected by a chart fit that never saw it, and the error against
the chart's published colour is divided by the σ computed from the other
patches only (nested leave-one-out). A σ that is right makes that ratio's RMS
about 1; the region's standard error alone (the σ before the chart) is ~1000×
too small.
"""

import tomllib
from pathlib import Path

import imageio.v3 as iio
import numpy as np
import pytest

from wardjax.capture import load_capture
from wardjax.smartphone import (
    COLORCHECKER_NAMES,
    Lab_to_diffuse,
    chart_correction,
    colorchecker_held_out_delta_E,
    colorchecker_held_out_Lab,
    colorchecker_patch_regions,
    colorchecker_reference_Lab,
    colorchecker_rho_d,
    diffuse_from_srgb,
    fit_camera_correction,
    rho_d_color_sigma,
)

DATA = Path(__file__).parent / "data" / "colorchecker"
EXAMPLE = Path(__file__).parents[1] / "examples" / "smartphone" / "colorchecker-red"
WHITE = COLORCHECKER_NAMES.index("white 9.5 (.05 D)")


@pytest.fixture(scope="module")
def chart():
    photo = iio.imread(DATA / "plantcv_source1_img.png")
    lay = tomllib.loads((DATA / "layout.toml").read_text(encoding="utf-8"))
    regions = colorchecker_patch_regions(
        tuple(lay["first_center"]), tuple(lay["pitch"]), tuple(lay["grid"]), lay["half_size"], lay["order"]
    )
    return photo, regions


def test_held_out_Lab_is_the_held_out_delta_E(chart):
    photo, regions = chart
    raw, ref = colorchecker_rho_d(photo, regions), colorchecker_reference_Lab()
    usable = np.arange(24) != WHITE
    lab = colorchecker_held_out_Lab(raw, ref, usable=usable)
    np.testing.assert_allclose(np.linalg.norm(lab, axis=-1), colorchecker_held_out_delta_E(raw, ref, usable=usable))
    assert np.isnan(lab[WHITE]).all()


def test_chart_correction_leaves_out_the_clipped_white_and_the_surface(chart):
    photo, regions = chart
    red = COLORCHECKER_NAMES.index("red")
    cc = chart_correction(photo, regions, surface=regions[red])
    assert not cc.usable[WHITE] and not cc.usable[red] and cc.usable.sum() == 22
    s = cc.summary()
    # the uncorrected photo is far off (mean ΔE*ab ~ 19); held out, the correction leaves ~ 3.4
    assert s["delta_E_uncorrected"]["mean"] > 15 > 5 > s["delta_E_held_out"]["mean"] > 2


def test_rho_d_sigma_is_the_colour_error_on_the_real_photo(chart):
    """Every usable patch as the surface: RMS over patches and channels of error/σ within [0.5, 2]."""
    photo, regions = chart
    raw, ref = colorchecker_rho_d(photo, regions), colorchecker_reference_Lab()
    usable = np.arange(24) != WHITE
    z, z_region = [], []
    for k in np.flatnonzero(usable):
        others = usable.copy()
        others[k] = False
        corr = fit_camera_correction(raw[others], ref[others])
        rho = corr.apply(raw[k : k + 1])[0]
        sigma = rho_d_color_sigma(rho, colorchecker_held_out_Lab(raw, ref, usable=others))
        truth = Lab_to_diffuse(ref[k], "D50")
        z.append((rho - truth) / sigma)
        _, se = diffuse_from_srgb(photo, regions[k], return_stderr=True)
        z_region.append((rho - truth) / se)
    rms, rms_region = (float(np.sqrt(np.mean(np.square(v)))) for v in (z, z_region))
    print(f"\nRMS error/σ over 23 patches × 3 channels: {rms:.2f} (region σ alone: {rms_region:.0f})")
    assert 0.5 < rms < 2.0
    assert rms_region > 100  # the σ before the chart: two to three orders too small


def test_example_capture_fit_carries_the_colour_error(tmp_path):
    """``wardjax fit`` on the shipped example: ρd σ ≈ the chart's held-out ΔE, not the region's standard error."""
    from wardjax.run import fit_smartphone_capture

    doc = fit_smartphone_capture(load_capture(EXAMPLE), tmp_path, created="2000-01-01T00:00:00Z")
    cc = doc["fit"]["color_correction"]
    sigma, region = np.array(doc["stderr"]["rho_d"]), np.array(cc["rho_d_sigma_region"])
    assert np.all(sigma > 50 * region)
    # σ in ΔE*ab: move the red's Lab by ±σ per channel; its size within 2× of the chart's RMS held-out ΔE
    from wardjax.smartphone import diffuse_to_Lab

    rho = np.array(doc["params"]["rho_d"])
    lab0 = diffuse_to_Lab(rho[None], "D50")[0]
    dE = np.sqrt(sum(np.sum((diffuse_to_Lab((rho + sigma * e)[None], "D50")[0] - lab0) ** 2) for e in np.eye(3)))
    rms = cc["delta_E_held_out"]["rms"]
    assert rms / 2 < dE < 2 * rms


def test_color_correction_field_is_validated(tmp_path):
    """A [color_correction] whose order misses a patch, or whose boxes leave the photo: one line naming the field."""
    from wardjax.capture import CaptureError

    for edit, field in (
        ("order = [18, 12, 6, 0, 19, 13, 7, 1, 20, 14, 8, 2, 21, 15, 9, 3, 22, 16, 10, 4, 23, 17, 11, 11]", "order"),
        ("first_center = [166.0, 390.0]", "color_correction"),
    ):
        folder = tmp_path / field
        folder.mkdir()
        (folder / "photo.png").write_bytes((EXAMPLE / "photo.png").read_bytes())
        key = edit.split(" = ")[0]
        text = (EXAMPLE / "capture.toml").read_text().splitlines()
        lines = [edit if ln.startswith(key + " = ") else ln for ln in text]
        (folder / "capture.toml").write_text("\n".join(lines) + "\n")
        with pytest.raises(CaptureError, match=f"color_correction.*{field}|{field}") as e:
            load_capture(folder)
        assert "\n" not in str(e.value)
