"""How ``discover`` runs: NumPy's linear algebra on one BLAS thread, restored afterwards."""

from __future__ import annotations

import pytest
from threadpoolctl import threadpool_info, threadpool_limits

from wardjax.effects import ThresholdModel, _discover, discover
from wardjax.effects._real import table1_threshold_data


def _blas_threads() -> list[int]:
    return [p["num_threads"] for p in threadpool_info() if p["user_api"] == "blas"]


class _Seen(Exception):
    """Raised by the spy once it has read the thread counts, to stop ``discover`` there."""


def test_discover_runs_numpy_linear_algebra_on_one_blas_thread(monkeypatch):
    """The texture's covariance is many small Cholesky factors and inverses: BLAS threads only hand work over
    (and spin on a busy machine). Inside ``discover`` every BLAS library runs one thread; after it, as before."""
    seen: list[list[int]] = []

    def spy(*_args, **_kwargs):
        seen.append(_blas_threads())
        raise _Seen  # what discover does next is not this test's concern

    monkeypatch.setattr(_discover, "_baseline", spy)
    with threadpool_limits(2, user_api="blas"):  # a caller's setting (one core or many, the same test)
        before = _blas_threads()
        assert before and all(n == 2 for n in before), "NumPy links a BLAS that threadpoolctl can set"
        with pytest.raises(_Seen):
            discover(ThresholdModel(), table1_threshold_data())
        after = _blas_threads()
    assert seen == [[1] * len(before)]
    assert after == before
