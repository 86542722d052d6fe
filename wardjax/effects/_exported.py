"""Discovery's traced programs kept on disk beside XLA's compile cache, so that a later process skips tracing them.

Why
    JAX's persistent compile cache (:func:`wardjax.run._cache.enable_compile_cache`) keeps the *compiled* programs,
    but finding one needs its key, and the key is computed from the lowered module: every process still traces
    and lowers each program first. The Levenberg–Marquardt program of a discovery run (optimistix's solver around
    the scanline model, every effect behind a switch) takes seconds to trace, in every ``wardjax diagnose``.

How
    :func:`call` runs a jitted function through :func:`jax.export`: the first process to need a program traces it
    once, serialises the exported StableHLO (:meth:`jax.export.Exported.serialize`) into ``exported/`` under the
    compile cache folder, and calls it; a later process reads it back and calls it without tracing the Python.
    The module is the one the jitted function lowers to, so the numbers are the same (the tests compare them
    bit for bit), and XLA's cache serves its compiled form as before.

    A file is named by a digest of everything the trace depends on: the program's name and static arguments,
    the argument tree and each leaf's shape and dtype, the 64-bit mode, the backend, the versions of JAX and of
    the solver libraries traced into it (equinox, lineax, optimistix) and the wardjax source itself (every
    ``.py`` file of the package), so that a changed library never reads a stale program. Without a compile
    cache folder (a library call, the tests) nothing is written and the function is
    called as it is, as is a program that cannot be exported (one with host callbacks).

    The folder holds one build's programs: a file's name starts with the program's name and a digest of the
    build (the libraries' versions and the wardjax source), and writing a program removes the files of every other
    build, which no process of this build reads again. So the folder stays as large as one build's programs (a
    few, ~1 MB each) however often the source changes. In a process the loaded programs are kept, the most
    recently used ``_MAX_LOADED`` of them (:func:`_loaded`); the process that writes a program runs it as read
    back from its file, as every later process does. Custom calls whose
    compatibility across JAX versions is not guaranteed (LAPACK's QR) are allowed: a file is only read by the JAX
    version that wrote it.
"""

from __future__ import annotations

import functools
import hashlib
import importlib.metadata
from collections.abc import Callable
from pathlib import Path

import jax
from jax import export

from .._files import write_bytes_atomic

__all__ = ["call"]

# the custom calls the LM program makes (LAPACK's QR in lineax): stable within one JAX version, which the key holds
_CUSTOM_CALLS = (
    "lapack_dgeqrf_ffi",
    "lapack_dorgqr_ffi",
    "lapack_dormqr_ffi",
    "lapack_sgeqrf_ffi",
    "lapack_sormqr_ffi",
)
# the libraries whose Python code is traced into the programs (their versions enter each file's name)
_TRACED_WITH = ("jax", "jaxlib", "equinox", "lineax", "optimistix")
_MAX_LOADED = 32  # programs kept loaded in a process (a discovery run uses two or three)


@functools.cache
def _versions() -> tuple[str, ...]:
    """The versions of the libraries a traced program is made of: an upgraded solver names a new program."""
    return tuple(f"{m}=={importlib.metadata.version(m)}" for m in _TRACED_WITH)


@functools.cache
def _source_digest() -> str:
    """A digest of wardjax's source: any change to the package names a new program."""
    root = Path(__file__).resolve().parents[1]
    h = hashlib.sha256()
    for p in sorted(root.rglob("*.py")):
        h.update(str(p.relative_to(root)).encode())
        h.update(p.read_bytes())
    return h.hexdigest()


def _folder() -> Path | None:
    """``exported/`` in the compile cache folder, or ``None`` where no cache folder is set."""
    d = getattr(jax.config, "jax_compilation_cache_dir", None)
    return Path(d) / "exported" if d else None


@functools.cache
def _build() -> str:
    """What names this build's programs apart from another's: the traced libraries' versions and the source."""
    return hashlib.sha256(repr((_versions(), _source_digest())).encode()).hexdigest()[:12]


def _digest(name: str, static: tuple, treedef, leaves) -> str:
    avals = [(tuple(x.shape), str(x.dtype), bool(getattr(x, "weak_type", False))) for x in leaves]
    parts = (
        name,
        repr(static),
        str(treedef),
        repr(avals),
        getattr(jax.config, "jax_enable_x64", False),
        jax.default_backend(),
    )
    return hashlib.sha256(repr((parts, _build())).encode()).hexdigest()[:40]


def _write(path: Path, blob: bytes | bytearray) -> None:
    """Write atomically (a concurrent process reads the whole file or none), then remove other builds' programs
    (:func:`_prune`); a failure only skips the write, or what is left of the pruning."""
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        write_bytes_atomic(path, blob)
        _prune(path.parent)
    except OSError:
        pass


def _prune(folder: Path) -> None:
    """Remove the program files of every build but this one (``NAME-BUILD-KEY.bin``, :func:`_build`; a name
    without a build is an older layout's, of another build too)."""
    for old in folder.glob("*.bin"):
        parts = old.stem.rsplit("-", 2)
        if len(parts) < 3 or parts[1] != _build():
            old.unlink(missing_ok=True)  # a concurrent process may have removed it


@functools.lru_cache(maxsize=_MAX_LOADED)
def _loaded(path: Path) -> Callable:
    """The program in ``path``, deserialised and jitted; the most recently used ``_MAX_LOADED`` stay loaded.

    Raises ``OSError`` (no such file), ``ValueError`` or ``TypeError`` (written by an interrupted run), which
    leaves nothing cached: the caller traces the program and writes it.
    """
    return jax.jit(export.deserialize(bytearray(path.read_bytes())).call)


def call(name: str, fn: Callable, static: tuple, args: tuple):
    """``fn(*args)`` (``fn`` closes over ``static``, which names it in the key), from the program on disk if there.

    ``args`` is any pytree of arrays; ``static`` the hashable settings ``fn`` was made with (their ``repr`` enters
    the file's name, so it must say everything that changes the trace).
    """
    folder = _folder()
    if folder is None:
        return fn(*args)
    leaves, treedef = jax.tree_util.tree_flatten(args)
    path = folder / f"{name}-{_build()}-{_digest(name, static, treedef, leaves)}.bin"
    try:
        run = _loaded(path)
    except (OSError, ValueError, TypeError):  # not written yet, or by an interrupted run: trace it and write it

        def flat(*xs):
            return fn(*jax.tree_util.tree_unflatten(treedef, xs))

        checks = [export.DisabledSafetyCheck.custom_call(t) for t in _CUSTOM_CALLS]
        try:
            exp = export.export(jax.jit(flat), disabled_checks=checks)(*leaves)
            blob = exp.serialize()
        except (NotImplementedError, ValueError):  # host callbacks, another custom call: run it as it is
            return fn(*args)
        _write(path, blob)
        try:
            run = _loaded(path)
        except (OSError, ValueError, TypeError):  # not written (a read-only folder): this trace, not kept
            run = jax.jit(exp.call)
    return run(*leaves)
