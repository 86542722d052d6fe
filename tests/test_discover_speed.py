"""How ``discover`` runs: NumPy's linear algebra on one BLAS thread (restored after); ρd's whitened least squares."""

from __future__ import annotations

import functools
from collections import OrderedDict

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
    monkeypatch.setattr(_exported, "_LOADED", OrderedDict())
    monkeypatch.setattr(_exported, "_folder", lambda: tmp_path)
    with jax.enable_x64(True):
        want = [np.asarray(v) for v in jitted(x, tree, k=3)]
        got = _exported.call("t", functools.partial(jitted, k=3), (("k", 3),), (x, tree))
        assert len(list(tmp_path.glob("t-*.bin"))) == 1
        monkeypatch.setattr(_exported, "_LOADED", OrderedDict())  # a new process: only the file is left

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


def test_stalling_lm_ends_a_settled_fit_unconverged_and_leaves_a_moving_one_alone():
    """A parameter that lowers χ² less and less as it runs off keeps Levenberg–Marquardt's parameter rule from ever
    being met: the plain solver runs to its cap. With the stall rule the fit ends once an accepted step gains less
    than the stall in χ², at the χ² of the capped fit (within the stall), flagged unconverged; from a start that gains
    little from its first step on (a lobe far from the data) it runs on. Rosenbrock's valley ends, also flagged,
    within the stall of its minimum; with no stall it is solved as by the plain solver, to the same point."""
    import jax
    import jax.numpy as jnp
    import optimistix as optx

    from wardjax.effects._solve import _LINEAR_SOLVER, _StallingLM

    def flat(z, _):  # the second parameter lowers χ² less and less as it runs off to large values
        return jnp.array([z[0] - 1.0, 1e-3 * jnp.exp(-z[1])])

    def valley(z, _):
        return jnp.array([z[0] - 1.0, 10 * (z[1] - z[0] ** 2)])

    @functools.partial(jax.jit, static_argnums=(0, 3))
    def solve(fn, y0, stall, plain=False):
        lm = (
            optx.LevenbergMarquardt(1e-6, 1e-8, linear_solver=_LINEAR_SOLVER)
            if plain
            else _StallingLM(1e-6, 1e-8, stall, _LINEAR_SOLVER, jnp.sum(fn(y0, None) ** 2))
        )
        sol = optx.least_squares(fn, lm, y0, max_steps=60, throw=False)
        chi2 = jnp.sum(fn(sol.value, None) ** 2)
        return chi2, sol.stats["num_steps"], sol.result == optx.RESULTS.successful, sol.value

    with jax.enable_x64(True):
        y0 = jnp.array([3.0, 0.0])
        c_cap, n_cap, ok_cap, _ = solve(flat, y0, 0.0)
        c_st, n_st, ok_st, _ = solve(flat, y0, 1e-3)
        assert int(n_cap) == 60 and not bool(ok_cap)
        assert int(n_st) < 60 and not bool(ok_st)
        assert float(c_st) - float(c_cap) < 1e-3
        _, n_far, _, _ = solve(flat, jnp.array([1.0, 0.0]), 1e-3)  # gains little from its start: not settled
        assert int(n_far) == 60
        (c0, n0, ok0, z0), (c1, n1, ok1, _) = (solve(valley, jnp.array([-1.2, 1.0]), s) for s in (0.0, 1e-3))
        assert bool(ok0) and float(c0) < 1e-20 and np.allclose(np.asarray(z0), 1.0)
        assert not bool(ok1) and int(n1) < int(n0) and float(c1) - float(c0) < 1e-3
        _, n_plain, _, z_plain = solve(valley, jnp.array([-1.2, 1.0]), 0.0, True)  # no stall: plain LM, step for step
        assert int(n_plain) == int(n0)
        np.testing.assert_array_equal(np.asarray(z0), np.asarray(z_plain))


def test_gauss_newton_decrease_is_what_a_quadratic_still_has_to_lose(rng):
    """On a linear least squares with a prior, χ² less the predicted decrease at any point is the minimum χ² (the
    normal equations' solution, by NumPy); at the minimum the decrease is zero; a padded slot changes nothing."""
    import jax

    from wardjax.effects._solve import _gn_decrease

    a, y = rng.normal(size=(30, 3)), rng.normal(size=30)
    pw, z0 = np.array([0.0, 0.5, 2.0]), rng.normal(size=3)
    A, b = np.vstack([a, np.diag(pw)]), np.concatenate([y, pw * z0])
    z_min = np.linalg.lstsq(A, b, rcond=None)[0]

    def chi2(z):
        return float(np.sum((A @ z - b) ** 2))

    with jax.enable_x64(True):
        for z in (rng.normal(size=3), z_min):
            r = a @ z - y
            got = float(_gn_decrease(a, r, pw, z - z0, np.ones(3, bool)))
            np.testing.assert_allclose(chi2(z) - got, chi2(z_min), rtol=1e-9, atol=1e-9)
        z = rng.normal(size=3)
        pad = float(
            _gn_decrease(
                np.c_[a, 0 * a[:, :1]], a @ z - y, np.r_[pw, 0.0], np.r_[z - z0, 0.0], np.r_[True, True, True, False]
            )
        )
        np.testing.assert_allclose(pad, chi2(z) - chi2(z_min), rtol=1e-9)
