"""The reconstruction ratio and its masks: hand-computed values."""

import numpy as np
import pytest

from wardjax.reconstruct import MaskReason, reconstruct_brdf, sample_bilinear


def test_formula_by_hand():
    # (0.50 − 0.10)/(0.30 − 0.05) · 0.99/π = 1.584/π = 0.504202859…
    f = reconstruct_brdf([[0.5, 0.5, 0.5]], [[0.1, 0.1, 0.1]], [[0.3, 0.3, 0.3]], [[0.05, 0.05, 0.05]], 0.99)
    np.testing.assert_allclose(f, np.full((1, 3), 1.6 * 0.99 / np.pi), rtol=1e-15)
    assert abs(f[0, 0] - 0.5042028597) < 1e-9


def test_per_channel_standard_and_no_background():
    # RGB standard, no dark frames: f = v / v_std · ρ/π per channel.
    f = reconstruct_brdf([0.2, 0.4, 0.6], None, [0.4, 0.4, 0.4], None, rho_standard=(0.5, 0.8, 1.0))
    np.testing.assert_allclose(f, [0.5 * 0.5 / np.pi, 1.0 * 0.8 / np.pi, 1.5 * 1.0 / np.pi], rtol=1e-15)


def test_a_perfect_diffuse_probe_equal_to_the_standard_gives_rho_over_pi():
    v = np.random.default_rng(1).uniform(0.2, 0.8, (5, 4, 3))
    f = reconstruct_brdf(v, 0.1 * v, v, 0.1 * v, 0.97)
    np.testing.assert_allclose(f, 0.97 / np.pi, rtol=1e-14)


def test_masks_each_reason():
    v = np.array([[0.5] * 3, [1.0, 0.5, 0.5], [0.5] * 3, [0.101] * 3, [0.5] * 3, [np.nan, 0.5, 0.5]])
    v_bg = np.full_like(v, 0.1)
    v_std = np.array([[0.3] * 3, [0.3] * 3, [0.3] * 3, [0.3] * 3, [0.1005] * 3, [0.3] * 3])
    v_std_bg = np.full_like(v, 0.1)
    on = np.array([True, True, False, True, True, True])
    f, flags = reconstruct_brdf(
        v, v_bg, v_std, v_std_bg, on_standard=on, saturation=0.999, noise_floor=0.002, return_flags=True
    )
    assert flags.dtype == np.uint8 and flags.shape == (6, 3)
    np.testing.assert_array_equal(flags[0], [0, 0, 0])
    np.testing.assert_allclose(f[0], 0.4 / 0.2 * 0.99 / np.pi)
    # row 1: red channel clipped only
    np.testing.assert_array_equal(flags[1], [MaskReason.SATURATED, 0, 0])
    assert np.isnan(f[1, 0]) and np.isfinite(f[1, 1:]).all()
    # row 2: mirror point off the standard, every channel
    np.testing.assert_array_equal(flags[2], [MaskReason.OFF_STANDARD] * 3)
    # row 3: probe signal 0.001 < floor 0.002; row 4: standard signal 0.0005 < floor
    np.testing.assert_array_equal(flags[3], [MaskReason.BELOW_NOISE] * 3)
    np.testing.assert_array_equal(flags[4], [MaskReason.BELOW_NOISE] * 3)
    # row 5: NaN input
    assert flags[5, 0] & MaskReason.NONFINITE and flags[5, 1] == 0
    assert np.all(np.isnan(f[flags != 0])) and np.all(np.isfinite(f[flags == 0]))


def test_known_saturated_mask_and_combined_reasons():
    f, flags = reconstruct_brdf(
        [[0.5] * 3],
        [[0.1] * 3],
        [[0.3] * 3],
        [[0.1] * 3],
        saturated=np.array([True]),
        on_standard=np.array([False]),
        return_flags=True,
    )
    np.testing.assert_array_equal(flags[0], [MaskReason.SATURATED | MaskReason.OFF_STANDARD] * 3)
    assert np.isnan(f).all()


def test_standard_below_its_dark_frame_is_masked_even_without_floor():
    _, flags = reconstruct_brdf([[0.5] * 3], [[0.1] * 3], [[0.1] * 3], [[0.2] * 3], return_flags=True)
    assert np.all(flags == MaskReason.BELOW_NOISE)


@pytest.mark.parametrize("rho", [0.0, 1.2, (0.9, 0.9)])
def test_bad_rho_standard(rho):
    with pytest.raises(ValueError, match="rho_standard"):
        reconstruct_brdf([0.5] * 3, None, [0.3] * 3, None, rho)


def test_bilinear_by_hand():
    img = np.zeros((2, 3, 1))
    img[..., 0] = [[0.0, 1.0, 2.0], [10.0, 11.0, 12.0]]
    clip = np.zeros((2, 3, 1), bool)
    clip[1, 2] = True
    out, anyclip = sample_bilinear(
        img, np.array([[0.5, 0.25], [2.0, 1.0], [1.5, 0.0], [3.5, 0.0], [np.nan, 0]]), reduce_max=clip
    )
    # (0.5, 0.25): row 0 → 0.5, row 1 → 10.5; 0.75·0.5 + 0.25·10.5 = 3.0
    np.testing.assert_allclose(out[:3, 0], [3.0, 12.0, 1.5])
    assert np.isnan(out[3:, 0]).all()
    np.testing.assert_array_equal(anyclip[:, 0], [False, True, True, False, False])
