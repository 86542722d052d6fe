"""The CLI's compile cache: a size limit, so that JAX locks it (processes share it: ``wardjax fit --scheduler``).

JAX takes its file lock (``filelock``) on the persistent cache only when the
cache has a size limit; without one, two workers compiling the same program
can read an entry the other has half written. Both ways the cache is set —
JAX's configuration when JAX is loaded, its environment variables when it is
not yet (read on import) — must carry the limit, under names JAX reads.
"""

from __future__ import annotations

import os
import sys

import jax

from wardjax.run._cache import MAX_BYTES, enable_compile_cache

_OPTIONS = ("jax_compilation_cache_dir", "jax_persistent_cache_min_compile_time_secs", "jax_compilation_cache_max_size")


def test_01_with_jax_loaded_the_config_carries_the_limit(tmp_path):
    before = {k: getattr(jax.config, k) for k in _OPTIONS}
    try:
        enable_compile_cache(tmp_path / "xla")
        assert jax.config.jax_compilation_cache_dir == str(tmp_path / "xla")
        assert jax.config.jax_compilation_cache_max_size == MAX_BYTES > 0
    finally:
        for k, v in before.items():
            jax.config.update(k, v)


def test_02_before_jax_loads_its_environment_carries_the_limit(tmp_path, monkeypatch):
    for k in _OPTIONS:  # restored by monkeypatch after the test, whatever enable_compile_cache writes
        monkeypatch.setenv(k.upper(), "")
    monkeypatch.delitem(sys.modules, "jax")
    before = dict(os.environ)
    enable_compile_cache(tmp_path / "xla")
    assert os.environ["JAX_COMPILATION_CACHE_MAX_SIZE"] == str(MAX_BYTES)
    assert os.environ["JAX_COMPILATION_CACHE_DIR"] == str(tmp_path / "xla")
    # every variable set is one JAX reads: an option's name in capitals
    set_here = {k for k, v in os.environ.items() if before.get(k) != v}
    assert len(set_here) == 3 and set_here <= {k.upper() for k in jax.config.values}
