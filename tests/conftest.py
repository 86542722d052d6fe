"""Test configuration: strict JAX numerics, checked shapes, seeded generators, shared fixtures.

Float64 is *not* switched on globally: the library scopes it itself, and the
tests check that it does (``tests/test_01_ward.py``). Every function of the
package is imported through jaxtyping's import hook with beartype, so the
shapes and dtypes written in its type hints are checked on every call the
suite makes. Rank and dtype promotion are strict: an implicit broadcast of
ranks or a silent float32 → float64 promotion is an error.
"""

import os
import shutil
import tempfile

import jax
import numpy as np
import pytest
from jaxtyping import install_import_hook

jax.config.update("jax_numpy_rank_promotion", "raise")
jax.config.update("jax_numpy_dtype_promotion", "strict")

with install_import_hook("wardjax", "_typecheck.typecheck"):
    import wardjax
    import wardjax.run

    # The package imports its names on first use; import them all here, through the hook, before any test does.
    for _package in (wardjax, wardjax.run):
        for _name in _package.__all__:
            getattr(_package, _name)
# The CLI keeps compiled kernels on disk (a process-wide JAX setting); tests
# run it in-process, so they leave it off unless a test turns it on itself
# (tests/test_cli_fit.py checks the cache in a subprocess).
os.environ.setdefault("WARDJAX_NO_CACHE", "1")

# Both xdist workers compile much the same programs; they share them through
# one JAX compilation cache for the run (a size limit turns on JAX's file lock,
# so the workers never read a half-written entry). The controller makes the
# folder before the workers start and removes it at the end.
_SHARED_CACHE = "WARDJAX_TEST_COMPILE_CACHE"


def pytest_configure(config):
    if not hasattr(config, "workerinput") and _SHARED_CACHE not in os.environ:
        os.environ[_SHARED_CACHE] = tempfile.mkdtemp(prefix="wardjax-test-jax-")
        config.stash[_cache_key] = os.environ[_SHARED_CACHE]
    folder = os.environ[_SHARED_CACHE]
    jax.config.update("jax_compilation_cache_dir", folder)
    jax.config.update("jax_compilation_cache_max_size", 4 << 30)
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.2)
    jax.config.update("jax_persistent_cache_min_entry_size_bytes", 0)


def pytest_unconfigure(config):
    folder = config.stash.get(_cache_key, None)
    if folder is not None:
        shutil.rmtree(folder, ignore_errors=True)
        os.environ.pop(_SHARED_CACHE, None)


_cache_key = pytest.StashKey[str]()


@pytest.fixture
def rng():
    return np.random.default_rng(20261121)
