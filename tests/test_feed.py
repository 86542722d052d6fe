"""The host feed: chunks copied to the devices by worker threads give the fit the direct path gives.

On an accelerator, NumPy inputs cross to the device in worker threads a few chunks ahead of the
compute (:mod:`wardjax.fit._feed`); on a CPU the compiled call takes them as they are. The
threaded feed is forced here on the CPU (the suite never needs an accelerator) and must return the
same numbers bit for bit, with a short last chunk padded, unweighted (the sandwich, Gauss–Newton's
covariance fetched only where the profile reads it) and weighted, with every row profiled too.
On a CPU the chunks take turns over execution streams (one per core) and run concurrently: the
results must be those of one stream, bit for bit.
"""

from __future__ import annotations

import os

import jax
import numpy as np
import pytest
from _captures import isotropic_set

import wardjax as wj
from wardjax.fit import _data, _feed


@pytest.fixture(scope="module")
def data():
    return isotropic_set(np.random.default_rng(11), 150, n_samples=64)[1]


def _fields(fit):
    return {
        "rho_d": fit.params.rho_d,
        "rho_s": fit.params.rho_s,
        "alpha": fit.params.alpha_x,
        "cov": fit.covariance,
        "chi2": fit.chi2,
        "status": fit.status,
        "errors": fit.errors,
    }


@pytest.mark.slow  # ~40 s: the fed arrays are committed to a device, so each fit compiles anew
@pytest.mark.parametrize(("weighted", "errors"), [(False, "auto"), (True, "auto"), (False, "profile")])
def test_threaded_feed_gives_the_direct_fit(data, monkeypatch, weighted, errors):
    w = 1 / data.sigma**2 if weighted else None
    fit = lambda: wj.fit_scanlines(data.f_r, data.wi, data.wo, weights=w, chunk_size=64, errors=errors)
    direct = fit()
    calls = []
    monkeypatch.setattr(_feed, "host_fed", lambda *a: calls.append(1) or True)
    fed = fit()
    assert calls, "the threaded feed was not used"
    assert np.mean(direct.ok) > 0.9
    for name, value in _fields(direct).items():
        np.testing.assert_array_equal(_fields(fed)[name], value, err_msg=name)
    if not weighted and errors == "auto":
        # Rows whose curvature check failed were profiled from Gauss–Newton's covariance on the host.
        assert np.any(direct.errors == "profile")


def test_chunks_keep_order_and_pad_the_last(monkeypatch):
    a = np.arange(10.0)[:, None] * np.ones((1, 2))
    spans = [(0, 4, 4), (4, 8, 4), (8, 10, 4)]
    got = list(_feed.chunks([a, None], spans, lambda x: x * 1, threaded=True))
    assert [g[1] for g in got] == [None] * 3
    np.testing.assert_array_equal(np.concatenate([g[0] for g in got])[:10], a)
    np.testing.assert_array_equal(got[-1][0][2:], 0.0)


def test_negative_host_weights_left_to_the_device_then_refused():
    f = np.ones((4, 5, 3))
    w = np.ones((4, 5))
    w[3, 2] = -1.0
    with pytest.raises(ValueError, match="weights must be non-negative"):
        _data.validate(f, f, f, None, w)
    *_, wt = _data.validate(f, f, f, None, w, sign_later=True)  # not scanned on the host
    flags = [_data.negative_flag(jax.device_put(wt[:2])), _data.negative_flag(jax.device_put(wt[2:]))]
    assert [bool(x) for x in flags] == [False, True]
    with pytest.raises(ValueError, match="weights must be non-negative"):
        _data.check_sign(flags)
    _data.check_sign(flags[:1])


@pytest.mark.slow
def test_negative_host_weights_refused_after_the_device_check(data, monkeypatch):
    monkeypatch.setattr(_feed, "host_fed", lambda *a: True)
    w = np.ones(data.f_r.shape[:2])
    w[120, 5] = -1.0  # in the last chunk: every chunk's flag is read
    with pytest.raises(ValueError, match="weights must be non-negative"):
        wj.fit_scanlines(data.f_r, data.wi, data.wo, weights=w, chunk_size=64, errors="gauss_newton")


def _identical(a, b):
    for name, value in _fields(a).items():
        np.testing.assert_array_equal(_fields(b)[name], value, err_msg=name)


@pytest.mark.parametrize("errors", ["auto", "gauss_newton"])
def test_chunks_on_several_streams_give_the_one_stream_fit(data, monkeypatch, errors):
    fit = lambda: wj.fit_scanlines(data.f_r, data.wi, data.wo, chunk_size=32, errors=errors)  # 5 chunks
    monkeypatch.setattr(_feed, "streams", lambda devices: 1)
    one = fit()
    used, stream = [], _feed.stream
    monkeypatch.setattr(_feed, "streams", lambda devices: 3)  # more streams than this machine may have cores
    monkeypatch.setattr(_feed, "stream", lambda i, n: used.append(i % n) or stream(i, n))
    several = fit()
    assert used[:5] == [0, 1, 2, 0, 1], "the chunks did not take turns over the streams"
    assert np.mean(one.ok) > 0.9
    _identical(one, several)


def test_streams_one_per_core_on_a_cpu_only():
    if _feed._STREAM_ID is None:
        pytest.skip("this jaxlib has no execution streams")
    assert _feed.streams(jax.devices("cpu")) == len(os.sched_getaffinity(0))

    class Accelerator:
        platform = "gpu"

    assert _feed.streams([Accelerator()]) == 1
