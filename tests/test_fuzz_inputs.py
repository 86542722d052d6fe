"""Property-based fuzzing (hypothesis) of every input boundary: nothing escapes the one-line rules.

Targets: ``capture.toml`` of both methods (documents built from a valid one
with fields replaced by wrong types, out-of-range, non-finite, huge or nested
values, removed, or added; and raw or edited bytes), the image readers
(truncated, garbled and valid-but-wrong images: channel counts, bit depths,
sizes, kinds of file, mismatched lit/dark pairs), ``texture.json``/``.npz``
and the command line's argument parsers.

The property, for every generated input: it loads — and then what was read
lies within the rules of :mod:`wardjax._rules` — or it is refused with
the project's error (:class:`~wardjax.capture.CaptureError`, the
``ValueError`` of the texture loader, the CLI's ``error:`` line) on one line
naming the file or field; never another exception, never a traceback, never
"unexpected failure". Escapes found by these tests are kept as ``@example``.

The default suite runs a small derandomised profile (reproducible); the slow
suite runs ≥ 10,000 inputs in all, with a failure database in ``.hypothesis/``.
"""

from __future__ import annotations

import copy
import io
import json
import math
import re
import shutil
from collections.abc import Callable
from pathlib import Path

import imagecodecs
import numpy as np
import pytest
import tifffile
import tomli_w
from click.testing import CliRunner
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st
from hypothesis.database import DirectoryBasedExampleDatabase

import wardjax as wj
from wardjax._rules import MAX_DISTANCE_MM
from wardjax.capture import CaptureError, RuleError, check_focal_px, load_capture, one_line
from wardjax.capture._setup import load_display
from wardjax.texture import TextureModel

ROOT = Path(__file__).resolve().parents[1]
BAD_TEXT = ("Traceback", "unexpected failure", "internal error", "Value error,", "capture.toml: capture.toml")
_COMMON = {"deadline": None, "suppress_health_check": [HealthCheck.too_slow, HealthCheck.data_too_large]}
# Default suite: a few hundred inputs in all, the same ones every run.
QUICK = settings(max_examples=60, derandomize=True, database=None, **_COMMON)
# Slow suite: ≥ 10,000 inputs in all (the counts per target below), failures kept in .hypothesis/.
_DB = DirectoryBasedExampleDatabase(ROOT / ".hypothesis" / "examples")


def slow(n: int):
    return settings(max_examples=n, database=_DB, **_COMMON)


def is_one_line(text: str) -> bool:
    return len(text.splitlines()) == 1 and not any(b in text for b in BAD_TEXT)


# --------------------------------------------------------------------------- values of every wrong kind

SCALARS = st.one_of(
    st.booleans(),
    st.integers(min_value=-(2**63), max_value=2**63 - 1),
    st.sampled_from([0, 1, -1, 2, 8, 16, 48, 64, 2**31, 2**63 - 1]),
    st.floats(),  # NaN, ±inf, ±0, subnormals, ±1.8e308
    st.floats(min_value=-1e3, max_value=1e3),
    st.text(max_size=12),  # newlines, NUL, any script
    st.sampled_from(["", "srgb", "linear", "lit.png", "../lit.png", "/etc/passwd", "a\nb", "photo.png", "\x00"]),
    st.datetimes(),
    st.dates(),
)
VALUES = st.recursive(
    SCALARS,
    lambda inner: st.lists(inner, max_size=5) | st.dictionaries(st.text(min_size=1, max_size=6), inner, max_size=3),
    max_leaves=8,
)
NUMBERS = st.one_of(st.floats(), st.integers(min_value=-(2**63), max_value=2**63 - 1))
VECTORS = st.lists(NUMBERS, min_size=0, max_size=5)


def _fields(doc: dict, prefix: tuple = ()) -> list[tuple]:
    out = []
    for k, v in doc.items():
        out.append((*prefix, k))
        if isinstance(v, dict):
            out += _fields(v, (*prefix, k))
    return out


# An edit of a document: (which field, by index modulo the fields there are; what to do; the value).
EDITS = st.lists(
    st.tuples(
        st.integers(0, 1000),
        st.one_of(
            st.tuples(st.just("any"), VALUES),
            st.tuples(st.just("number"), NUMBERS),
            st.tuples(st.just("vector"), VECTORS),
            st.tuples(st.just("same-length"), st.lists(NUMBERS, min_size=1, max_size=5)),
            st.tuples(st.just("delete"), st.none()),
            st.tuples(st.just("extra"), st.tuples(st.text(min_size=1, max_size=8), VALUES)),
        ),
    ),
    min_size=1,
    max_size=3,
)


def apply_edits(base: dict, edits) -> dict:
    """``base`` with each edit: a field replaced (any kind, or a number/vector of its length), removed or added."""
    doc = copy.deepcopy(base)
    for index, (op, value) in edits:
        fields = _fields(doc)
        if not fields:
            doc[str(index)] = value
            continue
        path = fields[index % len(fields)]
        parent = doc
        for k in path[:-1]:
            parent = parent[k]
        old = parent[path[-1]]
        if op == "delete":
            del parent[path[-1]]
        elif op == "extra":
            (old if isinstance(old, dict) else parent)[value[0]] = value[1]
        elif op == "same-length" and isinstance(old, list):
            parent[path[-1]] = (value * len(old))[: len(old)]
        else:
            parent[path[-1]] = value
    return doc


def _toml_bytes(doc: dict) -> bytes | None:
    try:
        return tomli_w.dumps(doc).encode()
    except (TypeError, ValueError):  # not representable in TOML (e.g. a list mixing tables and values)
        return None


# A byte edit: (where, by index modulo the length; what; the bytes inserted or the byte written).
BYTE_EDITS = st.lists(
    st.tuples(
        st.integers(0, 1 << 20),
        st.sampled_from(["replace", "insert", "delete", "truncate"]),
        st.binary(min_size=1, max_size=8),
    ),
    min_size=1,
    max_size=4,
)


def edit_bytes(data: bytes, edits) -> bytes:
    """``data`` with a few bytes replaced, inserted or deleted, or cut short."""
    b = bytearray(data)
    for where, op, payload in edits:
        i = where % (len(b) + 1)
        if op == "replace" and i < len(b):
            b[i] = payload[0]
        elif op == "insert":
            b[i:i] = payload
        elif op == "delete":
            del b[i : i + len(payload)]
        elif op == "truncate":
            del b[i:]
    return bytes(b)


# --------------------------------------------------------------------------- fixtures

PROBE = wj.WardParams(rho_d=(0.5, 0.45, 0.4), rho_s=0.04, alpha_x=0.12, alpha_y=0.12)
# The capture.toml simulate_capture writes for a 64 × 48 capture, and a smartphone capture's (both valid).
SCAN_DOC = {
    "method": "scanline",
    "rho_standard": 0.99,
    "images": {"lit": "lit.png", "dark": "dark.png", "encoding": "srgb", "bit_depth": 8},
    "rig": {"lamp": [0.0, 300.0, 400.0], "camera": [0.0, -300.0, 400.0]},
    "camera": {
        "look_at": [0.0, 0.0, 0.0],
        "up": [0.0, 0.0, 1.0],
        "focal_px": 78.72,
        "principal_point": [31.5, 23.5],
        "image_size": [64, 48],
    },
    "regions": {"probe": [3.0, 120.0, -150.0, 150.0], "standard": [-120.0, -3.0, -150.0, 150.0]},
    "material": {"tangent": [1.0, 0.0]},
    "fit": {"model": "isotropic", "normalization": "ward1992", "noise_floor": 0.002},
}
PHONE_DOC = {
    "method": "smartphone",
    "name": "phone",
    "photo": {"file": "photo.png", "region": [20, 80, 30, 100], "decoding": "gamma2.2"},
    "thresholds": {"ppb": [10, 11, 12]},
    "setup": {"display": "iphone5s", "viewing": "paper"},
    "specular": {"n": 1.5, "n_range": [1.4, 1.7]},
    "fit": {"seed": 0},
}


class _Work(dict):
    """The fixture's folders and files; shown by name in hypothesis's reports (not its bytes)."""

    def __repr__(self) -> str:
        return "work"


# The fields of a texture description, in the order TextureModel.to_dict writes them (for the edits' indices).
TEXTURE_DOC = dict.fromkeys(
    [
        "format",
        "version",
        "height",
        "orientations",
        "channels",
        "n_quantiles",
        "source_shape",
        "region",
        "region_source",
        "rho_s",
        "pca_mean",
        "pca_basis",
        "probabilities",
        "pixel_quantiles",
        "band_names",
        "band_quantiles",
    ]
)


@pytest.fixture(scope="module")
def work(tmp_path_factory) -> dict:
    """A scanline capture and a smartphone capture to edit, a texture model, a ρd map; all under one folder."""
    root = tmp_path_factory.mktemp("fuzz")
    good = root / "good"
    wj.simulate_capture(PROBE, good, seed=3, image_size=(64, 48))
    (good / "capture.toml").write_text(tomli_w.dumps(SCAN_DOC))
    photo = np.clip(np.random.default_rng(1).normal(150, 20, (96, 128, 3)), 0, 255).astype(np.uint8)
    phone = root / "phone"
    phone.mkdir()
    (phone / "photo.png").write_bytes(imagecodecs.png_encode(photo))
    (phone / "capture.toml").write_text(tomli_w.dumps(PHONE_DOC))
    for folder in (good, phone):
        _rules_hold(load_capture(folder))  # the unedited captures load
    rho = 0.4 + 0.05 * np.random.default_rng(5).standard_normal((32, 32))
    np.save(root / "rho.npy", rho)
    model = wj.analyze_texture(rho, height=1, n_quantiles=9)
    model.save(root / "model.json")
    model.save(root / "model.npz")
    assert list(model.to_dict()) == list(TEXTURE_DOC)
    return _Work(
        root=root,
        good=good,
        lit=(good / "lit.png").read_bytes(),
        phone=phone,
        photo=imagecodecs.png_encode(photo),
        texture=model.to_dict(),
    )


def _fresh(work: dict, kind: str) -> Path:
    """A clean copy of the scanline (``"good"``) or smartphone (``"phone"``) capture to edit."""
    dst = work["root"] / f"edit-{kind}"
    if dst.exists():
        shutil.rmtree(dst)
    shutil.copytree(work[kind], dst)
    return dst


# --------------------------------------------------------------------------- the property for captures


def _rules_hold(cap) -> None:
    """What a capture loaded with lies within the rules (the loader's promise)."""
    cfg = cap.config
    if cap.method == "smartphone":
        y0, y1, x0, x1 = cfg.photo.region
        h, w = cap.photo.shape[:2]
        assert 0 <= y0 < y1 <= h and 0 <= x0 < x1 <= w, cfg.photo.region
        assert cap.photo.ndim == 3 and cap.photo.shape[-1] == 3 and cap.photo.dtype in (np.uint8, np.uint16)
        disp = load_display(cfg.setup.display)
        ppb = cfg.thresholds.ppb or [cfg.thresholds.ppb_mean]
        assert all(disp.ppb_min <= p <= disp.ppb_max for p in ppb), ppb
        assert 1 < cfg.specular.n_range[0] <= cfg.specular.n <= cfg.specular.n_range[1] < 4
        return
    for v in (cfg.rig.lamp, cfg.rig.camera, cfg.camera.look_at):
        assert all(not isinstance(x, bool) and math.isfinite(x) for x in v), v
        assert np.linalg.norm(v) <= MAX_DISTANCE_MM, v
    w, h = cfg.camera.image_size
    check_focal_px("camera.focal_px", cfg.camera.focal_px, w)
    assert cap.lit.shape == (h, w, 3) and np.isfinite(cap.lit).all()
    assert all(0 < r <= 1 for r in cfg.rho_standard)
    assert math.isfinite(cfg.fit.noise_floor) and cfg.fit.noise_floor >= 0
    t = cap.tangent
    assert all(math.isfinite(x) for x in t) and abs(math.hypot(*t) - 1) < 1e-9, t
    assert np.isfinite(np.asarray(cfg.camera.up, float)).all() and max(abs(v) for v in cfg.camera.up) > 0


def _load_or_refuse(folder: Path) -> None:
    try:
        cap = load_capture(folder)
    except CaptureError as e:
        text = str(e)
        assert is_one_line(text), repr(text)
        assert e.file and text.startswith(e.file), text
    else:
        _rules_hold(cap)


def _write_doc(folder: Path, doc: dict) -> bool:
    data = _toml_bytes(doc)
    if data is None:
        return False
    (folder / "capture.toml").write_bytes(data)
    return True


# --------------------------------------------------------------------------- capture.toml, both methods


def _toml_edits(work, kind: str, edits) -> None:
    folder = _fresh(work, kind)
    if _write_doc(folder, apply_edits(SCAN_DOC if kind == "good" else PHONE_DOC, edits)):
        _load_or_refuse(folder)


def _toml_bytes_fuzz(work, kind: str, raw) -> None:
    folder = _fresh(work, kind)
    if not isinstance(raw, bytes):  # an edit plan of the valid file's bytes
        base = _toml_bytes(SCAN_DOC if kind == "good" else PHONE_DOC)
        assert base is not None
        raw = edit_bytes(base, raw)
    (folder / "capture.toml").write_bytes(raw)
    _load_or_refuse(folder)


KIND = st.sampled_from(["good", "phone"])
RAW = st.one_of(st.binary(max_size=400), BYTE_EDITS)


def _at(doc: dict, *path: str) -> int:
    """The edit index of the field at ``path``."""
    return _fields(doc).index(path)


# Escapes these tests found, kept (each was fixed at the boundary):
@given(edits=EDITS)
@example(edits=[(0, ("extra", ("\n", False)))])  # a key holding a line break: shown escaped, on one line
@example(edits=[(_at(SCAN_DOC, "material", "tangent"), ("vector", [1e308, 1e308]))])  # norm overflowed: (0, 0)
@example(edits=[(_at(SCAN_DOC, "rig", "lamp"), ("vector", [0.0, 1e200, 1e200]))])  # distance overflowed (warning)
@example(edits=[(_at(SCAN_DOC, "camera", "up"), ("vector", [1e308, 1e308, 1e308]))])  # the camera's axes NaN
@QUICK
def test_scanline_capture_toml_quick(work, edits):
    _toml_edits(work, "good", edits)


@given(edits=EDITS)
@example(edits=[(_at(PHONE_DOC, "thresholds", "ppb"), ("vector", [121]))])  # a grating the phone never showed
@example(edits=[(_at(PHONE_DOC, "photo", "file"), ("any", "/etc/hostname"))])  # a photo outside the folder
@QUICK
def test_smartphone_capture_toml_quick(work, edits):
    _toml_edits(work, "phone", edits)


@given(kind=KIND, raw=RAW)
@example(kind="good", raw=b"a = " + b"[" * 100_000)  # RecursionError from the TOML parser
@QUICK
def test_capture_toml_bytes_quick(work, kind, raw):
    _toml_bytes_fuzz(work, kind, raw)


@pytest.mark.slow
@given(edits=EDITS)
@slow(3000)
def test_scanline_capture_toml_slow(work, edits):
    _toml_edits(work, "good", edits)


@pytest.mark.slow
@given(edits=EDITS)
@slow(2000)
def test_smartphone_capture_toml_slow(work, edits):
    _toml_edits(work, "phone", edits)


@pytest.mark.slow
@given(kind=KIND, raw=RAW)
@slow(1500)
def test_capture_toml_bytes_slow(work, kind, raw):
    _toml_bytes_fuzz(work, kind, raw)


# --------------------------------------------------------------------------- image readers

# An image file: ("random", bytes) | ("original", byte edits of the capture's own file) |
# (kind, how, shape, dtype, channels, fill, drop the channel axis, byte edits for "garbled")
IMAGE_FILES = st.one_of(
    st.tuples(st.just("random"), st.sampled_from(["png", "tif", "jpg"]), st.binary(max_size=300)),
    st.tuples(st.just("original"), st.just("png"), BYTE_EDITS),
    st.tuples(
        st.sampled_from(["valid", "garbled"]),
        st.sampled_from(["png", "tif", "jpg"]),
        st.tuples(
            st.sampled_from([(48, 64), (40, 60), (96, 128), (1, 1), (3, 2)]),
            st.sampled_from(["uint8", "uint16", "int16", "float32", "float64", "bool"]),
            st.integers(1, 5),
            st.sampled_from(["noise", "zeros", "max"]),
            st.booleans(),
            BYTE_EDITS,
        ),
    ),
)


def image_bytes(spec, original: bytes) -> tuple[str, bytes]:
    """The (suffix, bytes) of an :data:`IMAGE_FILES` spec; arrays a format cannot hold fall back to what it can."""
    how, kind, detail = spec
    if how == "random":
        return kind, detail
    if how == "original":
        return kind, edit_bytes(original, detail)
    shape, dtype, channels, fill, squeeze, edits = detail
    if kind == "jpg":
        dtype, channels = "uint8", 1 if channels < 3 else 3
    elif kind == "png":
        dtype, channels = ("uint16" if dtype == "uint16" else "uint8"), min(channels, 4)
    top = 1 if dtype in ("bool", "float32", "float64") else np.iinfo(dtype).max
    full = (*shape, channels)
    a = {"noise": np.random.default_rng(0).uniform(0, top, full), "zeros": np.zeros(full)}.get(fill, np.full(full, top))
    a = a.astype(dtype)
    if channels == 1 and (squeeze or kind == "jpg"):
        a = a[..., 0]
    if kind == "png":
        data = imagecodecs.png_encode(np.ascontiguousarray(a))
    elif kind == "tif":
        buf = io.BytesIO()
        tifffile.imwrite(buf, a, photometric="rgb" if a.ndim == 3 and a.shape[-1] == 3 else "minisblack")
        data = buf.getvalue()
    else:
        import imageio.v3 as iio

        data = iio.imwrite("<bytes>", a, extension=".jpg")
    if how == "garbled":
        # past PNG's IHDR and JPEG's headers (the size stays honest: no decompression bomb); a TIFF is cut short
        cut = {"png": 41, "tif": len(data), "jpg": len(data) // 2}[kind]
        data = (
            data[:cut] + edit_bytes(data[cut:], edits)
            if kind != "tif"
            else edit_bytes(data, [(edits[0][0], "truncate", b"")])
        )
    return kind, data


ENCODINGS = st.tuples(st.sampled_from([8, 16]), st.sampled_from(["srgb", "gamma2.2", "linear"]))


def _scanline_images(work, images, encoding) -> None:
    folder = _fresh(work, "good")
    doc = copy.deepcopy(SCAN_DOC)
    for role, spec in images:
        kind, raw = image_bytes(spec, work["lit"])
        name = f"{role}-fuzz.{kind}"
        (folder / name).write_bytes(raw)
        doc["images"][role] = name
    doc["images"]["bit_depth"], doc["images"]["encoding"] = encoding
    assert _write_doc(folder, doc)
    _load_or_refuse(folder)


def _phone_images(work, spec, small_region) -> None:
    folder = _fresh(work, "phone")
    kind, raw = image_bytes(spec, work["photo"])
    (folder / f"photo-fuzz.{kind}").write_bytes(raw)
    doc = copy.deepcopy(PHONE_DOC)
    doc["photo"]["file"] = f"photo-fuzz.{kind}"
    doc["photo"]["region"] = [0, 1, 0, 1] if small_region else [20, 80, 30, 100]
    assert _write_doc(folder, doc)
    _load_or_refuse(folder)


PAIRS = st.lists(st.tuples(st.sampled_from(["lit", "dark"]), IMAGE_FILES), min_size=1, max_size=2)


@given(images=PAIRS, encoding=ENCODINGS)
@QUICK
def test_capture_images_quick(work, images, encoding):
    _scanline_images(work, images, encoding)


@given(spec=IMAGE_FILES, small_region=st.booleans())
@example(spec=("random", "jpg", b"\x00"), small_region=False)  # struct.error from a reader; the file left open
@example(spec=("valid", "tif", ((96, 128), "float32", 3, "noise", False, [(0, "truncate", b"")])), small_region=False)
@QUICK
def test_smartphone_photo_quick(work, spec, small_region):
    _phone_images(work, spec, small_region)


@pytest.mark.slow
@given(images=PAIRS, encoding=ENCODINGS)
@slow(1200)
def test_capture_images_slow(work, images, encoding):
    _scanline_images(work, images, encoding)


@pytest.mark.slow
@given(spec=IMAGE_FILES, small_region=st.booleans())
@slow(600)
def test_smartphone_photo_slow(work, spec, small_region):
    _phone_images(work, spec, small_region)


# --------------------------------------------------------------------------- texture.json / .npz


def _npz_bytes(doc: dict) -> bytes:
    arrays = {}
    for k, v in doc.items():
        try:
            arrays[k] = np.asarray(v)
        except (ValueError, TypeError, OverflowError):  # ragged or mixed: an object array (refused on load)
            arrays[k] = np.array([v, None], dtype=object)
    buf = io.BytesIO()
    np.savez(buf, **arrays)  # pyright: ignore[reportArgumentType]
    return buf.getvalue()


# ("fields", edits) | ("bytes", byte edits of the valid file) | ("random", bytes) | ("nested", depth)
TEXTURE_FILES = st.tuples(
    st.sampled_from([".json", ".npz"]),
    st.one_of(
        st.tuples(st.just("fields"), EDITS),
        st.tuples(st.just("bytes"), BYTE_EDITS),
        st.tuples(st.just("random"), st.binary(max_size=300)),
        st.tuples(st.just("nested"), st.integers(1, 200_000)),
    ),
)


def _texture(work, spec) -> None:
    suffix, (how, detail) = spec
    base = work["texture"]
    if how == "nested":  # deep nesting: a parser's recursion, not a model
        raw = ("[" * detail + "]" * detail).encode() if suffix == ".json" else _npz_bytes({"format": [[[1]]]})
    elif how == "random":
        raw = detail
    else:
        doc = apply_edits(base, detail) if how == "fields" else base
        raw = json.dumps(doc, default=str).encode() if suffix == ".json" else _npz_bytes(doc)
        if how == "bytes":
            raw = edit_bytes(raw, detail)
    path = work["root"] / f"texture-fuzz{suffix}"
    path.write_bytes(raw)
    try:
        model = TextureModel.load(path)
    except ValueError as e:
        assert is_one_line(str(e)) and str(e).startswith(str(path)), repr(str(e))
    else:
        assert np.all((model.rho_s >= 0) & (model.rho_s < 1)), model.rho_s
        assert 0 <= model.region[0] < model.region[1] <= model.source_shape[0], model.region
        assert 0 <= model.region[2] < model.region[3] <= model.source_shape[1], model.region
        basis = np.asarray(model.pca_basis)
        assert np.allclose(basis.T @ basis, np.eye(model.channels), atol=1e-4), basis


@given(spec=TEXTURE_FILES)
@example(spec=(".json", ("nested", 100_000)))  # RecursionError from the JSON parser
@example(spec=(".json", ("bytes", [(10, "insert", b"9" * 5000)])))  # an integer too long for int()
@example(spec=(".npz", ("random", b"PK\x03\x04 not a zip")))  # BadZipFile
@example(spec=(".json", ("fields", [(_at(TEXTURE_DOC, "rho_s"), ("same-length", [1.5]))])))  # ρs above 1
@example(spec=(".json", ("fields", [(_at(TEXTURE_DOC, "pca_basis"), ("same-length", [[2.0]]))])))  # not a basis
@QUICK
def test_texture_files_quick(work, spec):
    _texture(work, spec)


@pytest.mark.slow
@given(spec=TEXTURE_FILES)
@slow(1500)
def test_texture_files_slow(work, spec):
    _texture(work, spec)


# --------------------------------------------------------------------------- the command line's argument parsers

# Every option of every command with values of the right and wrong kinds; the heavy work behind each command is
# replaced by a stop (exit status 77) placed after the library's own checks, so that what reaches it can be checked.
REACHED = 77
PATHS = ["{good}", "{root}/rho.npy", "{root}/model.json", "{root}/model.npz", "{root}/no-such", "{good}/lit.png"]
PATHS += [f"{{root}}/cli-out/{n}" for n in ("o", "t.json", "t.npz", "s.tif", "s.png", "r.html", "x.txt")]
TOKENS = st.one_of(
    st.sampled_from(PATHS),
    st.sampled_from(["0", "1", "-1", "0.5", "1e30", "nan", "inf", "-inf", "", "x", "64x64", "0x10", "8", "16"]),
    st.sampled_from(["2", "20000", "20001", "15", "99999999999999999999", "true", "--", "-", "-h", "srgb", "png"]),
    st.sampled_from(["0:16,0:16", "0:0,0:0", "5:2,0:9", "a:b", "0:32,0:32", "0:64,0:64", "-3:5,0:9"]),
    st.integers(-(2**70), 2**70).map(str),
    st.floats().map(repr),
    st.text(max_size=8),
)
OPTIONS = {
    "fit": ["--out", "--force", "--quiet"],
    "simulate": ["--material", "--rho-d", "--rho-s", "--alpha-x", "--alpha-y", "--texture", "--encoding"]
    + ["--bit-depth", "--format", "--size", "--seed", "--renderer", "--force"],
    "texture analyze": ["-o", "--out", "--region", "--height", "--quantiles", "--rho-s"],
    "texture synthesize": ["--size", "--seed", "--iterations", "--match", "-o", "--out"],
    "diagnose": ["--out", "--max-steps", "--max-samples"],
    "report": ["-o", "--out"],
    "gratings": ["--display", "--viewing", "--out", "--orientation"],
    "demo": ["--out", "--seed"],
    "": ["--version", "--help", "--no-cache", "--cache-dir", "--bogus"],
}
# (command, [(option or None for a bare argument, its values)])
ARGVS = st.tuples(
    st.sampled_from(sorted(OPTIONS)),
    st.lists(st.tuples(st.one_of(st.none(), st.integers(0, 20)), st.lists(TOKENS, min_size=0, max_size=3)), max_size=6),
)


def _argv(spec, work) -> list[str]:
    command, parts = spec
    argv = command.split()
    fill = lambda t: t.replace("{good}", str(work["good"])).replace("{root}", str(work["root"]))
    for option, values in parts:
        if option is not None:
            argv.append(OPTIONS[command][option % len(OPTIONS[command])])
        argv += [fill(v) for v in values[: 1 if option is None else None]]
    return argv


def _stops(mp, reached: list) -> None:
    """Replace each command's heavy work by a stop that records the arguments it would have run with."""
    import wardjax.effects._capture
    import wardjax.report
    import wardjax.run._batch
    import wardjax.run._demo
    import wardjax.simulate._capture
    import wardjax.smartphone
    import wardjax.texture._analysis
    import wardjax.texture._synthesis

    def stop(name):
        def f(*args, **kwargs):
            reached.append((name, args, kwargs))
            raise SystemExit(REACHED)

        return f

    mp.setattr(wardjax.run._batch, "run_batch", stop("fit"))
    mp.setattr(wardjax.simulate._capture, "_rho_d_map", stop("simulate"))  # after the seed and parameter checks
    mp.setattr(wardjax.texture._analysis, "pyramid_shapes", stop("analyze"))  # after every argument check
    mp.setattr(wardjax.texture._synthesis, "pyramid_shapes", stop("synthesize"))
    mp.setattr(wardjax.effects._capture, "capture_data", stop("diagnose"))
    mp.setattr(wardjax.report, "write_report", stop("report"))
    mp.setattr(wardjax.smartphone, "write_gratings", stop("gratings"))
    mp.setattr(wardjax.run._demo, "run_capture_demo", stop("demo"))


def _cli(work, spec) -> None:
    from wardjax.run import main

    argv = _argv(spec, work)
    reached: list = []
    with pytest.MonkeyPatch.context() as mp:
        _stops(mp, reached)
        mp.chdir(work["root"])
        res = CliRunner().invoke(main, argv)
    text = res.output
    assert isinstance(res.exception, SystemExit) or res.exception is None, (argv, repr(res.exception))
    assert "Traceback" not in text and "unexpected failure" not in text, (argv, text)
    if res.exit_code == REACHED or (res.exit_code == 0 and not reached):  # ran, or --help / --version
        return
    lines = [ln for ln in text.splitlines() if ln.strip()]
    assert res.exit_code == 2, (argv, res.exit_code, text)
    assert 1 <= len(lines) <= 2 and lines[0].startswith("error: "), (argv, text)
    assert is_one_line(lines[0]), (argv, text)
    line, quoted = lines[0], re.findall(r"'([^']*)'", lines[0])
    shown = argv + [one_line(t) for t in argv]  # as typed, or with control characters escaped
    named = any((len(t) > 1 and t in line) or line.startswith(f"error: {t}: ") for t in shown)
    named = named or any(q in t for q in quoted for t in shown)
    named = named or re.search(
        r"'[A-Z_]+'|--[a-z-]+|Missing command|No such command|capture\.toml", line
    )  # a missing argument, option, command
    assert named, (argv, lines[0])


@given(spec=ARGVS)
@example(spec=("", []))  # `wardjax` alone: the help, not "error: Usage: …" over 17 lines
@example(spec=("demo", [(None, ["\x85"])]))  # a line break in an argument echoed
@example(spec=("texture synthesize", [(1, ["-1"])]))  # --seed -1: numpy's "expected non-negative integer"
@example(spec=("diagnose", [(None, ["0"])]))  # a one-character path, named first
@example(spec=("diagnose", [(None, ["a:b:"])]))  # rich printed the path "a:b:" as "a🅱"
@settings(QUICK, max_examples=60)
def test_cli_arguments_quick(work, spec):
    _cli(work, spec)


@pytest.mark.slow
@given(spec=ARGVS)
@slow(1500)
def test_cli_arguments_slow(work, spec):
    _cli(work, spec)


# --------------------------------------------------------------------------- library constructors

# A leaf of WardParams as a user may pass it: a number of any kind, a short list, a nested list, text.
LEAVES = st.one_of(
    NUMBERS,
    st.booleans(),
    st.complex_numbers(),
    st.text(max_size=3),
    st.lists(NUMBERS, min_size=0, max_size=4),
    st.lists(st.lists(st.floats(-2, 2), min_size=3, max_size=3), min_size=1, max_size=3),
    st.lists(st.one_of(NUMBERS, st.lists(NUMBERS, max_size=2)), min_size=1, max_size=3),  # ragged
)
PHYSICAL = st.floats(0, 1)


def _ward_rules_hold(p: wj.WardParams) -> None:
    """What a built WardParams holds, checked from the physics: finite; ρd ∈ [0, 1]; ρs ≥ 0; ρd + ρs ≤ 1; α > 0."""
    leaves = {k: np.asarray(getattr(p, k)) for k in ("rho_d", "rho_s", "alpha_x", "alpha_y")}
    for k, a in leaves.items():
        assert a.dtype.kind == "f" and np.all(np.isfinite(a)), (k, a)
    d, s = leaves["rho_d"], leaves["rho_s"]
    assert np.all((d >= 0) & (d <= 1)) and np.all(s >= 0)
    assert np.all(leaves["alpha_x"] > 0) and np.all(leaves["alpha_y"] > 0)
    try:
        total = d + (s[..., None] if s.ndim < d.ndim else s)
    except ValueError:
        return
    assert np.all(total <= 1 + 1e-12), total


def _construct(leaves: dict) -> None:
    try:
        p = wj.WardParams(**leaves)
    except RuleError as e:
        assert e.field in leaves, e
        assert is_one_line(str(e)) and len(str(e)) < 700, str(e)
        return
    _ward_rules_hold(p)


@given(rho_d=LEAVES, rho_s=LEAVES, alpha_x=LEAVES, alpha_y=LEAVES)
@example(rho_d=[0.5, 0.5, 0.5], rho_s=-1.0, alpha_x=0.1, alpha_y=0.1)  # built before the rules applied here
@example(rho_d=[0.5, 0.5, 0.5], rho_s=0.04, alpha_x=True, alpha_y=0.1)  # a boolean read as 1.0
@example(rho_d=[0.5, 0.5, 0.5], rho_s=0.04, alpha_x=1j, alpha_y=0.1)  # TypeError from the float converter
@QUICK
def test_ward_params_constructor_quick(rho_d, rho_s, alpha_x, alpha_y):
    _construct(dict(rho_d=rho_d, rho_s=rho_s, alpha_x=alpha_x, alpha_y=alpha_y))


@given(rho_d=st.lists(PHYSICAL, min_size=3, max_size=3), rho_s=PHYSICAL, alpha=st.floats(1e-4, 2))
@QUICK
def test_ward_params_physical_values_build_quick(rho_d, rho_s, alpha):
    """Every physical material builds; one that breaks energy conservation is refused on ``rho_s``."""
    leaves = dict(rho_d=rho_d, rho_s=rho_s, alpha_x=alpha, alpha_y=alpha)
    if max(rho_d) + rho_s <= 1:
        _ward_rules_hold(wj.WardParams(**leaves))
    else:
        with pytest.raises(RuleError, match="^rho_s: "):
            wj.WardParams(**leaves)


@pytest.mark.slow
@given(rho_d=LEAVES, rho_s=LEAVES, alpha_x=LEAVES, alpha_y=LEAVES)
@slow(3000)
def test_ward_params_constructor_slow(rho_d, rho_s, alpha_x, alpha_y):
    _construct(dict(rho_d=rho_d, rho_s=rho_s, alpha_x=alpha_x, alpha_y=alpha_y))


# --------------------------------------------------------------------------- report inputs


@pytest.fixture(scope="module")
def fits(tmp_path_factory) -> _Work:
    """A folder of fits in ``wardjax fit``'s layout (one scanline and one smartphone capture) and its documents."""
    from test_corpus import _write_fits

    root = tmp_path_factory.mktemp("fits")
    folder = _write_fits(root / "fits")
    docs = {n: json.loads((folder / n / "params.json").read_text()) for n in ("scan", "phone")}
    npz = {}
    for name, file in (("scan", "residuals.npz"), ("phone", "posterior.npz")):
        with np.load(folder / name / file) as z:
            npz[file] = {k: z[k] for k in z.files}
    return _Work(root=folder, docs=docs, npz=npz)


def _report_reads(folder: Path) -> None:
    """What the report's content reads of each capture's files: every value formatted, every table built."""
    from wardjax.report import load_fits
    from wardjax.report._collect import PARAMETERS, flag_outliers, load_chains
    from wardjax.report._figures import residual_figure
    from wardjax.report._sections import _chain_table, _errors_table

    results = load_fits(folder)
    flag_outliers(results)
    for r in results:
        shown = ["{:.4f} ± {:.2g}".format(*r.value(k)) for k in PARAMETERS]
        shown += [f"{v:.4f}" for v in r.doc["params"]["rho_d"]] + [f"{v:.2g}" for v in r.doc["stderr"]["rho_d"]]
        _errors_table(r)
        _chain_table(r)
        load_chains(r)
        if (r.folder / "residuals.npz").exists():
            residual_figure(r)


def _report_input(fits: _Work, write: Callable[[Path], None]) -> None:
    """Write one edited input; the report's validation refuses it on one line naming the file, or it reads cleanly."""
    from wardjax.report._validate import validate_fits_dir

    folder = fits["root"].parent / "edited"
    if folder.exists():
        shutil.rmtree(folder)
    shutil.copytree(fits["root"], folder)
    write(folder)
    try:
        validate_fits_dir(folder)
    except ValueError as e:
        text = str(e)
        assert is_one_line(text) and len(text) < 700, text
        assert text.startswith(str(folder)), text
        return
    _report_reads(folder)


def _params_edit(fits: _Work, name: str, edits) -> None:
    doc = apply_edits(fits["docs"][name], edits)
    text = json.dumps(doc, default=str)  # a date (a TOML value) is written as JSON writes it: text
    _report_input(fits, lambda f: (f / name / "params.json").write_text(text))


ARRAYS = st.one_of(
    st.lists(st.floats(), max_size=6).map(np.asarray),
    st.lists(st.integers(-5, 5), max_size=4).map(lambda v: np.asarray(v, np.int64)),
    st.sampled_from(
        [np.zeros((0, 3)), np.ones((2, 2, 3)), np.ones((3, 4)), np.array("x"), np.int64(0), np.float64(1.5)]
    ),
    st.tuples(st.integers(0, 4), st.integers(0, 4), st.integers(1, 4)).map(lambda s: np.ones(s, np.float32)),
)


def _npz_edit(fits: _Work, file: str, edits) -> None:
    arrays = dict(fits["npz"][file])
    keys = sorted(arrays)
    for index, value in edits:
        key = keys[index % len(keys)]
        if value is None:
            arrays.pop(key, None)
        else:
            arrays[key] = value
    buf = io.BytesIO()
    np.savez(buf, **arrays)
    name = "scan" if file == "residuals.npz" else "phone"
    _report_input(fits, lambda f: (f / name / file).write_bytes(buf.getvalue()))


NPZ_EDITS = st.lists(st.tuples(st.integers(0, 10), st.one_of(st.none(), ARRAYS)), min_size=1, max_size=3)


@given(name=st.sampled_from(["scan", "phone"]), edits=EDITS)
@settings(QUICK, max_examples=40)
def test_report_params_json_quick(fits, name, edits):
    _params_edit(fits, name, edits)


@given(file=st.sampled_from(["residuals.npz", "posterior.npz"]), edits=NPZ_EDITS)
@settings(QUICK, max_examples=20)
def test_report_npz_quick(fits, file, edits):
    _npz_edit(fits, file, edits)


@pytest.mark.slow
@given(name=st.sampled_from(["scan", "phone"]), edits=EDITS)
@slow(2000)
def test_report_params_json_slow(fits, name, edits):
    _params_edit(fits, name, edits)


@pytest.mark.slow
@given(file=st.sampled_from(["residuals.npz", "posterior.npz"]), edits=NPZ_EDITS)
@slow(500)
def test_report_npz_slow(fits, file, edits):
    _npz_edit(fits, file, edits)
