"""The documentation site builds with warnings as errors and documents every public name."""

import importlib
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

import wardjax as wj

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def site(tmp_path_factory):
    if shutil.which("mkdocs", path=str(Path(sys.executable).parent)) is None:
        pytest.fail("mkdocs is not installed in the test environment (it is a dev dependency: make install)")
    out = tmp_path_factory.mktemp("site")
    env = {**os.environ, "NO_MKDOCS_2_WARNING": "1"}
    mkdocs = str(Path(sys.executable).parent / "mkdocs")
    res = subprocess.run(
        [mkdocs, "build", "--strict", "-d", str(out)],  # not -q: quiet hides the warnings strict counts
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert res.returncode == 0, res.stdout + res.stderr
    return out


def _anchors(site: Path) -> set[str]:
    ids = set()
    for page in (site / "api").rglob("*.html"):
        ids |= set(re.findall(r'id="(wardjax[\w.]*)"', page.read_text(encoding="utf-8")))
    return ids


def test_every_public_name_is_in_the_api_reference(site):
    ids = _anchors(site)
    # where each name comes from: ``from .fit import ScanlineFit as ScanlineFit`` → wardjax.fit
    source = {
        name: mod
        for mod, name in re.findall(
            r"^\s*from \.(\w*) import (\w+) as \2$", (ROOT / "wardjax/__init__.py").read_text(), re.M
        )
    }
    missing = []
    for name in wj.__all__:
        if name == "effects":
            ok = "wardjax.effects" in ids
        else:
            ok = f"wardjax.{source[name]}.{name}" in ids
        if not ok:
            missing.append(name)
    assert not missing, f"public names missing from the API reference: {missing}"


def test_stage_packages_list_their_reexports_in_all():
    # __all__ is what the API reference documents: it must list exactly the explicit re-exports.
    for pkg in (
        "wardjax",
        "wardjax.capture",
        "wardjax.reconstruct",
        "wardjax.fit",
        "wardjax.texture",
        "wardjax.smartphone",
        "wardjax.export",
        "wardjax.render",
        "wardjax.simulate",
        "wardjax.effects",
        "wardjax.report",
        "wardjax.run",
    ):
        mod = importlib.import_module(pkg)
        src = Path(mod.__file__).read_text(encoding="utf-8")
        exported = set(re.findall(r"^\s*from \S+ import (\w+) as \1$", src, re.M))
        assert set(mod.__all__) == exported, pkg


def test_method_pages_and_notebooks_are_in_the_site(site):
    pages = ("cli", "image-based", "smartphone", "engine", "texture", "missing-effects", "rendering", "layout")
    for page in (*pages, "benchmarks"):
        assert (site / page / "index.html").is_file(), page
    for nb in ("alpha_uncertainty", "missing_effects", "fit_folder", "texture", "validation"):
        assert (site / "notebooks" / nb / "index.html").is_file(), nb


def test_notebooks_are_stored_executed():
    # The notebooks are read on the site and on GitHub as they are stored: with their outputs
    # (make notebooks re-executes them in place); the tests execute them again.
    import nbformat

    for path in sorted((ROOT / "notebooks").glob("*.ipynb")):
        nb = nbformat.read(path, as_version=4)
        code = [c for c in nb.cells if c.cell_type == "code"]
        assert code and all(c.get("execution_count") for c in code), f"{path.name}: a code cell was not executed"
        assert not [o for c in code for o in c.get("outputs", []) if o.output_type == "error"], path.name
        assert any("image/png" in o.get("data", {}) for c in code for o in c.get("outputs", [])), path.name
