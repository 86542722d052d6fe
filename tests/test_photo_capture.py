"""Photograph captures (flash, multiview, the rectified import): known geometry and BRDF in, the same out.

Each test renders photos with wardjax's own Ward code through the observation
model ``v = exposure · P · f_r · cos θi / d² + v_dark`` (the independent
reference: geometry computed here from the layout's definition, not by the
loader), writes them as the files a user would have, and checks what
:func:`wardjax.load_capture` recovers: directions, f_r within the pixel
noise, σ, the dark frame on its exposure scale, the light power from a grey
card; and that bad input is one line naming the file and field, with nothing
written.
"""

from __future__ import annotations

import jax
import numpy as np
import pytest
from PIL import Image

import wardjax as wj
from wardjax._files import encode_image, write_image
from wardjax.capture import CaptureError, PhotoCapture, fit_vignetting, read_exif

TRUTH = wj.WardParams(rho_d=(0.5, 0.3, 0.2), rho_s=0.05, alpha_x=0.15, alpha_y=0.15)


def _ward(wi, wo, p=TRUTH):
    with jax.enable_x64(True):
        return np.asarray(wj.ward_brdf(p, np.asarray(wi), np.asarray(wo)), np.float64)


def _unit(v):
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _grid(h, w, width):
    """Sample points of a rectified image (the layout's definition, written out independently)."""
    pix = width / w
    x = (np.arange(w) + 0.5 - w / 2) * pix
    y = -(np.arange(h) + 0.5 - h / 2) * pix
    xx, yy = np.meshgrid(x, y)
    return np.stack([xx, yy, np.zeros_like(xx)], -1)


def _render(points, cam, light, power, exposure=1.0):
    wi, wo = _unit(light - points), _unit(cam - points)
    d2 = np.sum((light - points) ** 2, -1)
    return exposure * np.asarray(power) * _ward(wi, wo) * (wi[..., 2] / d2)[..., None], wi, wo


def _write_rectified(folder, cams, lights, power_cm, width_cm, h=48, w=64, bits=16):
    folder.mkdir(parents=True, exist_ok=True)
    pts = _grid(h, w, width_cm * 10)
    truth = []
    for k, (c, lt) in enumerate(zip(cams, lights)):
        v, wi, wo = _render(pts, np.asarray(c) * 10, np.asarray(lt) * 10, np.asarray(power_cm) * 100)
        write_image(folder / f"{k}.png", encode_image(v, "srgb", bits))
        truth.append((v, wi, wo))
    np.savetxt(folder / "camera_pos.txt", np.asarray(cams), delimiter=",")
    np.savetxt(folder / "light_pos.txt", np.asarray(lights))
    (folder / "light_power.txt").write_text(f"{power_cm}\n")
    (folder / "image_size.txt").write_text(f"{width_cm}\n")
    return truth


CAMS = [(0.0, 0.0, 30.0), (8.0, 0.0, 28.0), (0.0, -8.0, 28.0), (-6.0, 6.0, 29.0)]
LIGHTS = [(0.0, 0.0, 30.0), (-10.0, 0.0, 25.0), (0.0, 10.0, 25.0), (6.0, -6.0, 29.0)]


@pytest.fixture
def rectified(tmp_path):
    truth = _write_rectified(tmp_path / "src", CAMS, LIGHTS, power_cm=900.0, width_cm=12.0)
    return tmp_path, truth


def test_01_import_recovers_geometry_and_brdf(rectified):
    tmp, truth = rectified
    cap = wj.capture.import_capture(tmp / "src", tmp / "cap")
    assert isinstance(cap, PhotoCapture) and cap.method == "multiview"
    assert cap.f_r.shape == (48, 64, 4, 3) and cap.wi.shape == (48, 64, 4, 3) and cap.mask.shape == (48, 64, 4)
    assert cap.pixel_mm == pytest.approx(120.0 / 64)
    for k, (v, wi, wo) in enumerate(truth):
        np.testing.assert_allclose(cap.wi[:, :, k], wi, atol=1e-12)
        np.testing.assert_allclose(cap.wo[:, :, k], wo, atol=1e-12)
        m = cap.mask[:, :, k]
        assert m.mean() > 0.95
        f = _ward(wi, wo)
        # 16-bit sRGB codes: f_r within a few σ of the truth, and σ of the order of the rounding
        z = (cap.f_r[:, :, k][m] - f[m]) / cap.sigma[:, :, k][m]
        assert np.max(np.abs(z)) < 5.0
        np.testing.assert_allclose(cap.to_photo(f, k)[m], v[m], rtol=2e-3, atol=1e-4)
    assert (tmp / "cap" / "capture.toml").is_file()


def test_02_import_units_and_flash_default(tmp_path):
    """Light positions absent: the light is at the camera; lengths in mm scale P by 100 against cm."""
    src = tmp_path / "src"
    truth = _write_rectified(src, CAMS[:2], CAMS[:2], power_cm=900.0, width_cm=12.0)
    (src / "light_pos.txt").unlink()
    cap = wj.capture.import_capture(src, tmp_path / "cap")
    np.testing.assert_allclose(cap.wi, cap.wo, atol=1e-12)
    np.testing.assert_allclose(cap.light_power, 900.0 * 100)
    assert np.allclose(cap.wi[:, :, 0], truth[0][1])


@pytest.mark.parametrize(
    ("edit", "needle"),
    [
        (lambda s: (s / "camera_pos.txt").write_text("0 0 30\n1 2\n0 0 30\n0 0 30\n"), "camera_pos.txt: line 2"),
        (lambda s: (s / "light_power.txt").unlink(), "light_power.txt: missing"),
        (lambda s: (s / "image_size.txt").write_text("-3\n"), "image_size.txt: expected one positive"),
        (lambda s: (s / "light_pos.txt").write_text("0 0 30\n0 0 -5\n0 0 30\n0 0 30\n"), "photos[1].light"),
        (lambda s: write_image(s / "2.png", np.zeros((40, 64, 3), np.uint16)), "2.png: is 64×40"),
        (lambda s: write_image(s / "1.png", np.full((48, 64, 3), 65535, np.uint16)), "1.png: every pixel is saturated"),
    ],
    ids=["short line", "no power", "negative width", "light behind", "other size", "saturated"],
)
def test_03_import_refuses_bad_layouts_and_writes_nothing(rectified, edit, needle):
    tmp, _ = rectified
    edit(tmp / "src")
    with pytest.raises(CaptureError) as e:
        wj.capture.import_capture(tmp / "src", tmp / "cap")
    assert needle in str(e.value) and "\n" not in str(e.value)
    assert not (tmp / "cap").exists()
    assert [p.name for p in tmp.iterdir()] == ["src"]  # no staging folder left behind


def _flash_folder(tmp_path, *, toml_extra="", dark=True, exif=None, card=True, size=(60, 80)):
    """A fronto-parallel flash photo (lamp 10 mm above the lens), a dark frame at 1/5 the exposure, a grey card."""
    h, w = size
    f_px, dist, power = 90.0, 200.0, 2.0e6
    folder = tmp_path / "flash"
    folder.mkdir()
    v, u = np.mgrid[0:h, 0:w].astype(float)
    # the pinhole's rays onto z = 0: camera at (0, 0, dist) looking down, image x = sample x, image down = −y
    pts = np.stack([(u - (w - 1) / 2) / f_px * dist, -(v - (h - 1) / 2) / f_px * dist, np.zeros_like(u)], -1)
    cam, lamp = np.array([0.0, 0.0, dist]), np.array([0.0, 10.0, dist])
    ambient = np.stack([0.05 + 0.05 * u / w, 0.06 * np.ones_like(u), 0.04 * np.ones_like(u)], -1)  # in the lit photo
    e_lit, e_dark = 0.1 / 2.2**2, 0.02 / 2.2**2  # t · (ISO/100) / N²
    lit, wi, wo = _render(pts, cam, lamp, power, e_lit)
    write_image(folder / "lit.png", encode_image(lit + ambient, "srgb", 16))
    if dark:
        write_image(folder / "dark.png", encode_image(ambient * (e_dark / e_lit), "srgb", 16))
    # the card: ρ = 0.18 fronto-parallel at 250 mm, flash at the camera, its own exposure (1/2 of the photo's)
    rho, dcard, e_card = 0.18, 250.0, 0.05 / 2.2**2
    r2 = ((u - (w - 1) / 2) ** 2 + (v - (h - 1) / 2) ** 2) / f_px**2
    card_v = e_card * power * rho / np.pi / dcard**2 * (1 + r2) ** -1.5
    write_image(folder / "card.png", encode_image(np.repeat(card_v[..., None], 3, -1), "srgb", 16))
    std = (
        '[standard]\nfile = "card.png"\nreflectance = 0.18\ndistance = 250.0\n'
        "exposure_time = 0.05\nf_number = 2.2\niso = 100\n"
        if card
        else f"[light]\npower = {power}\n"
    )
    (folder / "capture.toml").write_text(
        'method = "flash"\nencoding = "srgb"\n'
        '[photo]\nfile = "lit.png"\nexposure_time = 0.1\nf_number = 2.2\niso = 100\n'
        + ('[dark]\nfile = "dark.png"\nexposure_time = 0.02\nf_number = 2.2\niso = 100\n' if dark else "")
        + f"[camera]\ndistance = {dist}\nfocal_px = {f_px}\n[lamp]\noffset = [0.0, 10.0, 0.0]\n"
        + std
        + toml_extra
    )
    return folder, (lit, wi, wo, power)


def test_04_flash_dark_frame_and_grey_card(tmp_path):
    folder, (_, wi, wo, power) = _flash_folder(tmp_path)
    cap = wj.load_capture(folder)
    assert isinstance(cap, PhotoCapture) and cap.f_r.shape == (60, 80, 1, 3)
    np.testing.assert_allclose(cap.light_power, power, rtol=2e-3)  # from the card, on the photo's exposure scale
    np.testing.assert_allclose(cap.wi[:, :, 0], wi, atol=1e-9)
    np.testing.assert_allclose(cap.wo[:, :, 0], wo, atol=1e-9)
    m = cap.mask[:, :, 0]
    assert m.mean() > 0.95
    f = _ward(wi, wo)
    # the ambient light (5× brighter in the lit photo than in the dark frame) is removed
    np.testing.assert_allclose(cap.f_r[:, :, 0][m], f[m], rtol=5e-3)
    assert cap.pixel_mm == pytest.approx(200.0 / 90.0)


def test_05_flash_without_dark_frame_keeps_the_ambient(tmp_path):
    folder, (_, wi, wo, _) = _flash_folder(tmp_path, dark=False)
    cap = wj.load_capture(folder)
    m = cap.mask[:, :, 0]
    assert np.median(cap.f_r[:, :, 0][m] / _ward(wi, wo)[m]) > 1.05  # the ambient counts as reflectance


def test_06_flash_binning_averages_and_shrinks_sigma(tmp_path):
    folder, _ = _flash_folder(tmp_path, toml_extra="[fit]\nbin = 4\n")
    cap = wj.load_capture(folder)
    assert cap.f_r.shape == (15, 20, 1, 3)
    (tmp_path / "b").mkdir()
    full = wj.load_capture(_flash_folder(tmp_path / "b")[0])
    ratio = np.nanmedian(cap.sigma) / np.nanmedian(full.sigma)
    assert 0.15 < ratio < 0.35  # about 1/4: the mean of 16 pixels


def _exif_jpeg(path, arr, **tags):
    ex = Image.Exif()
    sub = {0x829A: tags.get("t"), 0x829D: tags.get("n"), 0x8827: tags.get("iso"), 0xA405: tags.get("f35")}
    ex[0x8769] = {k: v for k, v in sub.items() if v is not None}
    Image.fromarray(arr).save(path, exif=ex, quality=95)


def test_07_exif_read_and_contradiction(tmp_path):
    folder, _ = _flash_folder(tmp_path, dark=False, card=False)
    codes = encode_image(np.full((60, 80, 3), 0.3), "srgb", 8)
    _exif_jpeg(folder / "lit.jpg", codes, t=0.1, n=2.2, iso=100, f35=27)
    ex = read_exif(folder / "lit.jpg")
    assert ex.exposure_time == pytest.approx(0.1) and ex.f_number == pytest.approx(2.2) and ex.iso == 100
    assert ex.focal_35mm == 27
    text = (folder / "capture.toml").read_text().replace("lit.png", "lit.jpg")
    (folder / "capture.toml").write_text(text.replace("exposure_time = 0.1\n", "exposure_time = 0.05\n", 1))
    with pytest.raises(CaptureError, match=r"capture.toml: photo.exposure_time: 0.05 contradicts the EXIF of lit.jpg"):
        wj.load_capture(folder)
    # focal length: the EXIF's 35 mm equivalent against focal_px (27 mm at 80×60 px is 50 px, not 90)
    (folder / "capture.toml").write_text(text)
    with pytest.raises(CaptureError, match=r"camera.focal_px: 90 contradicts the EXIF of lit.jpg"):
        wj.load_capture(folder)
    (folder / "capture.toml").write_text(text.replace("focal_px = 90.0\n", ""))
    cap = wj.load_capture(folder)
    assert cap.pixel_mm == pytest.approx(200.0 / (27 / np.hypot(36, 24) * 100.0))


def test_08_exif_missing_names_the_field(tmp_path):
    folder, _ = _flash_folder(tmp_path)
    text = (folder / "capture.toml").read_text()
    (folder / "capture.toml").write_text(
        text.replace('[dark]\nfile = "dark.png"\nexposure_time = 0.02\n', '[dark]\nfile = "dark.png"\n')
    )
    with pytest.raises(CaptureError, match=r"capture.toml: dark.exposure_time: the exposure of dark.png is not known"):
        wj.load_capture(folder)


@pytest.mark.parametrize(
    ("old", "new", "needle"),
    [
        ("offset = [0.0, 10.0, 0.0]", "position = [0.0, 10.0, -5.0]", "lamp.position: the lamp must be above"),
        ("offset = [0.0, 10.0, 0.0]", "offset = [0.0, 0.0, 300.0]", "lamp.offset: puts the lamp at z = -100"),
        ("distance = 200.0", "distance = 200.0\nposition = [0, 0, 200]", "camera: give distance"),
        ('file = "card.png"', 'file = "nope.png"', "standard.file: 'nope.png' does not exist"),
    ],
)
def test_09_flash_bad_input_one_line(tmp_path, old, new, needle):
    folder, _ = _flash_folder(tmp_path)
    (folder / "capture.toml").write_text((folder / "capture.toml").read_text().replace(old, new))
    with pytest.raises(CaptureError) as e:
        wj.load_capture(folder)
    assert needle in str(e.value) and "\n" not in str(e.value)


def test_10_vignetting_from_flat_field(tmp_path):
    h, w = 60, 80
    r2 = ((np.mgrid[0:h, 0:w][1] - (w - 1) / 2) ** 2 + (np.mgrid[0:h, 0:w][0] - (h - 1) / 2) ** 2) / (
        0.5 * np.hypot(w - 1, h - 1)
    ) ** 2
    true = 1 - 0.3 * r2 + 0.05 * r2**2
    vig = fit_vignetting(0.5 * true[..., None] * np.ones(3))
    np.testing.assert_allclose(vig.gain(h, w), true, atol=1e-9)
    assert vig.rms < 1e-9
    # in a capture: the photo divided by the falloff gives the same f_r as without a lens falloff
    folder, (_, wi, wo, _) = _flash_folder(tmp_path, dark=False, card=False)
    plain = wj.load_capture(folder)
    from wardjax._files import decode_image, read_image

    lit = decode_image(read_image(folder / "lit.png"), "srgb", 16) * true[..., None]
    write_image(folder / "lit.png", encode_image(lit, "srgb", 16))
    write_image(folder / "flat.png", encode_image(0.6 * true[..., None] * np.ones(3), "srgb", 16))
    with open(folder / "capture.toml", "a") as fh:
        fh.write('[flat_field]\nfile = "flat.png"\n')
    cap = wj.load_capture(folder)
    assert cap.vignetting is not None
    m = cap.mask[:, :, 0] & plain.mask[:, :, 0]
    np.testing.assert_allclose(cap.f_r[:, :, 0][m], plain.f_r[:, :, 0][m], rtol=5e-3)


def _board_view(cam_pos, scale=4):
    """A photo of a printed 5 × 5 ArUco grid board (OpenCV draws it) through a pinhole at ``cam_pos`` (mm)."""
    import cv2

    from wardjax.geometry import Camera, back_project

    board = cv2.aruco.GridBoard((5, 5), 20.0, 5.0, cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_4X4_50))
    bw = 120
    printed = board.generateImage((bw * scale, bw * scale), marginSize=0, borderBits=1).astype(np.float32)
    cam = Camera(position=cam_pos, look_at=(0, 0, 0), focal_px=500.0, image_size=(480, 360), up=(0, 1, 0))
    v, u = np.mgrid[0:360, 0:480].astype(float)
    pts, _ = back_project(cam, u, v)
    # the printed board's pixel (column, row) of each sample point: its centre at the origin, its rows down −y
    xb = ((pts[..., 0] + bw / 2) * scale - 0.5).astype(np.float32)
    yb = ((bw / 2 - pts[..., 1]) * scale - 0.5).astype(np.float32)
    view = cv2.remap(printed, xb, yb, cv2.INTER_LINEAR, borderValue=255)
    return np.repeat((0.8 * view / 255 + 0.08)[..., None], 3, -1), printed


BOARD_TOML = """method = "multiview"
encoding = "linear"
[light]
power = 1e5
[board]
markers = [5, 5]
marker_size = 20.0
separation = 5.0
focal_px = 500.0
pixels = [120, 120]
"""


def test_11_marker_board_pose_and_rectification(tmp_path):
    positions = [(30.0, -40.0, 260.0), (-50.0, 10.0, 240.0)]
    text = BOARD_TOML
    for k, pos in enumerate(positions):
        view, printed = _board_view(pos)
        write_image(tmp_path / f"{k}.png", encode_image(view, "linear", 16))
        text += f'[[photos]]\nfile = "{k}.png"\nlight_offset = [0.0, 0.0, 0.0]\n'
    (tmp_path / "capture.toml").write_text(text)
    cap = wj.load_capture(tmp_path)
    assert cap.pixel_mm == pytest.approx(1.0) and cap.f_r.shape[:3] == (120, 120, 2)
    for k, pos in enumerate(positions):
        # the direction to the camera at the board's centre, from the pose solved on the markers
        want = np.asarray(pos) / np.linalg.norm(pos)
        got = 0.25 * (cap.wo[59, 59, k] + cap.wo[60, 60, k] + cap.wo[59, 60, k] + cap.wo[60, 59, k])
        assert np.degrees(np.arccos(np.clip(got @ want / np.linalg.norm(got), -1, 1))) < 0.5
        # the rectified photo is the printed board (box-averaged to 1 mm pixels), seen through the camera's blur
        ref = 0.8 * printed.reshape(120, 4, 120, 4).mean(axis=(1, 3)) / 255 + 0.08
        inner = (slice(4, -4), slice(4, -4))
        assert np.corrcoef(cap.linear[:, :, k, 0][inner].ravel(), ref[inner].ravel())[0, 1] > 0.9


def test_12_marker_board_not_found(tmp_path):
    write_image(tmp_path / "0.png", encode_image(np.full((360, 480, 3), 0.4), "linear", 16))
    (tmp_path / "capture.toml").write_text(BOARD_TOML + '[[photos]]\nfile = "0.png"\n')
    with pytest.raises(CaptureError, match=r"^0.png: the marker board was not found \(0 DICT_4X4_50 markers"):
        wj.load_capture(tmp_path)


def test_13_blocks_of_pixels_as_problems_round_trip(rng):
    from wardjax.run._fit_photo import from_problems, to_problems

    a = rng.normal(size=(6, 8, 3, 2))
    p = to_problems(a, 2)
    assert p.shape == (12, 12, 2)
    # problem 0 is the top-left 2 × 2 block, its views pixel by pixel then photo by photo
    np.testing.assert_array_equal(p[0], a[:2, :2].reshape(12, 2))
    np.testing.assert_array_equal(p[1], a[:2, 2:4].reshape(12, 2))
    np.testing.assert_array_equal(from_problems(p, 6, 8, 2), a)
    np.testing.assert_array_equal(to_problems(a, 1), a.reshape(48, 3, 2))


def test_14_cli_import_writes_the_capture_or_one_line(rectified):
    from click.testing import CliRunner

    from wardjax.run._cli import main

    tmp, _ = rectified
    r = CliRunner().invoke(main, ["import", str(tmp / "src"), "--out", str(tmp / "cap")])
    assert r.exit_code == 0, r.output
    assert "4 photos 64×48" in r.output and (tmp / "cap" / "capture.toml").is_file()
    (tmp / "src" / "camera_pos.txt").write_text("0 0 30\n")
    r = CliRunner().invoke(main, ["import", str(tmp / "src"), "--out", str(tmp / "cap2")])
    assert r.exit_code == 2 and not (tmp / "cap2").exists()
    assert r.output.strip().splitlines() == [
        "error: camera_pos.txt: has 1 lines but " + str(tmp / "src") + " holds 4 images (one line each)"
    ]
