"""Test configuration: strict JAX numerics, seeded generators, shared fixtures.

Float64 is *not* switched on globally: the library scopes it itself, and the
tests check that it does (tests/test_00_api.py).
"""

import os

import jax
import numpy as np
import pytest

jax.config.update("jax_numpy_rank_promotion", "raise")
# The CLI keeps compiled kernels on disk (a process-wide JAX setting); tests
# run it in-process, so they leave it off unless a test turns it on itself
# (tests/test_cli_fit.py checks the cache in a subprocess).
os.environ.setdefault("WARDJAX_NO_CACHE", "1")


@pytest.fixture
def rng():
    return np.random.default_rng(20261121)
