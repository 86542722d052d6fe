"""wardjax.smartphone (colour): sRGB decoding, Bradford D65→E, robust region mean, ΔE (smartphone paper §3.1, §9.1)."""

import csv

import colour
import numpy as np
import pytest

import wardjax as wj
from wardjax._data import calibration_path
from wardjax.smartphone import _color as color


def _srgb_decode_reference(c):
    """IEC 61966-2-1 written out independently of colour-science."""
    c = np.asarray(c, float)
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


# ----------------------------------------------------------------------------- decoding


def test_decode_gamma22_and_exact_srgb():
    codes = np.arange(256, dtype=np.uint8)
    np.testing.assert_allclose(color.decode_srgb(codes, "gamma2.2"), (codes / 255.0) ** 2.2, rtol=1e-12)
    np.testing.assert_allclose(
        color.decode_srgb(codes, "srgb"), _srgb_decode_reference(codes / 255.0), rtol=1e-10, atol=1e-12
    )
    # uint16 and floats mean the same encoded value
    np.testing.assert_allclose(color.decode_srgb(np.array([65535], np.uint16), "srgb"), [1.0])
    np.testing.assert_allclose(color.decode_srgb(np.array([0.5]), "gamma2.2"), [0.5**2.2])


def test_d65_to_E_matrix_matches_colour_science_bradford():
    m = color.matrix_rgb_D65_to_E()
    np.testing.assert_allclose(m @ np.ones(3), np.ones(3), atol=1e-12)  # white stays white
    rng = np.random.default_rng(3)
    rgb = rng.uniform(0.02, 1.0, (50, 3))
    ccs = colour.CCS_ILLUMINANTS["CIE 1931 2 Degree Standard Observer"]
    srgb = colour.RGB_COLOURSPACES["sRGB"].copy()
    srgb.use_derived_matrix_RGB_to_XYZ = True  # the primaries' NPM, not IEC's rounded matrix
    xyz = colour.RGB_to_XYZ(rgb, srgb, apply_cctf_decoding=False)
    xyz_e = colour.chromatic_adaptation(
        xyz, colour.xy_to_XYZ(ccs["D65"]), colour.xy_to_XYZ(ccs["E"]), method="Von Kries", transform="Bradford"
    )
    srgb_e = colour.RGB_Colourspace(
        "sRGB E",
        colour.RGB_COLOURSPACES["sRGB"].primaries,
        ccs["E"],
        use_derived_matrix_RGB_to_XYZ=True,
        use_derived_matrix_XYZ_to_RGB=True,
    )
    expected = colour.XYZ_to_RGB(xyz_e, srgb_e, apply_cctf_encoding=False)
    np.testing.assert_allclose(rgb @ m.T, expected, atol=1e-10)


# ----------------------------------------------------------------------------- diffuse_from_srgb


def test_diffuse_from_srgb_grey_patch_is_the_decoded_code():
    img = np.full((20, 30, 3), 180, np.uint8)
    for dec, expect in (("gamma2.2", (180 / 255) ** 2.2), ("srgb", _srgb_decode_reference(180 / 255))):
        rho = wj.diffuse_from_srgb(img, region=(2, 18, 5, 25), decoding=dec)
        assert rho.shape == (3,)
        np.testing.assert_allclose(rho, expect, rtol=1e-9)  # neutral stays neutral through Bradford


def test_diffuse_from_srgb_is_robust_to_specular_specks(rng):
    img = np.clip(rng.normal(120, 3, (40, 40, 3)), 0, 255).astype(np.uint8)
    clean = wj.diffuse_from_srgb(img, region=(0, 40, 0, 40))
    dirty = img.copy()
    idx = rng.choice(1600, 40, replace=False)  # 2.5 % of pixels are highlights
    dirty.reshape(-1, 3)[idx] = 255
    rho = wj.diffuse_from_srgb(dirty, region=(0, 40, 0, 40))
    plain = color.matrix_rgb_D65_to_E() @ color.decode_srgb(dirty.reshape(-1, 3)).mean(0)
    assert np.max(np.abs(rho / clean - 1)) < 0.01 < np.max(np.abs(plain / clean - 1))
    rho2, se = wj.diffuse_from_srgb(dirty, region=(0, 40, 0, 40), return_stderr=True)
    np.testing.assert_allclose(rho2, rho)
    assert np.all((se > 0) & (se < 0.01 * rho))


def test_diffuse_from_srgb_colour_path_against_colour_science(rng):
    codes = rng.integers(30, 230, 3).astype(np.uint8)
    img = np.broadcast_to(codes, (8, 8, 3)).copy()
    rho = wj.diffuse_from_srgb(img, (0, 8, 0, 8), decoding="srgb")
    ccs = colour.CCS_ILLUMINANTS["CIE 1931 2 Degree Standard Observer"]
    ccs_d65 = colour.xy_to_XYZ(ccs["D65"])
    npm = colour.normalised_primary_matrix(colour.RGB_COLOURSPACES["sRGB"].primaries, ccs["D65"])
    xyz = colour.cctf_decoding(codes / 255.0, function="sRGB") @ npm.T  # exact sRGB curve, D65
    xyz_e = colour.chromatic_adaptation(
        xyz, ccs_d65, colour.xy_to_XYZ(ccs["E"]), method="Von Kries", transform="Bradford"
    )
    np.testing.assert_allclose(
        rho @ colour.normalised_primary_matrix(colour.RGB_COLOURSPACES["sRGB"].primaries, ccs["E"]).T, xyz_e, atol=1e-10
    )


# ----------------------------------------------------------------------------- bad inputs


@pytest.mark.parametrize(
    "image, region, message",
    [
        (np.zeros((10, 10), np.uint8), (0, 5, 0, 5), "RGB photo"),
        (np.zeros((10, 10, 4), np.uint8), (0, 5, 0, 5), "RGB photo"),
        (np.zeros((10, 10, 3), np.uint8), (5, 5, 0, 5), "empty"),
        (np.zeros((10, 10, 3), np.uint8), (0, 5, 7, 3), "empty"),
        (np.zeros((10, 10, 3), np.uint8), (0, 11, 0, 5), "outside"),
        (np.zeros((10, 10, 3), np.uint8), (-1, 5, 0, 5), "outside"),
        (np.full((10, 10, 3), 2.0), (0, 5, 0, 5), "expected encoded values in \\[0, 1\\]"),
        (np.zeros((10, 10, 3), np.uint8), (0, 5, 0), "four entries"),
    ],
)
def test_bad_inputs_give_one_clear_error(image, region, message):
    with pytest.raises(ValueError, match=message):
        wj.diffuse_from_srgb(image, region=region)


def test_bad_region_types_and_decoding():
    img = np.zeros((10, 10, 3), np.uint8)
    with pytest.raises(TypeError, match="integers"):
        wj.diffuse_from_srgb(img, region=(0, 5.5, 0, 5))
    with pytest.raises(ValueError, match="decoding must be one of"):
        wj.diffuse_from_srgb(img, region=(0, 5, 0, 5), decoding="gamma1.8")
    with pytest.raises(TypeError, match="dtype"):
        wj.diffuse_from_srgb(np.zeros((10, 10, 3), np.int32), region=(0, 5, 0, 5))


# ----------------------------------------------------------------------------- colorimetry


def test_luminance_and_lab_round_trip(rng):
    assert float(color.luminance_from_rho_d(0.3)) == 0.3
    np.testing.assert_allclose(color.luminance_from_rho_d(np.full(3, 0.42)), 0.42)
    rho = rng.uniform(0.01, 0.95, (7, 3))
    for white in ("D50", "E", "D65"):
        np.testing.assert_allclose(color.Lab_to_diffuse(color.diffuse_to_Lab(rho, white), white), rho, atol=1e-10)
    # perfect white is L* = 100, a* = b* = 0 under any white
    np.testing.assert_allclose(color.diffuse_to_Lab(np.ones(3), "D50"), [100, 0, 0], atol=1e-8)


def test_delta_E_reproduces_table_II():
    with open(calibration_path("smartphone_table2_lab.csv"), encoding="utf-8") as fh:
        rows = list(csv.DictReader(r for r in fh if not r.startswith("#")))
    meas = np.array([[float(r[f"{c}_measured"]) for c in "Lab"] for r in rows])
    est = np.array([[float(r[f"{c}_estimated"]) for c in "Lab"] for r in rows])
    printed = np.array([float(r["delta_E_ab"]) for r in rows])
    got = wj.delta_E_CIE1976(meas, est)
    assert got.shape == (6,)
    np.testing.assert_allclose(got, printed, atol=0.006)  # the paper prints 2 decimals
    de2000 = wj.delta_E_CIE2000(meas, est)
    assert np.all(de2000 < got)  # CIEDE2000 discounts chroma differences of saturated paints


def test_ciede2000_sharma_reference_pairs():
    # Sharma, Wu & Dalal (2005), test data pairs 1, 2 and 7
    lab1 = np.array([[50.0, 2.6772, -79.7751], [50.0, 3.1571, -77.2803], [50.0, 0.0, 0.0]])
    lab2 = np.array([[50.0, 0.0, -82.7485], [50.0, 0.0, -82.7485], [50.0, -1.0, 2.0]])
    np.testing.assert_allclose(wj.delta_E_CIE2000(lab1, lab2), [2.0425, 2.8615, 2.3669], atol=1e-4)
