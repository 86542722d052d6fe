"""The folder of exported programs holds one build's programs; a process keeps a bounded number loaded."""

from __future__ import annotations

import functools

import numpy as np


def _square_plus(x, *, k):
    return x * x + k


def test_writing_a_program_removes_other_builds_files_and_keeps_this_builds(tmp_path, monkeypatch):
    """A source change names a new build: the first program it writes removes the files of the build before (and
    of the older layout without a build in the name), and leaves this build's other programs and foreign files."""
    import jax

    from wardjax.effects import _exported

    monkeypatch.setattr(_exported, "_folder", lambda: tmp_path)
    x = np.arange(3.0)
    jitted = jax.jit(_square_plus, static_argnames="k")

    def run(k):
        return np.asarray(_exported.call("t", functools.partial(jitted, k=k), (("k", k),), (x,)))

    old = _exported._build()
    run(1)
    run(2)
    assert len(list(tmp_path.glob(f"t-{old}-*.bin"))) == 2
    (tmp_path / "lm-0123456789abcdef.bin").write_bytes(b"older layout")
    (tmp_path / "notes.txt").write_text("not a program")
    monkeypatch.setattr(_exported, "_build", lambda: "b" * 12)  # the source changed: another build
    np.testing.assert_array_equal(run(1), x * x + 1)
    assert sorted(p.name.split("-")[1] for p in tmp_path.glob("*.bin")) == ["b" * 12]
    assert (tmp_path / "notes.txt").exists()
    run(2)  # this build's second program: the first stays
    assert len(list(tmp_path.glob(f"t-{'b' * 12}-*.bin"))) == 2


def test_a_process_reads_each_program_once_and_keeps_a_bounded_number_loaded(tmp_path, monkeypatch):
    """The process that writes a program and every later call run it as read back from its file, which is read
    once while it stays among the ``_MAX_LOADED`` most recently used; one dropped is read back from its file."""
    import jax

    from wardjax.effects import _exported

    _exported._loaded.cache_clear()
    monkeypatch.setattr(_exported, "_folder", lambda: tmp_path)
    x = np.arange(3.0)
    jitted = jax.jit(_square_plus, static_argnames="k")

    def run(k):
        return np.asarray(_exported.call("t", functools.partial(jitted, k=k), (("k", k),), (x,)))

    run(1)  # not on disk: traced, written, read back
    run(2)
    info = _exported._loaded.cache_info()
    assert (info.hits, info.misses) == (0, 4)  # two missing files, two reads
    np.testing.assert_array_equal(run(1), x * x + 1)
    np.testing.assert_array_equal(run(2), x * x + 2)
    info = _exported._loaded.cache_info()
    assert (info.hits, info.misses, info.currsize, info.maxsize) == (2, 4, 2, _exported._MAX_LOADED)
    files = sorted(tmp_path.glob("t-*.bin"))
    assert len(files) == 2
    _exported._loaded.cache_clear()  # dropped from memory: read back from its file, nothing written again
    stamps = [f.stat().st_mtime_ns for f in files]
    np.testing.assert_array_equal(run(2), x * x + 2)
    info = _exported._loaded.cache_info()
    assert (info.hits, info.misses, info.currsize) == (0, 1, 1)
    assert [f.stat().st_mtime_ns for f in sorted(tmp_path.glob("t-*.bin"))] == stamps
