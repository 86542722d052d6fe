"""Radiance exports and params.json: colour conversion against an independent matrix, material text."""

import numpy as np
import pytest

import wardjax as wj
from wardjax.export import radiance_material, radiance_metal, radiance_rgb


def _npm(xy, white):
    """RGB→XYZ matrix from chromaticities (SMPTE RP 177), written out independently of colour-science."""
    xyz = np.array([[x / y, 1.0, (1 - x - y) / y] for x, y in xy]).T
    w = np.array([white[0] / white[1], 1.0, (1 - white[0] - white[1]) / white[1]])
    return xyz * np.linalg.solve(xyz, w)


def test_radiance_rgb_matches_primaries_change():
    e = (1 / 3, 1 / 3)
    m_srgb = _npm([(0.64, 0.33), (0.30, 0.60), (0.15, 0.06)], e)
    m_rad = _npm([(0.640, 0.330), (0.290, 0.600), (0.150, 0.060)], e)
    rgb = np.array([[0.6, 0.5, 0.4], [0.1, 0.8, 0.2], [1.0, 0.0, 0.0]])
    want = rgb @ (np.linalg.inv(m_rad) @ m_srgb).T
    np.testing.assert_allclose(radiance_rgb(rgb), want, atol=1e-10)


def test_grey_stays_grey():
    np.testing.assert_allclose(radiance_rgb([0.42, 0.42, 0.42]), [0.42] * 3, atol=1e-12)


def test_plastic_text():
    p = wj.WardParams(rho_d=(0.5, 0.5, 0.5), rho_s=0.04, alpha_x=0.1, alpha_y=0.1)
    text = radiance_material(p, "desk top")
    # colour = ρd/(1 − ρs) = 0.5/0.96 = 0.520833
    assert text == "void plastic desk_top\n0\n0\n5 0.520833 0.520833 0.520833 0.04 0.1\n"


def test_plastic2_text_with_tangent():
    p = wj.WardParams(rho_d=(0.3, 0.3, 0.3), rho_s=0.02, alpha_x=0.05, alpha_y=0.08)
    text = radiance_material(p, "m", tangent=(0.0, 2.0))
    assert text == "void plastic2 m\n4 0 1 0 .\n0\n6 0.306122 0.306122 0.306122 0.02 0.05 0.08\n"


def test_bad_rho_s():
    with pytest.raises(ValueError, match="rho_s"):
        radiance_material(wj.WardParams(rho_d=(0.3,) * 3, rho_s=1.2, alpha_x=0.1, alpha_y=0.1))


def test_metal_exact_when_possible():
    # c = 0.8, s = 0.25: diffuse 0.6, specular 0.2 → exactly representable; distance 0.
    p = wj.WardParams(rho_d=(0.6, 0.6, 0.6), rho_s=0.2, alpha_x=0.09, alpha_y=0.09)
    text, dist = radiance_metal(p, "gold")
    assert text == "void metal gold\n0\n0\n5 0.8 0.8 0.8 0.25 0.09\n"
    assert dist < 1e-6
    _, far = radiance_metal(wj.WardParams(rho_d=(0.45, 0.1, 0.1), rho_s=0.5, alpha_x=0.1, alpha_y=0.1))
    assert far > 0.05
