"""Bad input, every command: refused in ≤ 2 lines naming the file or field, no traceback, nothing written.

Every CLI command (``fit``, ``simulate``, ``texture analyze``, ``texture
synthesize``, ``diagnose``, ``gratings``) and the public loaders are driven
with broken inputs of each kind: outputs that cannot be written, impossible
values, images that do not belong together, wrong types (a folder for a file,
a boolean for a number), truncated files. The rules are those of
:mod:`wardjax._rules`, shared by the CLI, ``capture.toml`` and the
Python API; the expected refusals here are written from the physics (ρd in
[0, 1], ρd + ρs ≤ 1, α > 0, a lens's field of view), not read off the code.
"""

import json
import os
import shutil
import tomllib
from pathlib import Path

import imageio.v3 as iio
import numpy as np
import pytest
import tifffile
import tomli_w
from _captures import phone_capture
from click.testing import CliRunner

import wardjax as wj
from wardjax._files import read_image
from wardjax.capture import CaptureError, RuleError, check_focal_px, check_ward_params, load_capture
from wardjax.run import main
from wardjax.simulate import write_capture_toml
from wardjax.texture import read_rho_d

PROBE = wj.WardParams(rho_d=(0.5, 0.45, 0.4), rho_s=0.04, alpha_x=0.12, alpha_y=0.12)
BAD_TEXT = ("Value error,", "internal error", "capture.toml: capture.toml", "Traceback")


# --------------------------------------------------------------------------- fixtures


@pytest.fixture(scope="module")
def good(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("good") / "cap"
    wj.simulate_capture(PROBE, folder, seed=3, image_size=(64, 48))
    return folder


@pytest.fixture(scope="module")
def texture_model(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("tex")
    rng = np.random.default_rng(5)
    np.save(folder / "rho.npy", 0.4 + 0.05 * rng.standard_normal((64, 64)))
    res = CliRunner().invoke(
        main, ["texture", "analyze", str(folder / "rho.npy"), "-o", str(folder / "m.json"), "--height", "1"]
    )
    assert res.exit_code == 0, res.output
    return folder / "m.json"


def _copy(good: Path, tmp: Path, name: str = "cap") -> Path:
    dst = tmp / "caps" / name
    shutil.copytree(good, dst)
    return dst


def _edit_toml(folder: Path, **changes) -> None:
    cfg = tomllib.loads((folder / "capture.toml").read_text())
    for dotted, value in changes.items():
        *head, last = dotted.split("__")
        d = cfg
        for k in head:
            d = d[k]
        d[last] = value
    write_capture_toml(folder / "capture.toml", cfg)


def _refused(argv: list[str], named: str, *, unwritten=(), contains: str = "") -> str:
    """Run the CLI and check the refusal; return its line."""
    res = CliRunner().invoke(main, argv)
    text = res.output
    lines = [ln for ln in text.splitlines() if ln.strip()]
    assert res.exit_code not in (0, None), text
    assert isinstance(res.exception, SystemExit), repr(res.exception)
    assert 1 <= len(lines) <= 2, text
    assert lines[0].startswith("error: "), text
    assert named in text, f"{named!r} not in {text!r}"
    assert contains in text, f"{contains!r} not in {text!r}"
    for bad in BAD_TEXT:
        assert bad not in text, text
    assert "  " not in lines[0].removeprefix("error: "), f"an empty slot in {lines[0]!r}"
    for p in unwritten:
        assert not Path(p).exists(), f"{p} was written"
    return lines[0]


# --------------------------------------------------------------------------- outputs that cannot be written


@pytest.fixture
def wall(tmp_path) -> Path:
    """A regular file where a folder is wanted."""
    p = tmp_path / "wall"
    p.write_text("a file, not a folder")
    return p


def test_outputs_under_a_file_are_refused_before_any_work(good, wall, tmp_path, texture_model):
    np.save(tmp_path / "rho.npy", np.full((64, 64), 0.4))
    cases = [
        ["fit", str(good), "--out", str(wall / "out"), "--quiet"],
        ["simulate", str(wall / "sim")],
        ["texture", "analyze", str(tmp_path / "rho.npy"), "-o", str(wall / "t.json")],
        ["texture", "synthesize", str(texture_model), "--size", "64x64", "-o", str(wall / "t.tif")],
        ["diagnose", str(good), "--out", str(wall / "d")],
        ["gratings", "--out", str(wall / "g")],
    ]
    for argv in cases:
        line = _refused(argv, str(wall), contains="is a file, not a folder")
        assert "cannot write here" in line
    assert wall.read_text() == "a file, not a folder"


@pytest.mark.skipif(os.geteuid() == 0, reason="root writes into read-only folders")
def test_read_only_output_folder_is_refused(good, tmp_path):
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o555)
    try:
        _refused(["fit", str(good), "--out", str(ro / "out"), "--quiet"], str(ro), contains="not writable")
        _refused(["simulate", str(ro / "sim")], str(ro), contains="not writable")
    finally:
        ro.chmod(0o755)


def test_folder_given_for_an_output_file(tmp_path):
    np.save(tmp_path / "rho.npy", np.full((64, 64), 0.4))
    (tmp_path / "m.json").mkdir()
    _refused(["texture", "analyze", str(tmp_path / "rho.npy"), "-o", str(tmp_path / "m.json")], "m.json")


def test_simulate_keeps_an_existing_capture_unless_forced(good, tmp_path):
    cap = _copy(good, tmp_path)
    before = (cap / "capture.toml").read_bytes(), (cap / "lit.png").stat().st_mtime_ns
    _refused(["simulate", str(cap), "--size", "32", "24"], str(cap), contains="holds a capture")
    assert ((cap / "capture.toml").read_bytes(), (cap / "lit.png").stat().st_mtime_ns) == before
    res = CliRunner().invoke(main, ["simulate", str(cap), "--size", "32", "24", "--force"])
    assert res.exit_code == 0, res.output
    assert load_capture(cap).lit.shape == (24, 32, 3)


# --------------------------------------------------------------------------- impossible values


SIM_BAD = {
    # option values → the option the error must name
    "rho_d_above_one": (["--rho-d", "1.2", "0.5", "0.4"], "--rho-d"),
    "rho_d_negative": (["--rho-d", "-0.1", "0.5", "0.4"], "--rho-d"),
    "rho_s_negative": (["--rho-s", "-0.01"], "--rho-s"),
    "energy": (["--rho-d", "0.6", "0.6", "0.6", "--rho-s", "0.5"], "--rho-s"),
    "alpha_x_zero": (["--alpha-x", "0"], "--alpha-x"),
    "alpha_y_negative": (["--alpha-y", "-0.1"], "--alpha-y"),
    "alpha_nan": (["--alpha-y", "nan"], "--alpha-y"),
    "rho_s_inf": (["--rho-s", "inf"], "--rho-s"),
    "size_too_small": (["--size", "8", "8"], "--size"),
    "rho_s_word": (["--rho-s", "shiny"], "--rho-s"),
}


@pytest.mark.parametrize("case", sorted(SIM_BAD))
def test_simulate_refuses_impossible_parameters(tmp_path, case):
    args, option = SIM_BAD[case]
    _refused(["simulate", str(tmp_path / "sim"), *args], option, unwritten=[tmp_path / "sim"])


def test_texture_options_out_of_range(tmp_path, texture_model):
    np.save(tmp_path / "rho.npy", np.full((64, 64), 0.4))
    out = tmp_path / "o.json"
    _refused(["texture", "analyze", str(tmp_path / "rho.npy"), "-o", str(out), "--rho-s", "1.5"], "--rho-s")
    _refused(["texture", "analyze", str(tmp_path / "rho.npy"), "-o", str(tmp_path / "o.txt")], "o.txt")
    _refused(["texture", "synthesize", str(texture_model), "--size", "0x10", "-o", str(tmp_path / "s.tif")], "--size")
    # below the model's smallest tile: the limit is stated, with the size as typed (width x height)
    line = _refused(
        ["texture", "synthesize", str(texture_model), "--size", "12x6", "-o", str(tmp_path / "s.tif")],
        "--size 12x6",
        unwritten=[tmp_path / "s.tif"],
    )
    assert "at least 8 pixels" in line  # 2 ** (levels + 2) for the one-level model


# capture.toml fields → (the field the error must name, a word it must say)
TOML_BAD = {
    "rho_standard_above_one": ({"rho_standard": 1.5}, "rho_standard", "less than or equal to 1"),
    "lamp_at_1e30": ({"rig__lamp": [0.0, 300.0, 1e30]}, "rig.lamp", "mm from the sample"),
    "camera_at_1e30": ({"rig__camera": [0.0, -1e30, 400.0]}, "rig.camera", "mm from the sample"),
    "look_at_far": ({"camera__look_at": [0.0, 0.0, -1e12]}, "camera.look_at", "mm from the sample"),
    "focal_no_lens_long": ({"camera__focal_px": 1e9}, "camera.focal_px", "field of view"),
    "focal_no_lens_short": ({"camera__focal_px": 0.5}, "camera.focal_px", "field of view"),
    "focal_y_no_lens": ({"camera__focal_px_y": 1e7}, "camera.focal_px_y", "field of view"),
    "bool_bit_depth": ({"images__bit_depth": True}, "images.bit_depth", ""),
    "bool_focal": ({"camera__focal_px": True}, "camera.focal_px", "not the boolean true"),
    "bool_image_size": ({"camera__image_size": [True, 48]}, "camera.image_size", ""),
    "bool_noise_floor": ({"fit__noise_floor": True}, "fit.noise_floor", "not the boolean true"),
    "bool_in_lamp": ({"rig__lamp": [0.0, True, 400.0]}, "rig.lamp", "not the boolean true"),
    "bool_rho_standard": ({"rho_standard": True}, "rho_standard", ""),
    "string_number": ({"camera__focal_px": "640"}, "camera.focal_px", ""),
}


@pytest.mark.parametrize("case", sorted(TOML_BAD))
def test_capture_toml_impossible_values(good, tmp_path, case):
    changes, field, word = TOML_BAD[case]
    cap = _copy(good, tmp_path)
    _edit_toml(cap, **changes)
    with pytest.raises(CaptureError) as info:
        load_capture(cap)
    assert info.value.file == "capture.toml" and info.value.field.startswith(field), str(info.value)
    out = tmp_path / "out"
    _refused(["fit", str(cap), "--out", str(out), "--quiet"], f"capture.toml: {field}", unwritten=[out / "cap"])
    assert word in str(info.value)


PHONE_BAD = {
    "bool_region": ({"photo__region": [True, 80, 30, 100]}, "photo.region"),
    "bool_ppb_mean": (
        {"thresholds__ppb": None, "thresholds__ppb_mean": True, "thresholds__n_observers": 3},
        "ppb_mean",
    ),
    "bool_n": ({"specular__n": True}, "specular.n"),
    "bool_seed": ({"fit__seed": False}, "fit.seed"),
    "both_threshold_forms": ({"thresholds__ppb_mean": 11.0, "thresholds__n_observers": 3}, "thresholds"),
}


@pytest.mark.parametrize("case", sorted(PHONE_BAD))
def test_smartphone_toml_wrong_values(tmp_path, case):
    edits, field = PHONE_BAD[case]
    edits = dict(edits)
    folder = phone_capture(tmp_path / "caps" / "phone")
    cfg = tomllib.loads((folder / "capture.toml").read_text())
    for key, value in edits.items():
        section, _, name = key.partition("__")
        if value is None:
            cfg[section].pop(name)
        else:
            cfg.setdefault(section, {})[name] = value
    (folder / "capture.toml").write_text(tomli_w.dumps(cfg))
    with pytest.raises(CaptureError, match=field):
        load_capture(folder)
    out = tmp_path / "out"
    _refused(["fit", str(folder), "--out", str(out), "--quiet"], field, unwritten=[out / "phone"])


def test_rules_against_closed_forms():
    # ρd + ρs = 1 exactly is allowed (energy conservation's bound), a hair above is not.
    check_ward_params([0.5, 0.5, 0.5], 0.5, 0.1, 0.1)
    check_ward_params(0.3, [0.1, 0.2, 0.3], 0.1, 0.2)
    with pytest.raises(RuleError, match="rho_s"):
        check_ward_params([0.5, 0.5, 0.5], 0.5 + 1e-9, 0.1, 0.1)
    with pytest.raises(RuleError, match="rho_d: expected 1 or 3"):
        check_ward_params([0.5, 0.5], 0.0, 0.1, 0.1)
    with pytest.raises(RuleError, match="boolean"):
        check_ward_params(0.5, True, 0.1, 0.1)
    # a 36 mm-wide sensor 6000 px across behind a 50 mm lens: f = 50/36 × 6000 ≈ 8333 px, 39.6° — a real lens;
    check_focal_px("f", 8333.0, 6000)
    # the field-of-view bounds: 2 atan(w / 2f) = 1° and 170° exactly at the limits
    w = 1000
    check_focal_px("f", w / 2 / np.tan(np.radians(0.5)) * (1 - 1e-9), w)
    check_focal_px("f", w / 2 / np.tan(np.radians(85.0)) * (1 + 1e-9), w)
    with pytest.raises(RuleError):
        check_focal_px("f", w / 2 / np.tan(np.radians(0.5)) * 1.01, w)
    with pytest.raises(RuleError):
        check_focal_px("f", w / 2 / np.tan(np.radians(85.0)) * 0.99, w)


def test_python_api_applies_the_same_rules(tmp_path):
    """WardParams refuses what capture.toml and the CLI refuse, at construction: nothing is simulated or written."""
    good = dict(rho_d=(0.5, 0.5, 0.5), rho_s=0.04, alpha_x=0.1, alpha_y=0.1)
    for edit, field in (
        (dict(rho_d=(1.5, 0.5, 0.5)), "rho_d"),
        (dict(rho_s=-0.1), "rho_s"),
        (dict(rho_d=(0.9, 0.9, 0.9), rho_s=0.2), "rho_s"),
        (dict(alpha_x=0.0), "alpha_x"),
        (dict(alpha_y=float("nan")), "alpha_y"),
    ):
        with pytest.raises(RuleError) as info:
            wj.simulate_capture(wj.WardParams(**(good | edit)), tmp_path / "sim", image_size=(32, 24))
        assert info.value.field == field
        assert not (tmp_path / "sim").exists()


# --------------------------------------------------------------------------- images that do not belong together


def _png(path: Path, img: np.ndarray) -> None:
    import imagecodecs

    path.write_bytes(imagecodecs.png_encode(img))


IMAGE_BAD = {
    # id: (change to the copied capture, file named, word in the error)
    "dark_smaller": (lambda f, im: _png(f / "dark.png", im[:40, :60]), "dark.png", "60×40"),
    "dark_grey": (
        lambda f, im: _png(f / "dark.png", np.ascontiguousarray(im[..., 0])),
        "dark.png",
        "1 channel(s) but lit.png has 3",
    ),
    "dark_16_bit": (lambda f, im: _png(f / "dark.png", im.astype(np.uint16) * 257), "dark.png", "uint16"),
    "dark_jpeg": (
        lambda f, im: (iio.imwrite(f / "dark.jpg", im), _edit_toml(f, images__dark="dark.jpg")),
        "dark.jpg",
        "JPEG",
    ),
    "lit_black": (lambda f, im: _png(f / "lit.png", np.zeros_like(im)), "lit.png", "black"),
    "lit_one_value": (lambda f, im: _png(f / "lit.png", np.full_like(im, 128)), "lit.png", "single value"),
    "lit_white": (lambda f, im: _png(f / "lit.png", np.full_like(im, 255)), "lit.png", "saturated"),
}


@pytest.mark.parametrize("case", sorted(IMAGE_BAD))
def test_images_that_do_not_belong_together(good, tmp_path, case):
    change, file, word = IMAGE_BAD[case]
    cap = _copy(good, tmp_path)
    change(cap, read_image(cap / "lit.png"))
    with pytest.raises(CaptureError) as info:
        load_capture(cap)
    assert info.value.file == file and word in str(info.value), str(info.value)
    out = tmp_path / "out"
    _refused(["fit", str(cap), "--out", str(out), "--quiet"], file, contains=word, unwritten=[out / "cap"])


@pytest.mark.parametrize("code", [0, 255])
def test_smartphone_clipped_region_is_never_a_converged_fit(tmp_path, code):
    photo = np.full((96, 128, 3), 120, np.uint8)
    photo[20:80, 30:100, 0] = code  # red clipped over the region: ρd_R would be exactly 0 or 1 "± 0"
    folder = phone_capture(tmp_path / "caps" / "phone", photo=photo)
    word = "black" if code == 0 else "saturated"
    with pytest.raises(CaptureError, match=word):
        load_capture(folder)
    with pytest.raises(RuleError, match=f"R values are {word}"):
        wj.fit_smartphone(photo, (20, 80, 30, 100), ppb=[10, 11, 12])
    out = tmp_path / "out"
    _refused(["fit", str(folder), "--out", str(out), "--quiet"], "photo.png", contains=word, unwritten=[out / "phone"])


# --------------------------------------------------------------------------- wrong types: folders for files and back


def test_folders_given_for_files(good, tmp_path, texture_model):
    cap = _copy(good, tmp_path, "a")
    (cap / "capture.toml").unlink()
    (cap / "capture.toml").mkdir()
    _refused(["fit", str(cap), "--out", str(tmp_path / "o1"), "--quiet"], "capture.toml", contains="is a folder")
    cap = _copy(good, tmp_path, "b")
    (cap / "lit.png").unlink()
    (cap / "lit.png").mkdir()
    _refused(["fit", str(cap), "--out", str(tmp_path / "o2"), "--quiet"], "lit.png", contains="is a folder")
    phone = phone_capture(tmp_path / "caps" / "c")
    (phone / "photo.png").unlink()
    (phone / "photo.png").mkdir()
    _refused(["fit", str(phone), "--out", str(tmp_path / "o3"), "--quiet"], "photo.png", contains="is a folder")
    (tmp_path / "rho.tif").mkdir()
    _refused(
        ["texture", "analyze", str(tmp_path / "rho.tif"), "-o", str(tmp_path / "m.json")],
        "rho.tif",
        contains="is a folder",
    )
    (tmp_path / "t.json").mkdir()
    argv = ["texture", "synthesize", str(tmp_path / "t.json"), "--size", "64x64", "-o", str(tmp_path / "s.tif")]
    _refused(argv, "t.json", contains="is a folder")
    for sub in ("o1", "o2", "o3"):
        assert not any((tmp_path / sub).glob("[!s]*")), "a capture folder was written"  # summary.csv only


def test_files_given_for_folders(good, tmp_path):
    f = tmp_path / "cap.txt"
    f.write_text("not a capture")
    _refused(["fit", str(f), "--out", str(tmp_path / "o"), "--quiet"], "cap.txt", contains="not a folder")
    _refused(["diagnose", str(f), "--out", str(tmp_path / "d")], "cap.txt", contains="not a folder")


def test_rho_d_maps_that_are_not_reflectances(tmp_path):
    out = tmp_path / "m.json"
    tifffile.imwrite(tmp_path / "codes8.tif", np.full((64, 64), 100, np.uint8))
    tifffile.imwrite(tmp_path / "codes16.tif", np.full((64, 64), 30000, np.uint16))
    np.save(tmp_path / "scaled.npy", np.full((64, 64), 120.0))
    for name, word in (
        ("codes8.tif", "uint8 codes"),
        ("codes16.tif", "divide by 65535"),
        ("scaled.npy", "far outside"),
    ):
        _refused(["texture", "analyze", str(tmp_path / name), "-o", str(out)], name, contains=word, unwritten=[out])
        with pytest.raises(ValueError, match=name):
            read_rho_d(tmp_path / name)


# --------------------------------------------------------------------------- truncated files


def test_truncated_files(good, tmp_path, texture_model):
    cap = _copy(good, tmp_path, "a")
    data = (cap / "lit.png").read_bytes()
    (cap / "lit.png").write_bytes(data[: len(data) // 2])
    _refused(["fit", str(cap), "--out", str(tmp_path / "o1"), "--quiet"], "lit.png", contains="cannot read")
    cap = _copy(good, tmp_path, "b")
    text = (cap / "capture.toml").read_text()
    (cap / "capture.toml").write_text(text[: text.index("[camera]") + 4])
    _refused(["fit", str(cap), "--out", str(tmp_path / "o2"), "--quiet"], "capture.toml")
    phone = phone_capture(tmp_path / "caps" / "c")
    data = (phone / "photo.png").read_bytes()
    (phone / "photo.png").write_bytes(data[:100])
    _refused(["fit", str(phone), "--out", str(tmp_path / "o3"), "--quiet"], "photo.png", contains="cannot be read")
    m = tmp_path / "m.json"
    m.write_text(texture_model.read_text()[:200])
    _refused(
        ["texture", "synthesize", str(m), "--size", "64x64", "-o", str(tmp_path / "s.tif")], "m.json", contains="JSON"
    )
    np.save(tmp_path / "rho.npy", np.full((64, 64), 0.4))
    data = (tmp_path / "rho.npy").read_bytes()
    (tmp_path / "rho.npy").write_bytes(data[: len(data) // 2])
    out = tmp_path / "t.json"
    _refused(
        ["texture", "analyze", str(tmp_path / "rho.npy"), "-o", str(out)],
        "rho.npy",
        contains="cannot read",
        unwritten=[out],
    )
    for sub in ("o1", "o2", "o3"):
        assert not any(p.is_dir() for p in (tmp_path / sub).iterdir()), "a capture folder was written"


# --------------------------------------------------------------------------- failures mid-way, the unforeseen


def test_a_fit_failing_mid_way_writes_nothing_and_the_unforeseen_is_logged(good, tmp_path, monkeypatch):
    from wardjax.run import _batch

    def half_then_fail(kind):
        def fitter(cap, out_dir, *, created):
            out_dir.mkdir(parents=True, exist_ok=True)
            (out_dir / "rho_d.tif").write_bytes(b"half the outputs")
            raise kind("the fit ran out of road")

        return fitter

    src = _copy(good, tmp_path)
    for kind, expect in ((ValueError, "the fit ran out of road"), (ZeroDivisionError, "unexpected failure")):
        monkeypatch.setitem(_batch.FITTERS, "scanline", half_then_fail(kind))
        out = tmp_path / f"out-{kind.__name__}"
        line = _refused(["fit", str(src), "--out", str(out), "--quiet"], "cap", contains=expect)
        assert not (out / "cap").exists() and not list(out.glob(".cap*"))
        if kind is ZeroDivisionError:
            log = out / "errors.log"
            assert str(log) in line and "Traceback" in log.read_text() and "ZeroDivisionError" in log.read_text()
        else:
            assert not (out / "errors.log").exists()


def test_an_unforeseen_cli_failure_is_one_line_and_a_log(tmp_path, monkeypatch):
    import wardjax.smartphone
    from wardjax.run import _cli

    def boom(*args, **kwargs):
        raise KeyError("a key nobody expected")

    monkeypatch.setattr(wardjax.smartphone, "write_gratings", boom)
    monkeypatch.setattr(_cli, "_error_log_path", lambda: tmp_path / "log" / "error.log")
    res = CliRunner().invoke(main, ["gratings", "--out", str(tmp_path / "g")])
    assert res.exit_code == 1 and isinstance(res.exception, SystemExit)
    lines = [ln for ln in res.output.splitlines() if ln.strip()]
    assert len(lines) == 1 and "unexpected failure (KeyError" in lines[0] and str(tmp_path / "log") in lines[0]
    assert "Traceback" not in res.output and "Traceback" in (tmp_path / "log" / "error.log").read_text()


def test_tiny_errors_are_printed_in_scientific_notation():
    from wardjax.run._cli import _pm

    assert _pm(0.05, 0.0123) == "0.0500 ± 0.0123"
    assert _pm(0.05, 3.2e-6) == "0.0500 ± 3.2e-06"
    assert float(_pm(0.05, 3.2e-6).split("± ")[1]) == pytest.approx(3.2e-6, rel=0.02)
    assert _pm(None, 0.1) == "–"


def test_usage_errors_are_one_line():
    for argv, named in (
        (["simulate"], "OUT_DIR"),
        (["fit"], "PATHS"),
        (["no-such-command"], "no-such-command"),
        (["simulate", "x", "--encoding", "rgb"], "--encoding"),
    ):
        _refused(argv, named)


def test_params_json_errors_stay_json(good, tmp_path):
    """The batch's foreseen refusals land in summary.csv as the same one line."""
    cap = _copy(good, tmp_path)
    _edit_toml(cap, camera__focal_px=1e9)
    items = wj.run_batch([cap], tmp_path / "out")
    assert items[0].status == "error" and items[0].error.startswith("capture.toml: camera.focal_px:")
    assert json.dumps(items[0].error)  # a plain string, one line
    assert "\n" not in items[0].error


def test_a_probe_saturated_over_half_its_pixels_is_refused(tmp_path):
    # Six times the default exposure: most probe pixels sit at the largest code, the rest of the image does not.
    cap = tmp_path / "caps" / "bright"
    wj.simulate_capture(PROBE, cap, seed=3, image_size=(64, 48), headroom=6.0, noise=wj.SensorNoise(0, 0))
    out = tmp_path / "out"
    line = _refused(["fit", str(cap), "--out", str(out), "--quiet"], "lit.png", unwritten=[out / "bright"])
    assert "of the probe's pixels are saturated" in line


@pytest.mark.slow  # a real fit at 160 × 120: ~35 s on a loaded 2-core machine
def test_scanlines_at_the_step_limit_are_said_in_the_output(tmp_path):
    # The desk of Table 1 at 160 × 120: a third of its scanlines run out of steps (22 of 55 when measured).
    from wardjax._data import table1_materials

    cap = tmp_path / "desk"
    wj.simulate_capture(table1_materials()["desk"], cap, seed=0, image_size=(160, 120), model="anisotropic")
    out = tmp_path / "out"
    res = CliRunner().invoke(main, ["fit", str(cap), "--out", str(out)])
    assert res.exit_code == 0, res.output
    scan = json.loads((out / "desk" / "params.json").read_text())["fit"]["diagnostics"]["scanlines"]
    stopped = scan["status"].get("max_steps", 0)
    assert stopped > 0, scan
    said = [ln for ln in res.output.splitlines() if "stopped at the step limit" in ln]
    assert len(said) == 1 and f"desk: {stopped} of {scan['count']} scanlines" in said[0], res.output


FUZZ_FIELDS = (
    "rho_standard",
    "images__bit_depth",
    "images__encoding",
    "rig__lamp",
    "rig__camera",
    "camera__look_at",
    "camera__up",
    "camera__focal_px",
    "camera__principal_point",
    "camera__image_size",
    "regions__probe",
    "material__tangent",
    "fit__noise_floor",
    "fit__smooth_standard_px",
)


def _fuzz_value(rng: np.random.Generator):
    """A value of a random kind: booleans, strings, non-finite and huge numbers, lists of any length, tables."""
    scalars = [True, False, 0, -1, 1e30, -1e30, 1e-300, float("nan"), float("inf"), "", "12", 0.5, 640.0, 2**63 - 1]
    kind = rng.integers(4)
    if kind == 0:
        return scalars[rng.integers(len(scalars))]
    if kind == 1:
        return [scalars[rng.integers(len(scalars))] for _ in range(rng.integers(0, 6))]
    if kind == 2:
        return [float(v) for v in rng.normal(0, 10.0 ** rng.integers(-3, 35), rng.integers(1, 5))]
    return {"x": 1.0}


def test_seeded_fuzz_of_capture_toml_never_escapes_the_rules(good, tmp_path, rng):
    """150 random edits: each loads (then within the rules) or is one CaptureError line; nothing else escapes."""
    refused = 0
    for i in range(150):
        cap = tmp_path / f"f{i}"
        shutil.copytree(good, cap)
        changes = {FUZZ_FIELDS[k]: _fuzz_value(rng) for k in rng.choice(len(FUZZ_FIELDS), rng.integers(1, 3))}
        try:
            _edit_toml(cap, **changes)
        except (ValueError, TypeError, OverflowError):  # tomlkit cannot write it: not a TOML input
            shutil.rmtree(cap)
            continue
        try:
            loaded = load_capture(cap)
        except CaptureError as e:
            refused += 1
            assert "\n" not in str(e) and not any(b in str(e) for b in BAD_TEXT), str(e)
        else:  # accepted: then the rules hold for what was read
            cfg = loaded.config
            for field in ("rig.lamp", "rig.camera", "camera.look_at"):
                section, name = field.split(".")
                check = getattr(getattr(cfg, section), name)
                assert all(not isinstance(v, bool) and np.isfinite(v) for v in check), (changes, check)
                assert np.linalg.norm(check) <= 1e5, (changes, check)
            assert all(0 < v <= 1 for v in cfg.rho_standard), changes
        shutil.rmtree(cap)
    assert refused > 75  # most random edits are wrong, and each was refused by name


def test_too_many_pixels_echoes_the_size_as_typed(tmp_path, texture_model):
    argv = ["texture", "synthesize", str(texture_model), "--size", "40000x20000", "-o", str(tmp_path / "s.tif")]
    line = _refused(argv, "--size 40000x20000", unwritten=[tmp_path / "s.tif"])
    assert "(20000, 40000)" not in line and "800000000 pixels" in line


def test_a_full_disk_is_refused_before_any_work(good, tmp_path, monkeypatch):
    import collections

    import wardjax._files

    usage = collections.namedtuple("usage", "total used free")
    monkeypatch.setattr(wardjax._files.shutil, "disk_usage", lambda p: usage(10 << 30, 10 << 30, 4096))
    out = tmp_path / "out"
    _refused(["fit", str(good), "--out", str(out), "--quiet"], str(out), contains="the disk is full", unwritten=[out])


def test_a_colour_correction_that_failed_is_refused():
    """The real ColorChecker photo's correction holds out at ΔE*ab ≈ 3–5 and passes; the same photo with its
    colours read in reversed order fits its own patches yet holds out far worse: refused by the rule, naming
    what to check. With no patch held out, the error cannot be estimated: refused too."""
    import tomllib

    from wardjax._rules import MAX_HELD_OUT_DELTA_E, check_camera_correction
    from wardjax.smartphone import (
        colorchecker_held_out_delta_E,
        colorchecker_patch_regions,
        colorchecker_reference_Lab,
        colorchecker_rho_d,
    )

    data = Path(__file__).parent / "data" / "colorchecker"
    img = iio.imread(data / "plantcv_source1_img.png")
    lay = tomllib.loads((data / "layout.toml").read_text())
    regions = colorchecker_patch_regions(
        tuple(lay["first_center"]), tuple(lay["pitch"]), tuple(lay["grid"]), lay["half_size"], lay["order"]
    )
    ref = colorchecker_reference_Lab("chromaticities")
    usable = np.ones(24, bool)
    usable[np.argmax(ref[:, 0])] = False  # the clipped white
    rho = colorchecker_rho_d(img, regions, decoding="gamma2.2")
    good = colorchecker_held_out_delta_E(rho, ref, usable=usable)
    check_camera_correction("chart.png", good)
    assert np.nanmedian(good) < MAX_HELD_OUT_DELTA_E / 2
    # the 18 colours read in reverse, the greys (chart indices 18–23) in place: the tone curve still fits
    order = np.r_[np.arange(17, -1, -1), np.arange(18, 24)]
    reversed_layout = colorchecker_held_out_delta_E(rho[order], ref, usable=usable[order])
    with pytest.raises(RuleError, match="^chart.png: the colour correction failed: held-out ΔE") as info:
        check_camera_correction("chart.png", reversed_layout)
    assert len(str(info.value).splitlines()) == 1
    # every patch reversed: the greys read colours, and the tone exponent no camera needs is refused first
    with pytest.raises(ValueError, match="tone exponent of 0.0"):
        colorchecker_held_out_delta_E(rho[::-1], ref, usable=usable[::-1])
    with pytest.raises(RuleError, match="cannot be estimated"):
        check_camera_correction("chart.png", np.full(24, np.nan))
