"""Radiance in the loop: the rig rendered by Radiance (pyradiance's rtrace) against closed forms and the JAX renderer.

Radiance is an independent renderer (its own ray tracing, source sampling and
material code, ``normal.c``/``aniso.c``); the JAX renderer shares only
:func:`wardjax.ward_brdf` with the fitter. Where the two agree per pixel, the
exported material means in Radiance what the fit meant.
"""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.interpolate import RegularGridInterpolator

import wardjax as wj
from wardjax.export import radiance_material, radiance_metal
from wardjax.geometry import pixel_geometry
from wardjax.render import from_radiance_rgb, radiance_render_rig, render_rig, texture_grid
from wardjax.simulate import default_rig

pytest.importorskip("pyradiance")

L = 1000.0  # lamp radiance: any value, the renders are linear in it
RIG = default_rig((64, 48))
# Pixels whose light or view direction lies within 5° of the horizon are left out of the comparison
# ("near-grazing"); the default rig has none, the grazing rig below has some.
GRAZING_COS = np.sin(np.radians(5.0))

MATERIALS = {
    "plastic": wj.WardParams(rho_d=(0.6, 0.5, 0.4), rho_s=0.04, alpha_x=0.1, alpha_y=0.1),
    "plastic2": wj.WardParams(rho_d=(0.3, 0.5, 0.4), rho_s=0.06, alpha_x=0.08, alpha_y=0.16),
    "metal": wj.WardParams(rho_d=(0.2, 0.2, 0.2), rho_s=0.5, alpha_x=0.12, alpha_y=0.12),
}


def _jax(params, rig, **kw):
    with jax.enable_x64(True):
        return np.asarray(render_rig(params, rig, lamp_radiance=L, dtype=jnp.float64, **kw))


def _compared(rig, grazing_cut: bool = True):
    """Pixels on the probe or the standard, away from grazing directions and the rectangles' edges (0.5 mm)."""
    g = pixel_geometry(rig, *np.meshgrid(np.arange(rig.camera.width), np.arange(rig.camera.height)))
    x, y = np.nan_to_num(g.points[..., 0]), np.nan_to_num(g.points[..., 1])

    def inside(box):
        return (x > box[0] + 0.5) & (x < box[1] - 0.5) & (y > box[2] + 0.5) & (y < box[3] - 0.5)

    cut = GRAZING_COS if grazing_cut else 0.0
    ok = (g.wi[..., 2] > cut) & (g.wo[..., 2] > cut)
    return np.nan_to_num(ok, nan=False) & (inside(rig.probe_box()) | inside(rig.standard_box()))


def test_01_diffuse_standard_matches_the_closed_form():
    """The standard under a sphere lamp: L · ρ/π · ω cos θi with ω = π r²/d² (Radiance's source term)."""
    rho = 0.99
    img = radiance_render_rig(RIG, radiance_material(MATERIALS["plastic"]), rho_standard=rho, lamp_radiance=L)
    g = pixel_geometry(RIG, *np.meshgrid(np.arange(64), np.arange(48)))
    omega = np.pi * 5.0**2 / g.dist_lamp**2
    expect = L * rho / np.pi * omega * g.wi[..., 2]
    m = g.in_standard & _compared(RIG)
    assert m.sum() > 500
    np.testing.assert_allclose(img[m], np.repeat(expect[m][:, None], 3, 1), rtol=1e-5)


@pytest.mark.parametrize("kind", list(MATERIALS))
def test_02_exported_material_renders_as_the_fit(kind):
    """Must show 1: Radiance's render of what export writes equals the JAX render of the parameters (≤ 5 %).

    Measured: ≤ 2e-5 relative on every compared pixel (float32 rays and 6-digit
    material text), for plastic, plastic2 and metal (a grey metal, which
    ``radiance_metal`` represents exactly).
    """
    p = MATERIALS[kind]
    text = radiance_metal(p)[0] if kind == "metal" else radiance_material(p)
    assert text.split()[1] == kind
    rad = radiance_render_rig(RIG, text, lamp_radiance=L)
    ref = _jax(p, RIG)
    m = _compared(RIG)
    assert m.sum() > 1000
    rel = np.abs(rad[m] / ref[m] - 1)
    assert rel.max() <= 0.05
    assert rel.max() <= 1e-4  # what is measured; the bound above is the issue's


def test_03_coloured_metal_specular_is_tinted():
    """A coloured ``metal``: its specular takes the material colour, c·s (Radiance RGB), diffuse c·(1 − s)."""
    p = wj.WardParams(rho_d=(0.25, 0.12, 0.05), rho_s=0.3, alpha_x=0.1, alpha_y=0.1)
    text, _ = radiance_metal(p)
    words = text.split()
    c, s, a = np.array(words[-5:-2], float), float(words[-2]), float(words[-1])
    implied = wj.WardParams(rho_d=from_radiance_rgb(c * (1 - s)), rho_s=from_radiance_rgb(c * s), alpha_x=a, alpha_y=a)
    rad = radiance_render_rig(RIG, text, lamp_radiance=L)
    ref = _jax(implied, RIG)
    m = _compared(RIG)
    np.testing.assert_allclose(rad[m], ref[m], rtol=1e-4, atol=1e-9 * L)


def test_04_source_size_widens_the_lobe():
    """A large lamp (r = 40 mm): Radiance agrees with a² = α² + ω/4π and not with α alone."""
    p = wj.WardParams(rho_d=(0.1, 0.1, 0.1), rho_s=0.08, alpha_x=0.04, alpha_y=0.04)
    rad = radiance_render_rig(RIG, radiance_material(p), lamp_radius=40.0, lamp_radiance=L)
    m = _compared(RIG)
    with_size = _jax(p, RIG, lamp_radius=40.0)
    without = _jax(p, RIG, lamp_radius=40.0, source_size=False)
    assert np.max(np.abs(rad[m] / with_size[m] - 1)) < 1e-4
    assert np.max(np.abs(rad[m] / without[m] - 1)) > 0.1


def test_05_grazing_rig():
    """Camera and lamp 4.6° above the plane 500 mm away: every sample pixel lies within the stated grazing region
    (3.5–5° from the horizon), and Radiance and JAX still agree there (measured 2e-6)."""
    cam = dataclasses.replace(RIG.camera, position=(0.0, -500.0, 40.0))
    rig = dataclasses.replace(RIG, lamp=(0.0, 500.0, 40.0), camera=cam)
    p = MATERIALS["plastic2"]
    rad = radiance_render_rig(rig, radiance_material(p), lamp_radiance=L)
    ref = _jax(p, rig)
    m = _compared(rig, grazing_cut=False)
    assert m.sum() > 100 and not np.any(m & _compared(rig))
    assert np.max(np.abs(rad[m] / ref[m] - 1)) <= 1e-4


def test_06_texture_pattern_is_bilinear_in_the_grid():
    """A ``colordata`` ρd texture: Radiance equals the JAX render with ρd interpolated by SciPy from the same grid."""
    p = MATERIALS["plastic"]

    def tex(x, y):
        m = 1 + 0.3 * np.sin(x / 7.0) * np.cos(y / 11.0)
        return np.asarray(p.rho_d)[None, None] * m[..., None]

    rad = radiance_render_rig(RIG, radiance_material(p), lamp_radiance=L, texture=tex, texture_spacing=2.0)
    xs, ys, grid = texture_grid(tex, RIG.probe_box(), 2.0)
    g = pixel_geometry(RIG, *np.meshgrid(np.arange(64), np.arange(48)))
    interp = RegularGridInterpolator((ys, xs), grid, bounds_error=False, fill_value=None)
    pts = np.nan_to_num(g.points[..., [1, 0]])
    rho_d = np.where(g.in_probe[..., None], interp(pts), 0.0)
    ref = _jax(p, RIG, rho_d=rho_d)
    m = _compared(RIG) & g.in_probe
    np.testing.assert_allclose(rad[m], ref[m], rtol=1e-4)
    assert np.std(rad[m][:, 0] / ref[m][:, 0]) < 1e-5 and np.ptp(rho_d[m][:, 0]) > 0.2


@pytest.mark.slow
def test_07_jax_render_is_differentiable():
    """∂(image)/∂α and ∂(image)/∂lamp from jax.grad equal central differences."""
    rig = default_rig((16, 12))

    def total(alpha, lamp):
        p = wj.WardParams(rho_d=jnp.array([0.5, 0.4, 0.3]), rho_s=jnp.array(0.05), alpha_x=alpha, alpha_y=alpha)
        return jnp.sum(render_rig(p, rig, lamp_radiance=L, lamp_position=lamp, dtype=jnp.float64))

    with jax.enable_x64(True):
        a, lamp = jnp.array(0.1), jnp.array(rig.lamp, jnp.float64)
        ga, gl = jax.grad(total, argnums=(0, 1))(a, lamp)
        h = 1e-6
        fd_a = (total(a + h, lamp) - total(a - h, lamp)) / (2 * h)
        e = jnp.eye(3, dtype=jnp.float64)
        fd_l = jnp.stack([(total(a, lamp + 1e-3 * e[i]) - total(a, lamp - 1e-3 * e[i])) / 2e-3 for i in range(3)])
    np.testing.assert_allclose(float(ga), float(fd_a), rtol=1e-6)
    np.testing.assert_allclose(np.asarray(gl), np.asarray(fd_l), rtol=1e-5, atol=1e-9)
    assert abs(float(ga)) > 0
