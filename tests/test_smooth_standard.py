"""The standard's smoothing: the plane fitted only on the tiles along the mask's edge equals the plane everywhere."""

from unittest import mock

import numpy as np
import pytest

from wardjax.reconstruct import _smooth
from wardjax.reconstruct._smooth import _kernels, _plane_levels, smooth_on


@pytest.mark.parametrize(
    ("shape", "sigma", "tile", "holes", "tiled"),
    [
        ((500, 700), 1.5, 32, 0.0, True),  # a large standard: the plane on the edge tiles only
        ((500, 700), 2.0, 48, 0.0, True),
        ((61, 83), 1.5, 16, 0.0, False),  # a small one: edge tiles cover most of it
        ((200, 260), 0.7, 7, 0.02, False),  # clipped specks put edges everywhere
    ],
)
def test_tiled_plane_equals_the_plane_over_the_whole_image(shape, sigma, tile, holes, tiled):
    """Ragged masks, with or without clipped holes, tiles that do not divide the image: inside the mask the
    smoothing is the whole-image first-order fit to float32 rounding, whichever way it is computed; outside it the
    image is kept."""
    rng = np.random.default_rng(3)
    h, w = shape
    y, x = np.mgrid[0:h, 0:w].astype(float)
    img = (0.4 * (1 + 0.01 * x - 0.008 * y))[..., None] * np.array([1.0, 0.9, 0.8])
    img = (img + 0.01 * rng.standard_normal(img.shape)).astype(np.float32)
    mask = (x >= 5 + 3 * np.sin(y / 7)) & (x <= w - 6) & (y >= 4) & (y <= h - 5)
    mask &= rng.random((h, w)) >= holes
    whole = _plane_levels(img, mask, sigma, _kernels(sigma))
    with mock.patch.object(_smooth, "_plane_levels", wraps=_smooth._plane_levels) as spy:
        out = smooth_on(img, mask, sigma, tile=tile)
    assert (spy.call_count > 1) == tiled
    np.testing.assert_allclose(out[mask], whole[mask], rtol=0, atol=1e-6)
    np.testing.assert_array_equal(out[~mask], img[~mask])


def test_kernels_are_scipys_gaussian_derivatives():
    """The cached kernels give what :func:`scipy.ndimage.gaussian_filter` gives for orders 0–2 on each axis."""
    from scipy.ndimage import gaussian_filter

    f = np.random.default_rng(0).standard_normal((30, 40)).astype(np.float32)
    k = _kernels(1.5)
    for order in ((0, 0), (1, 0), (0, 1), (2, 0), (0, 2), (1, 1)):
        ref = gaussian_filter(f, 1.5, order=order, mode="constant")  # pyright: ignore[reportArgumentType]
        np.testing.assert_allclose(_smooth._gauss(f, k, order), ref, rtol=0, atol=1e-6)
