"""Pinhole back-projection, mirror points and their pixels, irradiance: hand-computed cases."""

import numpy as np
import pytest

from wardjax.geometry import (
    Camera,
    Rig,
    back_project,
    irradiance_factor,
    mirror_point,
    pixel_geometry,
    project,
    to_material_frame,
)

# Camera at (0, −400, 300), 500 mm from the origin it looks at. Its axes, by hand:
# forward = (0, 0.8, −0.6); right = forward × z = (0.8, 0, 0)/0.8 = (1, 0, 0);
# down = forward × right = (0, −0.6, −0.8).
OBLIQUE = Camera(position=(0.0, -400.0, 300.0), look_at=(0.0, 0.0, 0.0), focal_px=500.0, image_size=(401, 301))
CX, CY = 200.0, 150.0


def test_axes_by_hand():
    np.testing.assert_allclose(OBLIQUE.axes(), [[1, 0, 0], [0, -0.6, -0.8], [0, 0.8, -0.6]], atol=1e-15)


def test_principal_point_sees_the_look_at_point():
    p, hit = back_project(OBLIQUE, CX, CY)
    assert hit
    np.testing.assert_allclose(p, [0, 0, 0], atol=1e-12)


def test_back_project_by_hand():
    # Pixel (cx + 100, cy): ray = 0.2·right + forward = (0.2, 0.8, −0.6); t = 300/0.6 = 500
    # → P = (0, −400, 300) + 500 (0.2, 0.8, −0.6) = (100, 0, 0).
    p, _ = back_project(OBLIQUE, CX + 100, CY)
    np.testing.assert_allclose(p, [100, 0, 0], atol=1e-12)
    # Pixel (cx, cy + 100): ray = 0.2·down + forward = (0, 0.68, −0.76); t = 300/0.76
    # → y = −400 + 0.68·300/0.76 = −131.578947…
    p, _ = back_project(OBLIQUE, CX, CY + 100)
    np.testing.assert_allclose(p, [0, -400 + 0.68 * 300 / 0.76, 0], atol=1e-12)


def test_ray_above_the_horizon_misses():
    # Far enough up the image the ray points above the horizon (d_z ≥ 0): no hit, NaN point.
    p, hit = back_project(OBLIQUE, CX, CY - 500 * 0.6 / 0.8 - 1)
    assert not hit and np.all(np.isnan(p))


def test_project_inverts_back_project(rng):
    u = rng.uniform(0, 400, 50)
    v = rng.uniform(60, 300, 50)
    p, hit = back_project(OBLIQUE, u, v)
    assert hit.all()
    uv, front = project(OBLIQUE, p)
    assert front.all()
    np.testing.assert_allclose(uv, np.stack([u, v], -1), atol=1e-9)


def test_mirror_point_and_pixel_by_hand():
    np.testing.assert_array_equal(mirror_point([[3.0, -2.0, 0.0]]), [[-3.0, -2.0, 0.0]])
    rig = Rig(lamp=(0.0, 400.0, 300.0), camera=OBLIQUE)
    g = pixel_geometry(rig, np.array([CX + 100]), np.array([CY]))
    # P = (100, 0, 0) → mirror (−100, 0, 0) → by the symmetry, pixel (cx − 100, cy).
    np.testing.assert_allclose(g.mirror_points[0], [-100, 0, 0], atol=1e-12)
    np.testing.assert_allclose(g.mirror_pixels[0], [CX - 100, CY], atol=1e-9)
    assert g.in_probe[0] and not g.in_standard[0] and g.mirror_ok[0]
    # wi = (lamp − P)/|lamp − P| = (−100, 400, 300)/√260000; wo = (−100, −400, 300)/√260000
    r = np.sqrt(260000.0)
    np.testing.assert_allclose(g.wi[0], np.array([-100, 400, 300]) / r, atol=1e-12)
    np.testing.assert_allclose(g.wo[0], np.array([-100, -400, 300]) / r, atol=1e-12)
    np.testing.assert_allclose(g.dist_lamp[0], r)
    # E = z_L / r³
    np.testing.assert_allclose(g.irradiance[0], 300 / r**3)


def test_mirror_off_the_standard_or_the_image():
    # A standard only 50 mm wide: the mirror of x = 100 lies off it.
    rig = Rig(lamp=(0.0, 400.0, 300.0), camera=OBLIQUE, probe=(0, 200, -100, 100), standard=(-50, 0, -100, 100))
    g = pixel_geometry(rig, np.array([CX + 100, CX + 40]), np.array([CY, CY]))
    assert list(g.mirror_ok) == [False, True]
    # A camera off the symmetry plane: the mirror pixel of the right edge falls outside the image.
    cam = Camera(position=(150.0, -400.0, 300.0), look_at=(150.0, 0.0, 0.0), focal_px=500.0, image_size=(401, 301))
    g = pixel_geometry(Rig(lamp=(0.0, 400.0, 300.0), camera=cam), np.array([CX + 100]), np.array([CY]))
    np.testing.assert_allclose(g.points[0], [250, 0, 0], atol=1e-9)
    assert g.mirror_pixels[0, 0] < 0 and not g.mirror_ok[0]


def test_overhead_camera_mirror_is_column_reflection():
    cam = Camera(
        position=(0.0, 0.0, 500.0), look_at=(0.0, 0.0, 0.0), focal_px=500.0, image_size=(201, 101), up=(0.0, 1.0, 0.0)
    )
    u = np.arange(101.0, 201.0)
    g = pixel_geometry(Rig(lamp=(0.0, 300.0, 400.0), camera=cam), u, np.full_like(u, 50.0))
    np.testing.assert_allclose(g.points[:, 0], u - 100.0, atol=1e-12)  # 1 px = 1 mm at 500 mm, f = 500
    np.testing.assert_allclose(g.mirror_pixels[:, 0], 200.0 - u, atol=1e-9)


def test_irradiance_is_symmetric():
    pts = np.array([[37.0, -12.0, 0.0]])
    np.testing.assert_allclose(
        irradiance_factor(pts, (0, 250, 400)), irradiance_factor(mirror_point(pts), (0, 250, 400))
    )


def test_material_frame_rotation():
    w = np.array([[0.6, 0.0, 0.8]])
    np.testing.assert_allclose(to_material_frame(w, (0.0, 2.0)), [[0.0, -0.6, 0.8]], atol=1e-15)
    np.testing.assert_array_equal(to_material_frame(w, (1.0, 0.0)), w)


def test_camera_validation():
    with pytest.raises(ValueError, match="coincides"):
        Camera((0, 0, 1), (0, 0, 1), 100.0, (10, 10)).axes()
    with pytest.raises(ValueError, match="parallel"):
        Camera((0, 0, 1), (0, 0, 0), 100.0, (10, 10)).axes()


@pytest.mark.parametrize("dtype, tol_mm, tol_px", [(np.float64, 1e-9, 1e-9), (np.float32, 2e-3, 2e-3)])
def test_band_geometry_is_pixel_geometry(dtype, tol_mm, tol_px):
    # The band geometry the pipeline's compiled kernels fuse (band_geometry_jnp) computes what
    # pixel_geometry + to_material_frame do, for whole rows and for a window of columns.
    import jax
    import jax.numpy as jnp

    from wardjax.geometry import band_geometry_jnp, rig_constants

    rig = Rig(
        lamp=(0.0, 300.0, 400.0),
        camera=OBLIQUE,
        probe=(3.0, 120.0, -150.0, 150.0),
        standard=(-120.0, -3.0, -150.0, 150.0),
    )
    rows = np.arange(0, 301, 7)
    u, v = np.meshgrid(np.arange(401, dtype=float), rows.astype(float))
    ref = pixel_geometry(rig, u, v)
    kernel = jax.jit(band_geometry_jnp, static_argnames=("width", "height", "ncols"))
    with jax.enable_x64(dtype == np.float64):
        k = jnp.asarray(rig_constants(rig, (0.6, 0.8)), dtype)
        r = jnp.asarray(rows, dtype)
        got = jax.tree_util.tree_map(np.asarray, kernel(k, r, width=401, height=301))
        window = jax.tree_util.tree_map(
            np.asarray, kernel(k, r, col0=jnp.asarray(150, dtype), width=401, height=301, ncols=100)
        )
    assert got.points.dtype == dtype and got.points.shape == (len(rows), 401, 3)
    hit = np.isfinite(ref.points[..., 0])
    np.testing.assert_array_equal(np.isfinite(got.points[..., 0]), hit)
    np.testing.assert_allclose(got.points[hit], ref.points[hit], atol=tol_mm)
    for name in ("wi", "wo"):
        want = np.where(hit[..., None], to_material_frame(getattr(ref, name), (0.6, 0.8)), 0.0)
        np.testing.assert_allclose(getattr(got, name), want, atol=10 * np.finfo(dtype).eps)
    for name in ("in_probe", "in_standard", "mirror_ok"):
        np.testing.assert_array_equal(getattr(got, name), getattr(ref, name), err_msg=name)
    ok = ref.mirror_ok
    assert ok.sum() > 1000
    np.testing.assert_allclose(got.mirror_pixels[ok], ref.mirror_pixels[ok], atol=tol_px)
    for name in got._fields:  # columns 150 … 249: the same values
        np.testing.assert_array_equal(getattr(window, name), getattr(got, name)[:, 150:250], err_msg=name)
