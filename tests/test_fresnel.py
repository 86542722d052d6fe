"""wardjax.smartphone (Fresnel): exact Fresnel (dielectrics, conductors), ρs = cosine-weighted mean 0–60°."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.integrate import quad

import wardjax as wj
from wardjax.smartphone import _fresnel as fresnel


def _fresnel_textbook(theta, n, k=0.0):
    """Born & Wolf form with an explicit transmitted angle (independent of the module's g form)."""
    eta = complex(n, k)
    st = np.sin(theta) / eta
    ct = np.sqrt(1 - st * st)
    ci = np.cos(theta)
    rs = (ci - eta * ct) / (ci + eta * ct)
    rp = (eta * ci - ct) / (eta * ci + ct)
    return 0.5 * (abs(rs) ** 2 + abs(rp) ** 2)


@pytest.mark.parametrize("n", [1.33, 1.5, 2.4])
def test_normal_incidence_dielectric(n):
    with jax.enable_x64(True):
        assert float(wj.fresnel_reflectance(1.0, n)) == pytest.approx(((n - 1) / (n + 1)) ** 2, rel=1e-12)


def test_normal_incidence_conductor_and_grazing():
    n, k = 0.27, 3.4
    with jax.enable_x64(True):
        f0 = float(wj.fresnel_reflectance(1.0, n, k))
        assert f0 == pytest.approx(((n - 1) ** 2 + k**2) / ((n + 1) ** 2 + k**2), rel=1e-12)
        assert float(wj.fresnel_reflectance(0.0, 1.5)) == pytest.approx(1.0)  # grazing: total
        assert float(wj.fresnel_reflectance(0.0, n, k)) == pytest.approx(1.0)


def test_matches_textbook_form_at_all_angles():
    theta = np.linspace(0, np.deg2rad(89.9), 50)
    with jax.enable_x64(True):
        for n, k in [(1.5, 0.0), (1.7, 0.0), (0.2, 3.0), (1.1, 2.6)]:
            got = np.asarray(wj.fresnel_reflectance(np.cos(theta), n, k))
            np.testing.assert_allclose(got, [_fresnel_textbook(t, n, k) for t in theta], rtol=1e-10)


def test_brewster_angle_p_polarisation_vanishes():
    # unpolarised F at Brewster is |rs|²/2; check that rp = 0 there through F = |rs|²/2
    n = 1.5
    tb = np.arctan(n)
    ct = np.cos(np.arcsin(np.sin(tb) / n))
    rs = (np.cos(tb) - n * ct) / (np.cos(tb) + n * ct)
    with jax.enable_x64(True):
        assert float(wj.fresnel_reflectance(np.cos(tb), n)) == pytest.approx(0.5 * rs**2, rel=1e-10)


def test_specular_from_fresnel_is_paper_value_and_a_cosine_weighted_mean():
    assert round(wj.specular_from_fresnel(1.5), 3) == 0.050
    t = np.deg2rad(60)
    num = quad(lambda th: _fresnel_textbook(th, 1.5) * np.cos(th) * np.sin(th), 0, t)[0]
    den = quad(lambda th: np.cos(th) * np.sin(th), 0, t)[0]
    assert wj.specular_from_fresnel(1.5) == pytest.approx(num / den, rel=1e-10)
    # batch: n-d in, n-d out; monotone in n
    rho = wj.specular_from_fresnel(np.array([[1.33, 1.5], [1.6, 1.7]]))
    assert rho.shape == (2, 2) and np.all(np.diff(rho.ravel()) > 0)
    # a narrower cone tends to normal incidence
    assert wj.specular_from_fresnel(1.5, max_angle_deg=1.0) == pytest.approx(0.04, rel=1e-3)


def test_jit_grad_and_no_global_x64_flip():
    before = jax.config.jax_enable_x64
    wj.specular_from_fresnel(1.5)
    assert jax.config.jax_enable_x64 == before
    g = jax.grad(lambda n: fresnel.fresnel_reflectance(jnp.asarray(1.0), n))(1.5)
    assert float(g) == pytest.approx(4 * (1.5 - 1) / (1.5 + 1) ** 3, rel=1e-4)  # d/dn ((n-1)/(n+1))²


def test_metal_rgb_rho_s():
    gold = wj.specular_rgb_metal("gold")
    silver = wj.specular_rgb_metal("silver")
    copper = wj.specular_rgb_metal("copper")
    alu = wj.specular_rgb_metal("aluminium")
    assert gold[0] > gold[1] > gold[2] and gold[2] < 0.5  # yellow
    assert copper[0] > copper[1] and copper[0] > copper[2]  # reddish
    assert np.ptp(silver) < 0.07 and np.ptp(alu) < 0.03  # nearly neutral
    assert np.all((silver > 0.85) & (silver < 1.0)) and np.all((alu > 0.85) & (alu < 1.0))
    # a spectrally flat conductor gives R = G = B (the colour path keeps white E neutral)
    n, k = fresnel.metal_ior("aluminium", 550.0)
    assert np.allclose(fresnel.specular_rgb_metal("aluminium"), wj.specular_from_fresnel(n, k), atol=0.02)


@pytest.mark.parametrize(
    "kwargs, message",
    [
        (dict(n=-1.5), "n \\(refractive index\\) must be finite and > 0"),
        (dict(n=1.5, k=-0.1), "k \\(extinction coefficient\\)"),
        (dict(n=1.5, max_angle_deg=95.0), "max_angle_deg"),
    ],
)
def test_bad_inputs(kwargs, message):
    with pytest.raises(ValueError, match=message):
        wj.specular_from_fresnel(**kwargs)


def test_unknown_metal_and_wavelength():
    with pytest.raises(ValueError, match="metal must be one of"):
        wj.specular_rgb_metal("unobtainium")
    with pytest.raises(ValueError, match="wavelength_nm"):
        fresnel.metal_ior("gold", 200.0)
