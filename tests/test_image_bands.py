"""Images read in bands: a TIFF's windows equal tifffile's whole read, a banded fit equals the whole-image fit,
and the fit path never decodes a whole image.

The references are independent of the banded reader: ``tifffile.imread`` (the
whole page through tifffile's own assembly of strips and tiles) for the
windows, and the same capture saved as 16-bit PNG, which is decoded whole at
load, for the fit.
"""

import functools
import shutil

import imagecodecs
import numpy as np
import pytest
import tifffile
import tomlkit
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import wardjax as wj
from wardjax.capture import CaptureError, CaptureImages, _images
from wardjax.capture._images import ArrayImage, TiffImage, open_image
from wardjax.run import _batch, _fit_capture
from wardjax.simulate import SensorNoise

PROBE = wj.WardParams(rho_d=(0.42, 0.38, 0.30), rho_s=0.06, alpha_x=0.12, alpha_y=0.12)

# layouts a camera or an editor writes: (tifffile.imwrite options, read in bands without decoding all)
LAYOUTS = {
    "one_strip": {},
    "strips": {"rowsperstrip": 7},
    "zlib_strips": {"compression": "zlib", "rowsperstrip": 5},
    "lzw_predictor": {"compression": "lzw", "predictor": True, "rowsperstrip": 4},
    "zlib_tiles": {"compression": "zlib", "tile": (16, 16)},
    "big_endian": {"byteorder": ">", "rowsperstrip": 9},
}


def _codes(rng, shape, dtype):
    return rng.integers(0, np.iinfo(dtype).max, shape, endpoint=True).astype(dtype)


@pytest.mark.parametrize("layout", sorted(LAYOUTS))
@pytest.mark.parametrize(("channels", "dtype"), [(3, np.uint16), (1, np.uint8), (4, np.uint16)])
def test_tiff_windows_equal_the_whole_read(tmp_path, rng, layout, channels, dtype):
    shape = (45, 37) if channels == 1 else (45, 37, channels)
    a = _codes(rng, shape, dtype)
    path = tmp_path / "i.tif"
    tifffile.imwrite(path, a, photometric="rgb" if channels > 1 else "minisblack", **LAYOUTS[layout])
    whole = tifffile.imread(path)
    rgb = np.repeat(whole[..., None], 3, -1) if whole.ndim == 2 else whole[..., :3]
    src = open_image(path, "i.tif")
    assert isinstance(src, TiffImage) and src.banded and src.decoded_pixels == 0  # only the header was read
    assert (src.height, src.width, src.channels, src.dtype) == (45, 37, channels, np.dtype(dtype))
    windows = [(slice(0, 45), slice(0, 37)), (slice(3, 20), slice(5, 36)), (slice(44, 45), slice(17, 18))]
    windows += [(slice(15, 33), slice(None)), (slice(10, 10), slice(0, 37)), (slice(30, 99), slice(20, None))]
    for rows, cols in windows:
        got = src.read(rows, cols)
        assert got.dtype == np.dtype(dtype) and got.flags.writeable
        np.testing.assert_array_equal(got, rgb[rows, cols], err_msg=f"{rows} {cols}")
    assert src.extremes() == (int(rgb.min()), int(rgb.max()))
    # a window decodes its own rows (rounded out to whole segments), not the image
    src.largest_read = 0
    src.read(slice(20, 22), slice(0, 37))
    seg_rows = {"one_strip": 0, "strips": 7, "zlib_strips": 5, "lzw_predictor": 4, "zlib_tiles": 16}.get(layout, 9)
    assert 0 < src.largest_read <= (2 + 2 * seg_rows) * 37 + 2 * 16 * 16


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(
    size=st.tuples(st.integers(1, 40), st.integers(1, 40)),
    layout=st.one_of(
        st.fixed_dictionaries({"rowsperstrip": st.integers(1, 45)}),
        st.fixed_dictionaries({"rowsperstrip": st.integers(1, 45), "compression": st.sampled_from(["zlib", "lzw"])}),
        st.fixed_dictionaries(
            {"tile": st.sampled_from([(16, 16), (16, 32), (32, 16)]), "compression": st.just("zlib")}
        ),
    ),
    window=st.tuples(st.integers(0, 45), st.integers(0, 45), st.integers(0, 45), st.integers(0, 45)),
)
def test_any_tiff_window_equals_the_whole_read(tmp_path, size, layout, window):
    a = np.arange(size[0] * size[1] * 3, dtype=np.uint16).reshape(*size, 3) * 7
    path = tmp_path / "f.tif"
    tifffile.imwrite(path, a, photometric="rgb", **layout)
    src = open_image(path, "f.tif")
    assert isinstance(src, TiffImage)
    rows, cols = slice(*sorted(window[:2])), slice(*sorted(window[2:]))
    np.testing.assert_array_equal(src.read(rows, cols), tifffile.imread(path)[rows, cols])


def test_tiff_layouts_outside_bands_are_read_whole(tmp_path, rng):
    a = _codes(rng, (3, 20, 30), np.uint16)
    tifffile.imwrite(tmp_path / "planar.tif", a, photometric="rgb", planarconfig="separate")
    tifffile.imwrite(tmp_path / "pages.tif", _codes(rng, (2, 20, 30, 3), np.uint16), photometric="rgb")
    tifffile.imwrite(tmp_path / "float.tif", rng.uniform(size=(20, 30, 3)).astype(np.float32), photometric="rgb")
    # the whole-image reader takes them: a planar-configuration RGB TIFF is an RGB image (its planes
    # moved last); a stack of pages is not one image
    assert isinstance(open_image(tmp_path / "float.tif", "float.tif"), ArrayImage)
    assert isinstance(open_image(tmp_path / "planar.tif", "planar.tif"), ArrayImage)
    with pytest.raises(ValueError, match="expected an RGB image"):
        open_image(tmp_path / "pages.tif", "pages.tif")


def _simulate(folder, size=(96, 72)):
    return wj.simulate_capture(
        PROBE,
        folder,
        seed=4,
        image_size=size,
        texture="wood",
        encoding="linear",
        bit_depth=16,
        image_format="tif",
        noise=SensorNoise(0.002, 0.0005),
    )


def _rewrite(folder, suffix, **tiff_options) -> None:
    """The capture's images written again (same codes) as ``suffix``, ``capture.toml`` pointing at them."""
    doc = tomlkit.parse((folder / "capture.toml").read_text())
    for role in ("lit", "dark"):
        old = folder / str(doc["images"][role])
        codes = tifffile.imread(old)
        new = old.with_suffix(suffix)
        if suffix == ".png":
            new.write_bytes(imagecodecs.png_encode(codes))
        else:
            new = old.with_name(f"{old.stem}-b.tif")
            tifffile.imwrite(new, codes, photometric="rgb", **tiff_options)
        doc["images"][role] = new.name
        old.unlink()
    (folder / "capture.toml").write_text(tomlkit.dumps(doc))


@pytest.fixture(scope="module")
def captures(tmp_path_factory):
    """One simulated 16-bit TIFF capture, as written (one strip), as zlib tiles, and as 16-bit PNG (read whole)."""
    base = tmp_path_factory.mktemp("bands")
    _simulate(base / "tif")
    shutil.copytree(base / "tif", base / "tiles")
    _rewrite(base / "tiles", ".tif", compression="zlib", tile=(16, 16))
    shutil.copytree(base / "tif", base / "png")
    _rewrite(base / "png", ".png")
    return base


@pytest.mark.slow
@pytest.mark.parametrize("layout", ["tif", "tiles"])
def test_a_banded_fit_equals_the_whole_image_fit(captures, layout):
    whole = wj.load_capture(captures / "png")
    banded = wj.load_capture(captures / layout)
    assert isinstance(whole, wj.Capture) and isinstance(banded, wj.Capture)
    assert not whole.images.banded and banded.images.banded
    ref = _fit_capture.fit_capture(whole)
    got = _fit_capture.fit_capture(banded, band_rows=24)  # bands of 24 rows: several, the last ragged
    for name in ("rho_d", "rho_s", "alpha_x", "alpha_y"):
        np.testing.assert_allclose(getattr(got.params, name), getattr(ref.params, name), rtol=1e-9, err_msg=name)
        np.testing.assert_allclose(getattr(got.stderr, name), getattr(ref.stderr, name), rtol=1e-6, err_msg=name)
    np.testing.assert_allclose(got.rho_d, ref.rho_d, rtol=1e-6, atol=1e-7)
    np.testing.assert_array_equal(got.flags, ref.flags)
    np.testing.assert_array_equal(got.probe, ref.probe)
    assert got.diagnostics["pixels"] == ref.diagnostics["pixels"]
    # and the material is the one simulated (the comparison is not of two broken fits)
    assert abs(float(ref.params.alpha_x) - PROBE.alpha_x) < 0.02 and np.isfinite(ref.rho_d).any()
    # the whole images the Capture still offers are the PNG's
    np.testing.assert_array_equal(banded.lit, whole.lit)
    np.testing.assert_array_equal(banded.lit_clipped, whole.lit_clipped)
    assert banded.dark is not None and whole.dark is not None
    np.testing.assert_array_equal(banded.dark, whole.dark)


def test_the_fit_path_never_decodes_a_whole_image(captures, tmp_path, monkeypatch):
    # wardjax.run.fit_one (load, reconstruct in bands, bin, fit, texture band by band, outputs) on a
    # compressed tiled capture: every read is a window of a band's rows or the standard's crop, and the
    # whole-image arrays (Capture.lit, .dark, .lit_clipped) are never built.
    from wardjax.run import fit_one

    reads = []
    read = TiffImage.read

    def counted(self, rows, cols=slice(None)):
        before = self.decoded_pixels
        out = read(self, rows, cols)
        reads.append((self.name, out.shape[:2], self.decoded_pixels - before))
        return out

    def whole(self, which):
        raise AssertionError(f"the whole {which} image was built")

    band_rows = 24
    monkeypatch.setattr(TiffImage, "read", counted)
    monkeypatch.setattr(CaptureImages, "whole", whole)
    monkeypatch.setattr(_images, "_STATS_ROWS", band_rows)  # the load checks' bands
    monkeypatch.setattr(_batch, "fit_capture", functools.partial(_fit_capture.fit_capture, band_rows=band_rows))
    item, tb = fit_one(captures / "tiles", "c", tmp_path / "out", "2026-11-26T00:00:00Z", force=True)
    assert item.status == "ok", (item.error, tb)
    h, w = 72, 96
    assert reads and all(n < h * w for _, _, n in reads)  # no read decoded a whole image
    # band reads: at most a band's rows plus the 16-row tiles around them
    bands = [n for _, (rows, cols), n in reads if rows <= band_rows]
    assert max(bands) <= (band_rows + 2 * 16) * w
    # every image was decoded about once per pass (load checks, clip count, binning, texture), not more
    lit = sum(n for name, _, n in reads if name.startswith("lit"))
    assert lit <= 6 * h * w


def _fresh_tiff_capture(captures, tmp_path, name="c"):
    folder = tmp_path / name
    shutil.copytree(captures / "tif", folder)
    doc = tomlkit.parse((folder / "capture.toml").read_text())
    return folder, str(doc["images"]["lit"]), str(doc["images"]["dark"])


@pytest.mark.parametrize(
    ("change", "word"),
    [
        (lambda a: a[:40], "96×40 pixels"),
        (lambda a: a[..., :1], "1 channel(s)"),
        (lambda a: (a >> 8).astype(np.uint8), "holds uint8 values"),
    ],
)
def test_a_dark_tiff_that_does_not_match_is_refused_from_its_header(captures, tmp_path, monkeypatch, change, word):
    folder, _, dark = _fresh_tiff_capture(captures, tmp_path)
    codes = change(tifffile.imread(folder / dark))
    tifffile.imwrite(folder / dark, codes, photometric="rgb" if codes.shape[-1] == 3 else "minisblack")
    decoded = []
    read = TiffImage.read
    monkeypatch.setattr(TiffImage, "read", lambda self, *a: (decoded.append(self.name), read(self, *a))[1])
    with pytest.raises(CaptureError) as info:
        wj.load_capture(folder)
    assert info.value.file == dark and word in str(info.value) and "\n" not in str(info.value)
    assert dark not in decoded  # refused from the header: none of its pixels was decoded


def test_a_truncated_tiff_is_refused_at_load(captures, tmp_path):
    for layout, options in (("strips", {}), ("tiles", {"compression": "zlib", "tile": (16, 16)})):
        folder, lit, _ = _fresh_tiff_capture(captures, tmp_path, layout)
        codes = tifffile.imread(folder / lit)
        tifffile.imwrite(folder / lit, codes, photometric="rgb", **options)
        data = (folder / lit).read_bytes()
        # the header and the first segments stay; the last rows are gone
        cut = len(data) - 4000 if layout == "strips" else int(len(data) * 0.8)
        (folder / lit).write_bytes(data[:cut])
        with pytest.raises(CaptureError) as info:
            wj.load_capture(folder)
        assert info.value.file == lit and "cannot read the image" in str(info.value), str(info.value)
