"""Big captures: the pieces that keep a 50 MP fit's memory bounded give the results of the whole-image path.

The memory figures themselves (12 MP and 50 MP, peak RSS and time) come from
``benchmarks/big_capture.py`` (docs/benchmarks.md); these tests check that
streaming changes nothing but memory.
"""

import numpy as np
import pytest

from wardjax._files import write_image
from wardjax.reconstruct import Reconstruction, ScanlineBinner, bin_layout, bin_scanlines
from wardjax.texture import analyze_texture


def _reconstruction(rng, h=70, w=53, clip=True) -> Reconstruction:
    """A reconstruction-shaped set of arrays: an elliptic probe, values with NaN holes and clip bounds."""
    yy, xx = np.mgrid[:h, :w]
    probe = ((yy - 33) / 30.0) ** 2 + ((xx - 27) / 22.0) ** 2 < 1
    f_r = rng.uniform(0.1, 0.3, (h, w, 3)).astype(np.float32)
    f_r[~probe] = np.nan
    f_r[rng.uniform(size=(h, w)) < 0.15] = np.nan
    f_clip = np.where(np.isnan(f_r) & probe[..., None] & (rng.uniform(size=(h, w, 1)) < 0.5), 0.4, np.nan)
    d = rng.normal(size=(2, h, w, 3)) + [0, 0, 3]
    d /= np.linalg.norm(d, axis=-1, keepdims=True)
    wi, wo = (np.where(probe[..., None], x, 0).astype(np.float32) for x in d)
    points = np.where(probe[..., None], rng.normal(size=(h, w, 3)), np.nan).astype(np.float32)
    flags = np.zeros((h, w), np.uint8)
    return Reconstruction(f_r, flags, wi, wo, points, probe, f_clip.astype(np.float32) if clip else None)


@pytest.mark.parametrize("clip", [True, False])
@pytest.mark.parametrize("step_bins", [1, 3])
def test_bins_fed_band_by_band_equal_the_whole_image_bins(rng, clip, step_bins):
    # fit_capture bins each band of the reconstruction as it comes (ScanlineBinner) instead of the whole
    # image (bin_scanlines): the same bins, bands of whole bins and a ragged last band included.
    rec = _reconstruction(rng, clip=clip)
    whole = bin_scanlines(rec, max_samples=200)
    box, b = bin_layout(rec.probe, 200)
    assert b > 1 and (box[0].stop - box[0].start) % (b * step_bins) != 0  # a ragged last band
    binner = ScanlineBinner(rec.probe, box, b)
    cols = box[1]
    for r0 in range(box[0].start, box[0].stop, b * step_bins):
        rows = slice(r0, min(r0 + b * step_bins, box[0].stop))
        sl = (rows, cols)
        binner.add(rows, rec.f_r[sl], rec.wi[sl], rec.wo[sl], rec.points[sl], None if not clip else rec.f_clip[sl])
    banded = binner.result()
    assert banded.b == whole.b and banded.box == whole.box
    for name in ("f_r", "censored", "wi", "wo", "points"):
        np.testing.assert_array_equal(getattr(banded, name), getattr(whole, name), err_msg=name)
    assert np.isfinite(whole.f_r).sum() > 30 and (whole.censored.any() == clip)


def test_texture_analysis_of_a_big_region_keeps_its_centred_part(rng):
    # write_capture_outputs analyses at most 2048 pixels a side (max_side): the centred part of the region,
    # said in region_source; the model is that of analysing that part as the region.
    img = rng.uniform(0.2, 0.6, (80, 150, 3))
    img[:5] = np.nan  # the largest valid rectangle is rows 5:80
    capped = analyze_texture(img, max_side=64, height=2)
    assert capped.region == (5 + 5, 5 + 5 + 64, 43, 43 + 64)
    assert capped.region_source == "largest valid rectangle, centred 64x64 part"
    direct = analyze_texture(img, region=capped.region, height=2)
    np.testing.assert_array_equal(capped.band_quantiles, direct.band_quantiles)
    np.testing.assert_array_equal(capped.pixel_quantiles, direct.pixel_quantiles)
    assert analyze_texture(img, max_side=200, height=2).region == (5, 80, 0, 150)  # small enough: untouched


def test_tiled_tiff_holds_the_image(tmp_path, rng):
    import tifffile

    a = rng.uniform(size=(300, 520, 3)).astype(np.float32)
    a[7, 9] = np.nan
    write_image(tmp_path / "t.tif", a, tile=256)
    with tifffile.TiffFile(tmp_path / "t.tif") as tf:
        page = tf.pages[0]
        assert page.is_tiled and (page.tilelength, page.tilewidth) == (256, 256)
        np.testing.assert_array_equal(page.asarray(), a)
