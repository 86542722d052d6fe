"""How ``discover`` runs: NumPy's linear algebra on one BLAS thread (restored after); ρd's whitened least squares."""

from __future__ import annotations

import numpy as np
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


def _whitened_problem(rng, s_n=3, n=5, c_n=3):
    """A lower-triangular whitening ``(S, C N, C N)`` with the channels of a scanline together, and GLS inputs."""
    m = c_n * n
    W = np.tril(rng.normal(size=(s_n, m, m))) + 3.0 * np.eye(m)
    inv_sp, resid = rng.uniform(0.5, 2.0, (s_n, n, c_n)), rng.normal(size=(s_n, n, c_n))
    return W, inv_sp, resid


def test_gls_whitening_of_all_columns_at_once_is_each_whitened_alone(rng):
    """ρd's design columns and the data go through the whitening in one product; each column is the whitening of
    its own vector (``_whiten``, the values ordered channel by channel)."""
    import jax

    from wardjax.effects._gls import _gls_whitened, _whiten

    W, inv_sp, resid = _whitened_problem(rng)
    with jax.enable_x64(True):
        A, b = (np.asarray(x) for x in _gls_whitened(W, inv_sp, resid))
        for c in range(inv_sp.shape[-1]):
            alone = np.where(np.arange(inv_sp.shape[-1]) == c, inv_sp, 0.0)
            np.testing.assert_allclose(A[..., c], np.asarray(_whiten(W, alone)), rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(b, np.asarray(_whiten(W, resid)), rtol=1e-12, atol=1e-12)


def test_gls_rho_derivative_by_hand_is_autodiff_through_the_whitening(rng):
    """The profiled ρd's derivative rule, ``dx = H⁻¹ (dDᵀ Wᵀ e + (Wᵀ A)ᵀ (dr − dD x))``, against forward-mode
    autodiff of the same least squares differentiated through ``W`` (and the value against the normal equations)."""
    import jax

    from wardjax.effects._gls import _gls_rho_joint, _gls_solve, _gls_whitened

    W, inv_sp, resid = _whitened_problem(rng)
    d_inv, d_res = rng.normal(size=inv_sp.shape), rng.normal(size=resid.shape)
    with jax.enable_x64(True):
        p_ref, t_ref = jax.jvp(lambda a, r: _gls_solve(*_gls_whitened(W, a, r)), (inv_sp, resid), (d_inv, d_res))
        p, t = jax.jvp(lambda a, r: _gls_rho_joint(W, a, r), (inv_sp, resid), (d_inv, d_res))
    np.testing.assert_array_equal(np.asarray(p), np.asarray(p_ref))
    np.testing.assert_allclose(np.asarray(t), np.asarray(t_ref), rtol=1e-10, atol=1e-12)
    # the value: the normal equations of each scanline, solved with NumPy
    s_n, n, c_n = inv_sp.shape
    for s in range(s_n):
        X = np.zeros((c_n * n, c_n))
        for c in range(c_n):
            X[c * n : (c + 1) * n, c] = inv_sp[s, :, c]
        A, b = W[s] @ X, W[s] @ resid[s].T.reshape(-1)
        np.testing.assert_allclose(np.asarray(p)[s, 0] / np.pi, np.linalg.solve(A.T @ A, A.T @ b), rtol=1e-10)


def _program(x, tree, *, k):
    """A traced program with a static setting, a pytree argument and LAPACK's QR (as the LM program solves)."""
    import jax.numpy as jnp
    import lineax as lx

    a = tree["a"] + k * jnp.eye(x.shape[0])
    sol = lx.linear_solve(lx.MatrixLinearOperator(a), x, lx.QR(), throw=False)
    return sol.value, jnp.sum(sol.value * tree["b"])


def test_exported_program_is_read_back_without_tracing_and_gives_the_same_numbers(rng, tmp_path, monkeypatch):
    """A program traced once is written beside the compile cache; a fresh process (the in-memory table emptied)
    reads it back without tracing the Python, and the numbers are the jitted function's, bit for bit. Another
    static setting is another program; with no cache folder the function is called as it is."""
    import functools

    import jax

    from wardjax.effects import _exported

    jitted = jax.jit(_program, static_argnames="k")
    x, tree = rng.normal(size=6), {"a": rng.normal(size=(6, 6)), "b": rng.normal(size=6)}
    _exported._loaded.cache_clear()
    monkeypatch.setattr(_exported, "_folder", lambda: tmp_path)
    with jax.enable_x64(True):
        want = [np.asarray(v) for v in jitted(x, tree, k=3)]
        got = _exported.call("t", functools.partial(jitted, k=3), (("k", 3),), (x, tree))
        assert len(list(tmp_path.glob("t-*.bin"))) == 1
        _exported._loaded.cache_clear()  # a new process: only the file is left

        def no_trace(*_a, **_k):
            raise AssertionError("traced again")

        monkeypatch.setattr(_exported.export, "export", no_trace)
        again = _exported.call("t", functools.partial(jitted, k=3), (("k", 3),), (x, tree))
        for a, b, c in zip(want, got, again):
            np.testing.assert_array_equal(np.asarray(b), a)
            np.testing.assert_array_equal(np.asarray(c), a)
        with pytest.raises(AssertionError, match="traced again"):  # another setting: another program
            _exported.call("t", functools.partial(jitted, k=4), (("k", 4),), (x, tree))
        monkeypatch.setattr(_exported, "_folder", lambda: None)
        plain = _exported.call("t", functools.partial(jitted, k=4), (("k", 4),), (x, tree))
        np.testing.assert_allclose(np.asarray(plain[1]), np.asarray(jitted(x, tree, k=4)[1]), rtol=0, atol=0)


def test_back_whitening_of_all_columns_at_once_is_each_transposed_alone(rng):
    """``Wᵀ`` of ``K`` columns in one product, in both layouts (channels together ``(S, C N, C N)``, per channel
    ``(S, C, N, N)``) and on both kinds of array (NumPy's on the host, JAX's in a program), against each
    scanline's transposed matrix times each column with NumPy."""
    import jax
    import jax.numpy as jnp

    from wardjax.effects._gls import _back_whiten_columns

    W, _, _ = _whitened_problem(rng)
    s_n, m, _ = W.shape
    c_n, n, k = 3, m // 3, 4
    cols = rng.normal(size=(s_n, n, c_n, k))
    per = np.tril(rng.normal(size=(s_n, c_n, n, n))) + 3.0 * np.eye(n)
    host = _back_whiten_columns(W, cols), _back_whiten_columns(per, cols)
    assert all(isinstance(x, np.ndarray) for x in host)
    with jax.enable_x64(True):
        dev = _back_whiten_columns(jnp.asarray(W), cols), _back_whiten_columns(jnp.asarray(per), jnp.asarray(cols))
    assert all(isinstance(x, jax.Array) for x in dev)
    for got, got_per in (host, (np.asarray(dev[0]), np.asarray(dev[1]))):
        for s in range(s_n):
            for j in range(k):
                want = (W[s].T @ cols[s, :, :, j].T.reshape(-1)).reshape(c_n, n).T  # values ordered channel by channel
                np.testing.assert_allclose(got[s, :, :, j], want, rtol=1e-12, atol=1e-12)
                for c in range(c_n):
                    np.testing.assert_allclose(got_per[s, :, c, j], per[s, c].T @ cols[s, :, c, j], rtol=1e-12)


def test_materialised_residuals_linearise_to_their_jacobian_not_to_the_data(rng):
    """The LM's residuals (``_solve._materialised``) have the tangents of the function they wrap, and their
    linearisation (what optimistix keeps in its loop state) holds the ``M × K`` Jacobian, not the data the
    tangents read (a whitening ``W`` of ``M × M``) as JAX's own linearisation of the function does."""
    import jax
    import jax.numpy as jnp

    from wardjax.effects._solve import _materialised

    m, k = 60, 3
    W = np.tril(rng.normal(size=(m, m))) + 3.0 * np.eye(m)
    x = rng.normal(size=(m, k))

    def f(z, args):
        W, x = args
        return W @ jnp.tanh(x @ z)

    z, dz = rng.normal(size=k), rng.normal(size=k)
    with jax.enable_x64(True):
        r_ref, t_ref = jax.jvp(lambda z: f(z, (W, x)), (z,), (dz,))
        r, t = jax.jvp(lambda z: _materialised(f, z, (W, x)), (z,), (dz,))
        _, lin_ref = jax.linearize(lambda z: f(z, (W, x)), z)
        _, lin = jax.linearize(lambda z: _materialised(f, z, (W, x)), z)
        t_lin = lin(jnp.asarray(dz))
    np.testing.assert_array_equal(np.asarray(r), np.asarray(r_ref))
    np.testing.assert_allclose(np.asarray(t), np.asarray(t_ref), rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(np.asarray(t_lin), np.asarray(t_ref), rtol=1e-12, atol=1e-12)

    def held(fn):
        return sum(np.size(a) for a in jax.tree_util.tree_leaves(fn))

    assert held(lin_ref) >= m * m  # the whitening itself
    assert held(lin) <= m * k + m  # the Jacobian (and at most the residuals)
