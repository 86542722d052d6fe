"""ColorChecker validation of the ρd method (smartphone paper §3.2): simulated and real photos.

Run with ``-s`` to see the per-patch ΔE tables.
"""

import tomllib
from pathlib import Path

import colour
import imageio.v3 as iio
import numpy as np
import pytest

from wardjax.smartphone import _color as color
from wardjax.smartphone._colorchecker import (
    COLORCHECKER_NAMES,
    _XYZ_of_spectra,
    colorchecker_delta_E,
    colorchecker_held_out_delta_E,
    colorchecker_patch_regions,
    colorchecker_reference_Lab,
    colorchecker_rho_d,
    fit_camera_correction,
    simulate_colorchecker_photo,
)

DATA = Path(__file__).parent / "data" / "colorchecker"
PAPER_MIN_MEAN_MAX = (1.6, 7.1, 18.8)  # its iPhone 5s photo, section 3.2
WHITE = COLORCHECKER_NAMES.index("white 9.5 (.05 D)")
NEUTRALS = list(range(WHITE, WHITE + 6))


def _print_table(title, dE_by_column):
    print(f"\n{title}")
    cols = list(dE_by_column)
    print(f"{'patch':22s}" + "".join(f"{c:>14s}" for c in cols))
    for i, name in enumerate(COLORCHECKER_NAMES):
        print(f"{name:22s}" + "".join(f"{dE_by_column[c][i]:14.2f}" for c in cols))
    for stat in (np.min, np.mean, np.max):
        print(f"{stat.__name__:22s}" + "".join(f"{stat(dE_by_column[c]):14.2f}" for c in cols))


# ----------------------------------------------------------------------------- simulated chart


def test_simulated_chart_mean_delta_E_below_2_with_exact_srgb():
    ref = colorchecker_reference_Lab("spectra")
    img, regions = simulate_colorchecker_photo()  # 8-bit JPEG (quality 95) via imageio
    assert img.dtype == np.uint8 and img.ndim == 3
    dE = {
        dec: colorchecker_delta_E(colorchecker_rho_d(img, regions, decoding=dec), ref) for dec in ("srgb", "gamma2.2")
    }
    _print_table("simulated ColorChecker, ΔE*ab (D50) per patch", dE)
    assert dE["srgb"].mean() <= 2.0
    # the paper's γ 2.2 mis-decodes the sRGB toe: it is worse than the exact curve
    assert dE["gamma2.2"].mean() > dE["srgb"].mean()


def test_simulated_chart_remaining_error_is_the_illuminant_change():
    """Decompose the simulated error (mean ΔE76 ≈ 1.35 with the exact sRGB curve).

    1. Illuminant change (≈ 1.1 of it): the reference integrates the spectra under D50,
       while the camera saw D65 and the method carries white with Bradford (D65 → E →
       D50); for real spectra a von Kries transform is not a change of illuminant.
       Against the D65 colours Bradford-adapted to D50 the unquantised pipeline is exact.
    2. Gamut clipping: cyan lies outside sRGB under D65 (R < 0) and is clipped (≈ 4.7 on
       that patch alone).
    3. The camera: 8-bit quantisation and JPEG (quality 95) add ≈ 0.2 on average.
    """
    ref = colorchecker_reference_Lab("spectra")
    ideal, regions = simulate_colorchecker_photo(quantize=False)
    eight_bit, _ = simulate_colorchecker_photo(jpeg_quality=None)
    jpeg, _ = simulate_colorchecker_photo()
    dE = {
        name: colorchecker_delta_E(colorchecker_rho_d(im, regions, decoding="srgb"), ref)
        for name, im in (("ideal", ideal), ("8-bit", eight_bit), ("8-bit JPEG", jpeg))
    }
    # reference = the same spectra seen under D65, Bradford-adapted to D50
    ccs = colour.CCS_ILLUMINANTS["CIE 1931 2 Degree Standard Observer"]
    xyz65 = _XYZ_of_spectra("D65")  # what the simulated camera saw
    xyz50 = colour.chromatic_adaptation(
        xyz65, colour.xy_to_XYZ(ccs["D65"]), colour.xy_to_XYZ(ccs["D50"]), method="Von Kries", transform="Bradford"
    )
    ref_cat = colour.XYZ_to_Lab(xyz50, ccs["D50"])
    dE["ideal vs CAT ref"] = colorchecker_delta_E(colorchecker_rho_d(ideal, regions, decoding="srgb"), ref_cat)
    _print_table("simulated ColorChecker: where the error comes from", dE)
    # patches outside the sRGB gamut under D65 (cyan) are clipped by the camera
    out_of_gamut = np.any(colour.XYZ_to_RGB(xyz65, "sRGB", apply_cctf_encoding=False) < 0, axis=-1)
    assert list(np.flatnonzero(out_of_gamut)) == [COLORCHECKER_NAMES.index("cyan")]
    assert dE["ideal vs CAT ref"][~out_of_gamut].max() < 0.05  # in gamut, the method itself is exact
    assert dE["ideal vs CAT ref"][out_of_gamut].min() > 2  # gamut clipping: cyan
    assert dE["ideal"].mean() > 0.75 * dE["8-bit JPEG"].mean()  # most error: illuminant change + clipping
    assert 0 < dE["8-bit JPEG"].mean() - dE["ideal"].mean() < 0.5  # camera quantisation + JPEG: small


def test_camera_correction_on_simulated_chart_held_out():
    ref = colorchecker_reference_Lab("spectra")
    img, regions = simulate_colorchecker_photo()
    rho = colorchecker_rho_d(img, regions, decoding="srgb")
    fit = np.arange(24) % 2 == 0
    corr = fit_camera_correction(rho[fit], ref[fit])
    before = colorchecker_delta_E(rho[~fit], ref[~fit]).mean()
    after = colorchecker_delta_E(corr.apply(rho[~fit]), ref[~fit]).mean()
    print(f"\nsimulated chart, held-out mean ΔE*ab: {before:.2f} → {after:.2f} (γ {corr.gamma:.3f})")
    # an ideal camera: only the D65 → D50 spectral change is left, and a least-squares fit in
    # linear RGB on 12 patches does not remove it (it shifts it between patches)
    assert after < 2.0 and abs(corr.gamma - 1) < 0.05  # nothing to fix in the tone curve


# ----------------------------------------------------------------------------- the real photo


def _real_photo():
    img = iio.imread(DATA / "plantcv_source1_img.png")
    with open(DATA / "layout.toml", "rb") as fh:
        lay = tomllib.load(fh)
    regions = colorchecker_patch_regions(
        tuple(lay["first_center"]), tuple(lay["pitch"]), tuple(lay["grid"]), lay["half_size"], lay["order"]
    )
    return img, regions


def test_real_photo_layout_hits_the_patches():
    img, regions = _real_photo()
    assert img.shape == (335, 400, 3) and img.dtype == np.uint8
    assert len(regions) == 24
    spreads = []
    for y0, y1, x0, x1 in regions:
        box = img[y0:y1, x0:x1].reshape(-1, 3).astype(float)
        spreads.append(np.median(np.abs(box - np.median(box, 0)), 0).max())
    assert max(spreads) <= 4, spreads  # uniform: no box straddles a black gap
    # the neutral series runs down the first column, white at the top: strictly darker
    y = [color.luminance_from_rho_d(color.diffuse_from_srgb(img, regions[i])) for i in NEUTRALS]
    assert np.all(np.diff(y) < 0)


def test_real_photo_delta_E_beside_the_paper():
    img, regions = _real_photo()
    ref = colorchecker_reference_Lab("chromaticities")
    dE = {
        dec: colorchecker_delta_E(colorchecker_rho_d(img, regions, decoding=dec), ref) for dec in ("gamma2.2", "srgb")
    }
    _print_table("PlantCV photo, ΔE*ab (D50) per patch vs colour-science's ColorChecker24 (After Nov 2014)", dE)
    print(
        "min/mean/max   this photo (γ 2.2): "
        + "/".join(f"{f(dE['gamma2.2']):.1f}" for f in (np.min, np.mean, np.max))
        + "   paper's iPhone 5s: "
        + "/".join(f"{v:.1f}" for v in PAPER_MIN_MEAN_MAX)
    )
    assert all(np.all(np.isfinite(v)) and v.shape == (24,) for v in dE.values())
    # The white patch is clipped (all channels at 255) — outside what any decoding can recover.
    y0, y1, x0, x1 = regions[WHITE]
    assert np.all(img[y0:y1, x0:x1] == 255)


def test_real_photo_tone_curve_is_near_linear_not_srgb():
    """Why the photo scores worse than the paper's: its tone curve is not sRGB.

    Fit ``Y_ref = g · (C/255)^γ`` to the unclipped neutrals: a camera that encoded sRGB
    would give γ ≈ 2.2; this one is near-linear, so decoding with 2.2 crushes the darks.
    """
    img, regions = _real_photo()
    ref_y = color.luminance_from_rho_d(color.Lab_to_diffuse(colorchecker_reference_Lab(), "D50"))
    idx = NEUTRALS[1:]  # white is clipped
    codes = (
        np.array([img[y0:y1, x0:x1].reshape(-1, 3).mean() for (y0, y1, x0, x1) in (regions[i] for i in idx)]) / 255.0
    )
    gamma, log_g = np.polyfit(np.log(codes), np.log(ref_y[idx]), 1)
    print(f"\nPlantCV photo: effective decoding exponent from the neutrals γ = {gamma:.2f} (sRGB ≈ 2.2)")
    assert 0.8 < gamma < 1.4


@pytest.mark.parametrize("split", ["even/odd", "pairs"])
def test_real_photo_camera_correction_held_out(split):
    img, regions = _real_photo()
    ref = colorchecker_reference_Lab("chromaticities")
    rho = colorchecker_rho_d(img, regions, decoding="gamma2.2")
    i = np.arange(24)
    fit = (i % 2 == 0) if split == "even/odd" else ((i // 2) % 2 == 0)
    test = ~fit
    fit[WHITE] = False  # clipped: not a valid fitting target
    test[WHITE] = False
    before = colorchecker_delta_E(rho[test], ref[test])
    after = {}
    for label, kw in [
        ("3×3 only", dict(method="Cheung 2004", terms=3, tone=False)),
        ("γ + 3×3", dict(method="Cheung 2004", terms=3)),
        ("γ + root-poly 2", dict(method="Finlayson 2015", degree=2)),
    ]:
        corr = fit_camera_correction(rho[fit], ref[fit], **kw)
        after[label] = colorchecker_delta_E(corr.apply(rho[test]), ref[test])
        if kw.get("tone", True):
            assert 0.3 < corr.gamma < 0.7  # 2.2 · γ ≈ 1: the near-linear camera, found from held-in neutrals
    print(
        f"\nPlantCV photo ({split}), held-out mean ΔE*ab: uncorrected {before.mean():.1f}, "
        + ", ".join(f"{k} {v.mean():.1f} (min/max {v.min():.1f}/{v.max():.1f})" for k, v in after.items())
    )
    assert after["γ + 3×3"].mean() < 0.5 * before.mean()
    # With only 11 fitted patches the root-polynomial is fragile: in the "pairs" split it
    # extrapolates wildly to a few held-out saturated colours (ΔE > 50; median 5.4 against
    # 4.9 for γ + 3×3). Only the tone exponent is a sure gain at this size; see the
    # leave-one-out test for 22 fitted patches.
    assert max(np.median(after["γ + root-poly 2"]), np.median(after["γ + 3×3"])) < np.median(after["3×3 only"])


@pytest.mark.parametrize(
    ("method", "options", "limit"),
    [("Finlayson 2015", {"degree": 2}, 4.0), ("Cheung 2004", {"terms": 3}, 5.5), ("Cheung 2004", {"terms": 7}, 5.0)],
)
def test_real_photo_leave_one_out_delta_E(method, options, limit):
    """Held-out ΔE*ab on the real photo, each patch predicted by a correction fitted on the 22
    others (the clipped white is neither fitted nor scored). The root-polynomial meets the
    target of ≤ 4 (3.4); the linear γ + 3×3 (4.9) and Cheung's 7 terms (4.5) do not."""
    img, regions = _real_photo()
    ref = colorchecker_reference_Lab("chromaticities")
    rho = colorchecker_rho_d(img, regions, decoding="gamma2.2")
    usable = np.arange(24) != WHITE
    dE = colorchecker_held_out_delta_E(rho, ref, usable=usable, method=method, **options)
    assert np.isnan(dE[WHITE]) and np.all(np.isfinite(dE[usable]))
    d = dE[usable]
    before = colorchecker_delta_E(rho[usable], ref[usable])
    print(
        f"\nPlantCV photo, leave-one-out ΔE*ab, {method} {options}: min/mean/max"
        f" {d.min():.2f}/{d.mean():.2f}/{d.max():.2f} (uncorrected mean {before.mean():.1f};"
        f" paper's iPhone 5s {'/'.join(map(str, PAPER_MIN_MEAN_MAX))})"
    )
    assert d.mean() <= limit


def test_camera_correction_rejects_bad_input():
    ref = colorchecker_reference_Lab("chromaticities")
    rho = np.clip(np.asarray(color.Lab_to_diffuse(ref, "D50")), 1e-3, None)  # in gamut
    ref = np.asarray(color.diffuse_to_Lab(rho, "D50"))
    with pytest.raises(ValueError, match="method"):
        fit_camera_correction(rho, ref, method="Vandermonde 1772")
    with pytest.raises(ValueError, match="patches"):
        fit_camera_correction(rho[:5], ref[:5], method="Finlayson 2015", degree=2, tone=False)
    with pytest.raises(ValueError, match="neutral"):
        fit_camera_correction(rho[:12], ref[:12])
    # an exact chart: the correction is the identity, γ = 1
    corr = fit_camera_correction(rho, ref)
    assert corr.gamma == pytest.approx(1.0, abs=1e-9)
    np.testing.assert_allclose(corr.apply(rho), rho, atol=1e-9)
