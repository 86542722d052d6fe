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
    pages = (
        "cli",
        "report",
        "image-based",
        "smartphone",
        "engine",
        "texture",
        "missing-effects",
        "rendering",
        "layout",
    )
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


# --------------------------------------------------------------------------- the manual's form

PAGES = sorted((ROOT / "docs").rglob("*.md"))
# A page or the README that tells how the code came to be rather than what it does.
HISTORY = re.compile(r"\bissues? #?[0-9]|\bsessions?\b", re.I)
MAX_PAGE_LINES = 300


def test_no_page_names_an_issue_or_a_session():
    hits = [
        f"{path.relative_to(ROOT)}:{i}: {line.strip()[:80]}"
        for path in (*PAGES, ROOT / "README.md")
        for i, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1)
        if HISTORY.search(line)
    ]
    assert not hits, "\n".join(hits)


def test_no_page_is_over_300_lines():
    long = {str(p.relative_to(ROOT)): n for p in PAGES if (n := len(p.read_text(encoding="utf-8").splitlines())) > 300}
    assert not long, long


def test_the_history_regex_catches_what_it_should():
    assert HISTORY.search("as issue 13 asks") and HISTORY.search("the third session") and HISTORY.search("Issues 4")
    assert not HISTORY.search("the issue asks nothing") and not HISTORY.search("sessional")


def _roles():
    sys.path.insert(0, str(ROOT / "docs" / "_tools"))
    import sphinx_roles

    return sphinx_roles


def test_docstring_roles_become_cross_references():
    # The griffe extension mkdocs.yml loads: every Sphinx role in a docstring is rewritten, a public target as a link.
    import griffe

    roles = _roles()
    pkg = griffe.load("wardjax", search_paths=[str(ROOT)], resolve_aliases=False)
    before = sum(len(roles.ROLE.findall(o.docstring.value)) for o in roles._objects(pkg) if o.docstring)
    assert before > 100  # the docstrings are numpydoc with Sphinx roles: the extension has work to do
    roles.convert_package(pkg)
    left = [o.path for o in roles._objects(pkg) if o.docstring and roles.RAW_ROLE.search(o.docstring.value)]
    assert not left, left
    fit_capture = pkg["run._fit_capture.fit_capture"]
    # ":class:`~wardjax.Capture`" in its docstring: a link to the public name, shown by its last component
    assert (
        '<autoref identifier="wardjax.Capture" optional><code>Capture</code></autoref>' in fit_capture.docstring.value
    )
    scanline = pkg["run._fit_capture"]
    # ":func:`wardjax.reconstruct_brdf`" (a re-export) and ":meth:`~wardjax.ScanlineFit.combined`" resolve too
    assert 'identifier="wardjax.reconstruct_brdf"' in scanline.docstring.value
    assert "<code>combined()</code>" in scanline.docstring.value


def test_built_site_shows_no_raw_role(site):
    roles = _roles()
    bad = {
        str(p.relative_to(site)): len(roles.RAW_ROLE.findall(p.read_text(encoding="utf-8")))
        for p in site.rglob("*.html")
        if roles.RAW_ROLE.search(p.read_text(encoding="utf-8"))
    }
    assert not bad, bad
    fit_page = (site / "api" / "fit" / "index.html").read_text(encoding="utf-8")
    assert re.search(r'<a class="autorefs autorefs-internal"[^>]*href="[^"]*#wardjax\.ward\.WardParams"', fit_page) or (
        re.search(r'<a class="autorefs autorefs-internal"[^>]*WardParams', fit_page)
    )
