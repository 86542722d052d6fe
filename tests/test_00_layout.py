"""The package's layout: stages in the order of the flow, no import cycles, small modules, one writer.

The import graph is read from the source with ``ast`` (every ``import`` in a
module, function-level ones included; those under ``if TYPE_CHECKING:`` are
annotations, not imports, and are left out), so the tests see what a reader
sees and import nothing.
"""

from __future__ import annotations

import ast
import os
import stat
from pathlib import Path

import numpy as np
import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "wardjax"

# The flow, written once. A module may import modules of its own stage and of
# earlier ones; the base is shared by every stage.
BASE = (
    "wardjax.ward",
    "wardjax.geometry",
    "wardjax._files",
    "wardjax._rules",
    "wardjax._status",
    "wardjax._shapes",
    "wardjax._data",
    "wardjax._jit",
)
STAGES = (
    "capture",
    "reconstruct",
    "fit",
    "texture",
    "smartphone",
    "export",
    "render",
    "simulate",
    "effects",
    "report",
    "run",
)

MAX_MODULE_LINES = 700
MAX_FUNCTION_LINES = 120
ONE_PIECE = "# one piece:"  # a comment just above a longer function saying why it must stay whole


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(PACKAGE.parent).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


MODULES = {_module_name(p): p for p in sorted(PACKAGE.rglob("*.py"))}


def _is_type_checking(node: ast.If) -> bool:
    t = node.test
    return (isinstance(t, ast.Name) and t.id == "TYPE_CHECKING") or (
        isinstance(t, ast.Attribute) and t.attr == "TYPE_CHECKING"
    )


def _imports(name: str, annotations: bool = False) -> set[str]:
    """The wardjax modules that module ``name`` imports (packages resolve to their ``__init__``).

    ``annotations``: count the imports under ``if TYPE_CHECKING:`` too.
    """
    path = MODULES[name]
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    tree = ast.parse(path.read_text(encoding="utf-8"))
    skip = {
        id(n)
        for node in ast.walk(tree)
        if isinstance(node, ast.If) and _is_type_checking(node) and not annotations
        for n in ast.walk(node)
        if n is not node
    }
    out = set()
    for node in ast.walk(tree):
        if id(node) in skip:
            continue
        if isinstance(node, ast.Import):
            out |= {a.name for a in node.names if a.name.split(".")[0] == "wardjax"}
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                base = base[: len(base) - (node.level - 1)]
                mod = ".".join(base + ([node.module] if node.module else []))
            else:
                mod = node.module or ""
            if mod.split(".")[0] != "wardjax":
                continue
            for a in node.names:  # ``from . import _shapes`` names a module
                sub = f"{mod}.{a.name}"
                out.add(sub if sub in MODULES else mod)
    return {m for m in out if m in MODULES and m != name}


GRAPH = {name: _imports(name) for name in MODULES}


def _stage(name: str) -> int:
    """-1 for the base, the stage's index otherwise; the top-level ``wardjax`` namespace is last."""
    if name in BASE:
        return -1
    if name == "wardjax":
        return len(STAGES)
    return STAGES.index(name.split(".")[1])


def test_every_module_has_a_place_in_the_flow():
    unplaced = [m for m in MODULES if m != "wardjax" and m not in BASE and m.split(".")[1] not in STAGES]
    assert not unplaced, f"modules outside the stages {STAGES} and the base: {unplaced}"


def test_no_import_from_a_later_stage():
    bad = [
        f"{m} (stage {STAGES[_stage(m)] if _stage(m) >= 0 else 'base'}) imports {d}"
        for m, deps in GRAPH.items()
        for d in deps
        if _stage(d) > _stage(m) or (_stage(m) == -1 and _stage(d) != -1)
    ]
    assert not bad, "imports against the flow:\n" + "\n".join(sorted(bad))


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components of more than one module (Tarjan), or a module importing itself."""
    index, low, on, stack, out, counter = {}, {}, set(), [], [], [0]

    def visit(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in sorted(graph[v]):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1 or v in graph[v]:
                out.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


def test_no_import_cycles():
    # A package's __init__ imports its own modules; a module importing its own
    # package's __init__ would close a loop, and counts like any other.
    assert _cycles(GRAPH) == []


def test_no_cycle_between_private_modules_even_through_annotations():
    # Within a stage, two modules that need each other's names even for type hints are one idea split in two
    # (the packages' __init__ re-export lazily under TYPE_CHECKING: they are left out).
    graph = {m: _imports(m, annotations=True) for m in MODULES if MODULES[m].name != "__init__.py"}
    graph = {m: deps & graph.keys() for m, deps in graph.items()}
    assert _cycles(graph) == []


def test_the_cycle_finder_finds_cycles():
    assert _cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert _cycles({"a": {"b"}, "b": set()}) == []


def test_modules_and_functions_are_small():
    long_modules = {m: n for m, p in MODULES.items() if (n := len(p.read_text().splitlines())) > MAX_MODULE_LINES}
    assert not long_modules, f"modules over {MAX_MODULE_LINES} lines: {long_modules}"
    long_functions = []
    for m, p in MODULES.items():
        lines = p.read_text().splitlines()
        for node in ast.walk(ast.parse("\n".join(lines))):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                n = node.end_lineno - node.lineno + 1
                first = min([node.lineno] + [d.lineno for d in node.decorator_list])
                above = lines[max(first - 4, 0) : first - 1]
                if n > MAX_FUNCTION_LINES and not any(ONE_PIECE in line for line in above):
                    long_functions.append(f"{m}.{node.name}: {n} lines")
    assert not long_functions, f"functions over {MAX_FUNCTION_LINES} lines: {long_functions}"


def test_library_reads_no_data_outside_the_package():
    for m, p in MODULES.items():
        text = p.read_text()
        assert '"tests"' not in text and "'tests'" not in text, f"{m} reaches into tests/"


def _direct_writes(tree: ast.AST) -> list[str]:
    """Calls that write a file by themselves: ``open(..., "w…")``, ``.write_text``, ``.write_bytes``,
    ``mkstemp``, ``os.replace``, and ``imwrite``/``savefig``/``np.save*`` to anything but an in-memory buffer."""
    found = []
    for node in ast.walk(tree):
        if not isinstance(node, ast.Call):
            continue
        f = node.func
        name = f.attr if isinstance(f, ast.Attribute) else f.id if isinstance(f, ast.Name) else ""
        first = ast.unparse(node.args[0]) if node.args else ""
        if name == "open":
            mode = (
                node.args[1] if len(node.args) > 1 else next((k.value for k in node.keywords if k.arg == "mode"), None)
            )
            writes = isinstance(mode, ast.Constant) and isinstance(mode.value, str) and set(mode.value) & set("wax")
            if writes and first != "tmp":  # tmp: the temporary file atomic_path hands out
                found.append(f"open({first}, {mode.value!r})")
        elif name in ("write_text", "write_bytes", "mkstemp") or (
            name == "replace" and ast.unparse(f).startswith("os.")
        ):
            found.append(ast.unparse(f))
        elif (
            name in ("imwrite", "savefig", "savez", "savez_compressed") or ast.unparse(f) == "np.save"
        ) and first not in (
            "buf",
            "fh",
        ):
            found.append(f"{ast.unparse(f)}({first})")
    return found


def test_no_module_writes_files_but_through_the_atomic_writer():
    # Every output goes through wardjax._files (atomic, umask mode); a direct
    # write elsewhere would bypass both. Writing into an in-memory buffer (buf)
    # or into the writer's own temporary file (fh) is fine.
    bad = {
        m: w for m, p in MODULES.items() if m != "wardjax._files" and (w := _direct_writes(ast.parse(p.read_text())))
    }
    assert not bad, f"modules writing files directly: {bad}"


def test_the_write_finder_finds_writes():
    src = 'open(p, "w")\nopen(p)\nPath(p).write_text("x")\nfig.savefig(path)\nfig.savefig(buf)\nos.replace(a, b)\n'
    assert _direct_writes(ast.parse(src)) == ["open(p, 'w')", "Path(p).write_text", "fig.savefig(path)", "os.replace"]


# --------------------------------------------------------------------------- what the commands write


@pytest.fixture
def umask_022():
    old = os.umask(0o022)
    yield
    os.umask(old)


def _modes(folder: Path) -> dict[str, int]:
    return {str(p.relative_to(folder)): stat.S_IMODE(p.stat().st_mode) for p in folder.rglob("*") if p.is_file()}


@pytest.mark.slow
def test_every_output_has_the_umask_mode_and_no_temporary_survives(tmp_path, umask_022):
    from wardjax.run import main

    cap, fits, tex, diag = tmp_path / "cap", tmp_path / "fits", tmp_path / "tex", tmp_path / "diag"
    for args in (
        ["simulate", str(cap), "--size", "96", "72", "--seed", "1"],
        ["fit", str(cap), "--out", str(fits), "--quiet"],
        ["texture", "analyze", str(fits / "cap" / "rho_d.tif"), "-o", str(tex / "model.json")],
        ["texture", "synthesize", str(tex / "model.json"), "--size", "64x48", "-o", str(tex / "tile.png")],
        ["texture", "synthesize", str(tex / "model.json"), "--size", "64x48", "-o", str(tex / "tile.tif")],
        ["diagnose", str(cap), "--out", str(diag), "--max-steps", "0"],
    ):
        with pytest.raises(SystemExit) as e:
            main(args)
        assert e.value.code == 0, args
    modes = {**_modes(cap), **_modes(fits), **_modes(tex), **_modes(diag)}
    assert len(modes) >= 12
    assert set(modes.values()) == {0o644}, {k: oct(v) for k, v in modes.items() if v != 0o644}
    assert not [k for k in modes if k.endswith(".tmp")]


def test_an_interrupted_write_leaves_no_temporary(tmp_path, monkeypatch):
    import tifffile

    from wardjax import _files

    def broken(path, *a, **k):
        Path(path).write_bytes(b"half an image")
        raise KeyboardInterrupt  # the user presses ^C mid-write

    monkeypatch.setattr(tifffile, "imwrite", broken)
    with pytest.raises(KeyboardInterrupt):
        _files.write_image(tmp_path / "rho_d.tif", np.zeros((4, 4, 3), np.float32))
    assert list(tmp_path.iterdir()) == []


def test_a_batch_removes_temporaries_an_earlier_killed_run_left(tmp_path):
    from wardjax import _files

    (tmp_path / ".params.abc123.json.tmp").write_bytes(b"{")
    (tmp_path / "keep.json").write_bytes(b"{}")
    _files.remove_temporaries(tmp_path)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["keep.json"]
