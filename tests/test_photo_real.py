"""Real flash photographs (``tests/data/flash/``, licences beside them) loaded and fitted end to end.

What can be checked on photos nobody here took: the EXIF the loader reads
against the values Pillow's own tag table gives; the grey card's light power
neutral (a grey card reflects the three channels alike, so P_r : P_g : P_b is
the white balance of the phone, near 1); every diffuse estimate ``π f_r`` a
reflectance (0 to 1); the dataset's own ambient export refused as a dark
frame with one line saying why; and the CLI fitting each photo, writing its
report.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

import wardjax as wj
from wardjax.capture import CaptureError, PhotoCapture, read_exif

DATA = Path(__file__).parent / "data" / "flash"
REAL = sorted(p.name for p in DATA.iterdir() if (p / "capture.toml").is_file())


def test_01_the_real_captures_are_there_with_their_licences():
    assert REAL == [
        "deschaintre2018_20180115_135508",
        "deschaintre2018_20180115_143924",
        "green_towel",
        "matfusion_pink",
    ]
    for name in REAL:
        assert any((DATA / name / f).is_file() for f in ("LICENSE", "LICENSE.txt"))
    assert "Apache License" in (DATA / "matfusion_pink" / "LICENSE-2.0.txt").read_text()


def test_02_green_towel_exif():
    from PIL import ExifTags, Image

    with Image.open(DATA / "green_towel" / "point.jpg") as im:
        sub = im.getexif().get_ifd(ExifTags.IFD.Exif)
        names = ("ExposureTime", "FNumber", "ISOSpeedRatings", "FocalLengthIn35mmFilm")
        want = {ExifTags.TAGS[k]: float(v) for k, v in sub.items() if ExifTags.TAGS.get(k) in names}
    ex = read_exif(DATA / "green_towel" / "point.jpg")
    assert ex.exposure_time == pytest.approx(want["ExposureTime"]) == pytest.approx(0.1)
    assert ex.f_number == pytest.approx(want["FNumber"]) and ex.iso == want["ISOSpeedRatings"] == 100
    assert ex.focal_35mm == want["FocalLengthIn35mmFilm"] == 27
    card = read_exif(DATA / "green_towel" / "greycard.jpg")
    assert card.exposure_time == pytest.approx(0.1) and card.f_number is None and card.iso is None


def test_03_green_towel_loads_with_a_neutral_card():
    cap = wj.load_capture(DATA / "green_towel")
    assert isinstance(cap, PhotoCapture) and cap.f_r.shape == (75, 100, 1, 3)
    p = cap.light_power
    assert np.all(np.abs(p / p.mean() - 1) < 0.1)  # the grey card is grey: the phone's white balance near neutral
    rho = np.pi * cap.f_r[cap.mask]
    assert cap.mask.mean() > 0.95 and np.nanmin(rho) > 0 and np.nanmax(rho) < 1
    assert np.median(rho[:, 1]) > 1.5 * np.median(rho[:, 0]) > 3 * np.median(rho[:, 2])  # a yellow-green towel


@pytest.mark.parametrize(
    ("edit", "needle"),
    [
        (
            lambda t: t.replace("[standard]", '[dark]\nfile = "ambient.jpg"\n\n[standard]'),
            "ambient.jpg: on the exposure scale of point.jpg (×5, from the exposures) it is brighter than point.jpg",
        ),
        (
            lambda t: t.replace('file = "point.jpg"', 'file = "point.jpg"\nexposure_time = 0.05'),
            "capture.toml: photo.exposure_time: 0.05 contradicts the EXIF of point.jpg (ExposureTime = 0.1)",
        ),
        (
            lambda t: t.replace("f_number = 2.2 ", "# f_number = 2.2"),
            "capture.toml: standard.exposure_time: the exposure of greycard.jpg is not known",
        ),
        (
            lambda t: t.replace("distance = 185.0", "distance = 185.0\nfocal_px = 900.0"),
            "capture.toml: camera.focal_px: 900 contradicts the EXIF of point.jpg (FocalLengthIn35mmFilm = 27 mm",
        ),
    ],
    ids=["ambient as dark", "exposure contradicts", "exif missing", "focal contradicts"],
)
def test_04_green_towel_bad_input(tmp_path, edit, needle):
    folder = tmp_path / "towel"
    shutil.copytree(DATA / "green_towel", folder)
    (folder / "capture.toml").write_text(edit((folder / "capture.toml").read_text()))
    with pytest.raises(CaptureError) as e:
        wj.load_capture(folder)
    assert str(e.value).startswith(needle) and "\n" not in str(e.value)


@pytest.mark.parametrize("name", [n for n in REAL if n != "green_towel"])
def test_05_single_flash_photos_load(name):
    cap = wj.load_capture(DATA / name)
    assert cap.f_r.shape == (128, 128, 1, 3) and cap.mask.mean() > 0.85
    assert "no photo has its exposure" in cap.notes[0]
    # the flash at the lens: wi = wo, and the mirror direction (normal incidence) at the image centre
    np.testing.assert_allclose(cap.wi, cap.wo, atol=1e-12)
    cos = cap.wo[..., 0, 2]
    assert np.unravel_index(np.argmax(cos), cos.shape) in {(63, 63), (63, 64), (64, 63), (64, 64)}
    assert np.degrees(np.arccos(cos.min())) == pytest.approx(np.degrees(np.arctan(np.hypot(127, 127) / 309)), abs=1)
