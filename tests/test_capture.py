"""The capture folder: schema validation, image I/O, encodings, and a corpus of broken captures.

Every broken capture must give exactly one clear error naming the file and
the field or value, from the library (``CaptureError``) and from the CLI
(one ``error:`` line, exit status 2, no traceback).
"""

import shutil
import tomllib
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

import wardjax as wj
from wardjax._files import decode_values, encode_image, encode_values, read_image
from wardjax.capture import CaptureError, load_capture
from wardjax.run import main
from wardjax.simulate import SensorNoise, write_capture_toml

PROBE = wj.WardParams(rho_d=(0.5, 0.45, 0.4), rho_s=0.04, alpha_x=0.12, alpha_y=0.12)


@pytest.fixture(scope="module")
def good(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("good") / "cap"
    wj.simulate_capture(PROBE, folder, seed=3, image_size=(64, 48))
    return folder


def _toml(folder: Path) -> dict:
    return tomllib.loads((folder / "capture.toml").read_text())


def _edit(**changes):
    """A case that sets dotted fields (value None deletes the field)."""

    def apply(folder: Path):
        cfg = _toml(folder)
        for dotted, value in changes.items():
            keys = dotted.split("__")
            d = cfg
            for k in keys[:-1]:
                d = d[k]
            if value is None:
                del d[keys[-1]]
            else:
                d[keys[-1]] = value
        write_capture_toml(folder / "capture.toml", cfg)

    return apply


def _raw(text: str):
    def apply(folder: Path):
        (folder / "capture.toml").write_text(text)

    return apply


def _replace_text(old: str, new: str):
    def apply(folder: Path):
        p = folder / "capture.toml"
        t = p.read_text()
        assert old in t
        p.write_text(t.replace(old, new))

    return apply


def _delete(name: str):
    return lambda folder: (folder / name).unlink()


def _write_bytes(name: str, data):
    def apply(folder: Path):
        p = folder / name
        p.write_bytes(data(p.read_bytes()) if callable(data) else data)

    return apply


def _write_png(name: str, make):
    def apply(folder: Path):
        import imagecodecs

        img = read_image(folder / name)
        (folder / name).write_bytes(imagecodecs.png_encode(make(folder, img)))

    return apply


BROKEN = {
    # id: (change, file named in the error, text the error must contain)
    "no_capture_toml": (_delete("capture.toml"), "capture.toml", "missing"),
    "toml_syntax": (_raw("method = \n"), "capture.toml", "not valid TOML"),
    "empty_toml": (_raw(""), "capture.toml", "method: required field is missing"),
    "missing_method": (_edit(method=None), "capture.toml", "method: required field is missing"),
    "unknown_method": (_edit(method="laser"), "capture.toml", "method:"),
    # a scanline capture relabelled: the smartphone schema wants [photo], not [images]
    "scanline_as_smartphone": (_edit(method="smartphone"), "capture.toml", "photo: required field is missing"),
    "missing_section": (_edit(camera=None), "capture.toml", "camera: required field is missing"),
    "missing_field": (_edit(images__encoding=None), "capture.toml", "images.encoding: required field is missing"),
    "extra_field": (_edit(camera__focal=500.0), "capture.toml", "camera.focal: unknown field"),
    "extra_top_level": (_edit(rho_standrad=0.99), "capture.toml", "rho_standrad: unknown field"),
    "mistyped_focal": (_edit(camera__focal_px="wide"), "capture.toml", "camera.focal_px:"),
    "negative_focal": (_edit(camera__focal_px=-5.0), "capture.toml", "camera.focal_px: Input should be greater than 0"),
    "nan_in_lamp": (
        _replace_text("lamp = [0.0, 300.0", "lamp = [0.0, nan"),
        "capture.toml",
        "rig.lamp[1]: Input should be a finite number",
    ),
    "inf_in_camera": (
        _replace_text("camera = [0.0, -300.0, 400.0]", "camera = [0.0, -300.0, inf]"),
        "capture.toml",
        "rig.camera[2]: Input should be a finite number",
    ),
    "nan_noise_floor": (_replace_text("noise_floor = 0.002", "noise_floor = nan"), "capture.toml", "fit.noise_floor:"),
    "short_vector": (_edit(rig__lamp=[0.0, 300.0]), "capture.toml", "rig.lamp"),
    "lamp_off_plane": (
        _edit(rig__lamp=[50.0, 300.0, 400.0]),
        "capture.toml",
        "rig.lamp: the lamp must lie in the plane x = 0",
    ),
    "camera_below": (_edit(rig__camera=[0.0, -300.0, -10.0]), "capture.toml", "rig.camera: the camera must be above"),
    "look_at_is_position": (_edit(camera__look_at=[0.0, -300.0, 400.0]), "capture.toml", "camera.look_at:"),
    "principal_outside": (_edit(camera__principal_point=[500.0, 10.0]), "capture.toml", "camera.principal_point:"),
    "bad_encoding": (_edit(images__encoding="rgb"), "capture.toml", "images.encoding:"),
    "bad_bit_depth": (_edit(images__bit_depth=12), "capture.toml", "images.bit_depth:"),
    "rho_standard_too_big": (_edit(rho_standard=1.5), "capture.toml", "rho_standard"),
    "probe_wrong_side": (
        _edit(regions__probe=[-100.0, -3.0, -150.0, 150.0]),
        "capture.toml",
        "regions.probe: must lie at x ≥ 0",
    ),
    "zero_tangent": (_edit(material__tangent=[0.0, 0.0]), "capture.toml", "material.tangent:"),
    "image_path_escapes": (_edit(images__lit="../lit.png"), "capture.toml", "images.lit:"),
    "missing_image": (_delete("lit.png"), "lit.png", "image file is missing"),
    "missing_dark": (_delete("dark.png"), "dark.png", "image file is missing"),
    "corrupt_image": (_write_bytes("lit.png", b"this is not a PNG file at all"), "lit.png", "cannot read the image"),
    "truncated_image": (_write_bytes("lit.png", lambda b: b[: len(b) // 2]), "lit.png", "cannot read the image"),
    "unsupported_type": (
        lambda f: (shutil.copy(f / "lit.png", f / "lit.bmp"), _edit(images__lit="lit.bmp")(f)),
        "capture.toml",
        "images.lit: unsupported image type",
    ),
    "dark_size_mismatch": (_write_png("dark.png", lambda f, im: im[:40, :60]), "dark.png", "is 60×40 pixels"),
    "image_size_mismatch": (_edit(camera__image_size=[100, 80]), "lit.png", "camera.image_size = [100, 80]"),
    "bit_depth_mismatch": (_edit(images__bit_depth=16), "lit.png", "images.bit_depth = 16"),
    "camera_misses_probe": (
        _edit(camera__look_at=[0.0, -5000.0, 0.0]),
        "capture.toml",
        "camera: no pixel of the image sees the probe",
    ),
    "all_saturated": (
        _write_png("lit.png", lambda f, im: np.full_like(im, 255)),
        "lit.png",
        "every pixel is saturated",
    ),
    "all_dark": (lambda f: shutil.copy(f / "dark.png", f / "lit.png"), "lit.png", "below the noise floor"),
}


def _make(good: Path, tmp_path: Path, case: str) -> Path:
    folder = tmp_path / case
    shutil.copytree(good, folder)
    BROKEN[case][0](folder)
    return folder


def test_corpus_is_big_enough():
    assert len(BROKEN) >= 20


@pytest.mark.parametrize("case", sorted(BROKEN))
def test_broken_capture_gives_one_clear_error(good, tmp_path, case):
    folder = _make(good, tmp_path, case)
    _, file, text = BROKEN[case]
    with pytest.raises(CaptureError) as info:
        wj.fit_capture(load_capture(folder))
    msg = str(info.value)
    assert "\n" not in msg
    assert msg.startswith(f"{file}: "), msg
    assert text in msg, msg
    assert info.value.file == file


@pytest.mark.parametrize(
    "case",
    [
        "no_capture_toml",
        "nan_in_lamp",
        "corrupt_image",
        "dark_size_mismatch",
        "all_saturated",
        "all_dark",
        "camera_misses_probe",
        "scanline_as_smartphone",
    ],
)
def test_cli_reports_one_line_without_traceback(good, tmp_path, case):
    folder = _make(good, tmp_path, case)
    res = CliRunner().invoke(main, ["fit", str(folder), "--out", str(tmp_path / "out"), "--quiet"])
    assert res.exit_code == 2
    err_lines = [ln for ln in res.stderr.splitlines() if ln.strip()]
    assert len(err_lines) == 1, res.stderr
    assert err_lines[0].startswith("error: ") and BROKEN[case][2] in err_lines[0]
    assert "Traceback" not in res.output + res.stderr
    assert isinstance(res.exception, SystemExit)


def test_good_capture_loads(good):
    cap = load_capture(good)
    assert cap.method == "scanline" and cap.name == "cap"
    assert cap.lit.shape == (48, 64, 3) and cap.lit.dtype == np.float32
    assert cap.dark is not None and not cap.lit_clipped.any()
    assert set(cap.checksums) == {"capture.toml", "lit.png", "dark.png"}
    assert all(v.startswith("sha256:") and len(v) == 71 for v in cap.checksums.values())
    assert cap.config.fit.model == "isotropic"  # αx == αy in the simulation


@pytest.mark.parametrize("encoding", ["srgb", "gamma2.2", "linear"])
def test_encodings_invert(encoding):
    x = np.linspace(0, 1, 1001)
    np.testing.assert_allclose(decode_values(encode_values(x, encoding), encoding), x, atol=1e-12)


def test_srgb_reference_values():
    # IEC 61966-2-1: code 0.5 → 0.21404; linear 0.0031308 is the knee.
    np.testing.assert_allclose(decode_values(0.5, "srgb"), 0.214041140, rtol=1e-8)
    np.testing.assert_allclose(encode_values(0.0031308, "srgb"), 0.040449936, rtol=1e-6)
    np.testing.assert_allclose(decode_values(0.5, "gamma2.2"), 0.5**2.2)
    np.testing.assert_array_equal(encode_image(np.array([0.0, 0.5, 1.0, 2.0]), "linear", 16), [0, 32768, 65535, 65535])


@pytest.mark.parametrize(
    ("fmt", "encoding", "bits"),
    [("png", "linear", 16), ("tif", "srgb", 8), ("tif", "gamma2.2", 16), ("jpg", "srgb", 8)],
)
def test_formats_round_trip_through_the_loader(tmp_path, fmt, encoding, bits):
    cap = wj.simulate_capture(
        PROBE,
        tmp_path / "c",
        seed=1,
        image_size=(48, 36),
        image_format=fmt,
        encoding=encoding,
        bit_depth=bits,
        noise=SensorNoise(0.0, 0.0),
        texture="none",
    )
    raw = read_image(tmp_path / "c" / f"lit.{fmt}")
    assert raw.dtype == (np.uint8 if bits == 8 else np.uint16) and raw.shape == (36, 48, 3)
    # Decoding gives back the linear values written, to within half a code (JPEG: its compression error).
    step = 1 / ((1 << bits) - 1)
    tol = 0.03 if fmt == "jpg" else 0.5 * step * (2.5 if encoding != "linear" else 1.0) + 1e-7
    relin = decode_values(encode_values(cap.lit, encoding), encoding)
    assert np.max(np.abs(relin - cap.lit)) <= tol
    assert cap.lit.max() > 0.5


def test_rgb_standard_and_defaults(tmp_path, good):
    folder = tmp_path / "rgb"
    shutil.copytree(good, folder)
    _edit(rho_standard=[0.98, 0.99, 0.97], regions=None, material=None, fit=None)(folder)
    cap = load_capture(folder)
    np.testing.assert_array_equal(cap.rho_standard, [0.98, 0.99, 0.97])
    assert cap.rig.probe is None and cap.tangent == (1.0, 0.0)
    assert cap.config.fit.model == "anisotropic" and cap.config.fit.noise_floor == 0.002
