"""The folder of exported programs holds one build's programs; a process keeps a bounded number loaded."""

from __future__ import annotations

import functools
from collections import OrderedDict

import numpy as np


def _square_plus(x, *, k):
    return x * x + k


def test_writing_a_program_removes_other_builds_files_and_keeps_this_builds(tmp_path, monkeypatch):
    """A source change names a new build: the first program it writes removes the files of the build before (and
    of the older layout without a build in the name), and leaves this build's other programs and foreign files."""
    import jax

    from wardjax.effects import _exported

    monkeypatch.setattr(_exported, "_LOADED", OrderedDict())
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


def test_a_process_keeps_the_most_recently_used_programs_loaded(tmp_path, monkeypatch):
    """Past ``_MAX_LOADED`` programs the least recently used is dropped from memory (its file stays, to be read
    back); one used again moves to the front."""
    import jax

    from wardjax.effects import _exported

    monkeypatch.setattr(_exported, "_LOADED", OrderedDict())
    monkeypatch.setattr(_exported, "_folder", lambda: tmp_path)
    monkeypatch.setattr(_exported, "_MAX_LOADED", 2)
    x = np.arange(3.0)
    jitted = jax.jit(_square_plus, static_argnames="k")

    def run(k):
        return np.asarray(_exported.call("t", functools.partial(jitted, k=k), (("k", k),), (x,)))

    run(1)
    keys = list(_exported._LOADED)
    run(2)
    run(1)  # used again: now the most recent
    run(3)  # the third: k = 2, the least recently used, is dropped
    assert len(_exported._LOADED) == 2 and keys[0] in _exported._LOADED
    assert len(list(tmp_path.glob("t-*.bin"))) == 3
    np.testing.assert_array_equal(run(2), x * x + 2)  # read back from its file
