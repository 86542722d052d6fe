"""Test configuration: strict JAX numerics, seeded generators, shared fixtures.

Float64 is *not* switched on globally: the library scopes it itself, and the
tests check that it does (tests/test_00_api.py).
"""

import jax
import numpy as np
import pytest

jax.config.update("jax_numpy_rank_promotion", "raise")


@pytest.fixture
def rng():
    return np.random.default_rng(20261121)
