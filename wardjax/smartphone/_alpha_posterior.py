"""Bayesian α from grating thresholds: the statistical model and its emcee sampler.

Model (one surface)
-------------------
Parameters, sampled as ``θ = (log t, log σ_obs, z₁, z₂)``:

- ``t`` — the median threshold PPB of an observer population for this surface;
- ``σ_obs`` — observer threshold noise: observer ``j``'s latent threshold is
  ``t_j = t · exp(σ_obs ε_j)``, ``ε_j ~ N(0, 1)`` (Weber-like, multiplicative);
- ``z`` — the calibration line at the surface's lightness, ``(a, b) = μ + L z`` with
  ``L Lᵀ`` the calibration covariance (:mod:`wardjax.smartphone._alpha_model`), ``z ~ N(0, I)``.

``α = a + b t`` is derived. Priors: ``log α`` uniform on ``alpha_bounds`` (carried to
``log t`` with the Jacobian ``b t / α``; outside the bounds, or ``b ≤ 0``, the density is
0), ``log σ_obs ~ N(m, s²)`` from Table 1, ``z ~ N(0, I)``.

Likelihood, individual integer thresholds ``k_j`` (the gratings step in whole pixels;
an observer reports the grating nearest their latent threshold, clipped to the set
``k_min…k_max``):

.. math::

    P(k) = \\Phi\\!\\left(\\frac{\\log(k+\\tfrac12) - \\log t}{\\sigma}\\right)
         - \\Phi\\!\\left(\\frac{\\log(k-\\tfrac12) - \\log t}{\\sigma}\\right),

with the lower edge at ``−∞`` for ``k = k_min`` and the upper at ``+∞`` for ``k = k_max``.

A published mean ``m`` of ``n`` observers (e.g. Table 1b) uses a normal approximation
to the mean of ``n`` rounded log-normal thresholds: mean ``t e^{σ²/2}``, variance
``t² e^{σ²}(e^{σ²} − 1)/n + 1/(12 n)``.

Sampler
-------
emcee's :class:`~emcee.EnsembleSampler` with ``vectorize=True`` and a jit-compiled,
vmapped JAX log-probability (float64, scoped). Several independent surfaces can run in
lock step: the ensemble holds ``B × W`` walkers, walker rows grouped by surface, and a
custom :class:`emcee.moves.Move` makes the Goodman–Weare stretch move pair walkers only
within their own surface (with a balanced half split per surface), so each block is an
exact, independent ``W``-walker stretch-move ensemble. ``B = 1`` is the ordinary case.

Convergence: after a burn-in the chain is extended in chunks until its length is at
least ``50 τ`` (emcee's integrated autocorrelation time, the largest over parameters)
or ``max_steps`` is reached; a single posterior that has not converged is refused
(:class:`NotConvergedError`).
"""

from __future__ import annotations

from dataclasses import dataclass

import emcee
import jax
import jax.numpy as jnp
import numpy as np
from jax.lax import erfc
from numpy.typing import NDArray

from ._moves import block_moves

__all__ = [
    "AlphaPosterior",
    "AlphaPosteriorBatch",
    "NotConvergedError",
    "alpha_posterior",
    "alpha_posterior_batch",
    "log_prob_numpy",
    "simulate_observers",
]

PARAM_NAMES = ("alpha", "sigma_obs", "ppb_median", "cal_intercept", "cal_slope")
_NDIM = 4
_LEVELS = (0.025, 0.16, 0.5, 0.84, 0.975)
_INV_SQRT2 = float(1.0 / np.sqrt(2.0))


class NotConvergedError(RuntimeError):
    """The MCMC chain is shorter than the required number of autocorrelation times."""


# ----------------------------------------------------------------------------- the model


def _log_interval(lo, hi):
    """``log(Φ(hi) − Φ(lo))`` for ``lo < hi`` (either may be infinite).

    Both ends are reflected into the lower tail (``Φ(b) − Φ(a) = Φ(−a) − Φ(−b)``) and
    ``Φ(x) = erfc(−x/√2)/2`` is used there, where erfc keeps full relative precision; it
    underflows only beyond 37 σ (log-probability −∞). erfc is ~6× cheaper than
    ``log_ndtr`` on CPU, and this is the sampler's hot path.
    """
    flip = lo > 0
    a = jnp.where(flip, -hi, lo)
    b = jnp.where(flip, -lo, hi)
    diff = erfc(-b * _INV_SQRT2) - erfc(-a * _INV_SQRT2)
    return jnp.log(0.5 * diff)


def _log_prob_one(theta, k, mask, is_mean, mean_ppb, n_obs, mu, chol, hyper):
    """Log posterior (up to a constant) of one walker ``theta (4,)`` for one surface."""
    log_t, log_s, z1, z2 = theta[0], theta[1], theta[2], theta[3]
    s_mu, s_sd, log_a_lo, log_a_hi, k_min, k_max = (hyper[i] for i in range(6))
    a = mu[0] + chol[0, 0] * z1
    b = mu[1] + chol[1, 0] * z1 + chol[1, 1] * z2
    t = jnp.exp(log_t)
    sigma = jnp.exp(log_s)
    alpha = a + b * t
    ok = (b > 0) & (alpha > 0)
    log_alpha = jnp.log(jnp.where(ok, alpha, 1.0))
    ok = ok & (log_alpha >= log_a_lo) & (log_alpha <= log_a_hi)
    lp = -0.5 * (z1 * z1 + z2 * z2) - 0.5 * ((log_s - s_mu) / s_sd) ** 2
    lp = lp + jnp.log(jnp.where(ok, b * t, 1.0)) - log_alpha  # log-uniform α carried to log t
    # individual integer thresholds
    lo = jnp.where(k <= k_min, -jnp.inf, (jnp.log(jnp.maximum(k - 0.5, 1e-12)) - log_t) / sigma)
    hi = jnp.where(k >= k_max, jnp.inf, (jnp.log(k + 0.5) - log_t) / sigma)
    ll_ind = jnp.sum(jnp.where(mask, _log_interval(lo, hi), 0.0))
    # a published mean of n observers
    e_s2 = jnp.exp(sigma * sigma)
    m_exp = t * jnp.sqrt(e_s2)
    var = (t * t * e_s2 * (e_s2 - 1.0) + 1.0 / 12.0) / n_obs
    ll_mean = -0.5 * (mean_ppb - m_exp) ** 2 / var - 0.5 * jnp.log(2.0 * jnp.pi * var)
    lp = lp + jnp.where(is_mean, ll_mean, ll_ind)
    lp = jnp.where(ok, lp, -jnp.inf)
    return jnp.where(jnp.isnan(lp), -jnp.inf, lp)


_per_block = jax.vmap(_log_prob_one, in_axes=(0, None, None, None, None, None, None, None, None))
_batched = jax.jit(jax.vmap(_per_block, in_axes=(0, 0, 0, 0, 0, 0, 0, 0, None)))


def _observer_log_likelihood(log_t, sigma, k, is_mean, mean_ppb, n_obs, k_min, k_max):
    """Log-likelihood of the thresholds given each walker's median ``t = exp(log_t)`` and observer SD ``sigma``.

    Individual thresholds ``k`` (pixels per bar): each observer's log threshold is
    N(log t, σ²), read to the whole pixel (the interval ``[k − ½, k + ½]``) and censored at
    the grating set's ends ``k_min``, ``k_max``. A published mean of ``n_obs`` observers
    (``is_mean``): Gaussian with the log-normal's mean ``t e^{σ²/2}`` and variance
    ``(t² e^{σ²}(e^{σ²} − 1) + 1/12) / n_obs``. Shared by the calibrated-lines and the
    physical-model posteriors; ``log_t``, ``sigma`` are ``(W,)``.
    """
    from scipy.special import log_ndtr

    if is_mean:
        t, e_s2 = np.exp(log_t), np.exp(sigma**2)
        var = (t * t * e_s2 * (e_s2 - 1.0) + 1.0 / 12.0) / n_obs
        return -0.5 * (mean_ppb - t * np.sqrt(e_s2)) ** 2 / var - 0.5 * np.log(2 * np.pi * var)
    lo = np.where(k <= k_min, -np.inf, (np.log(np.maximum(k - 0.5, 1e-12))[None] - log_t[:, None]) / sigma[:, None])
    hi = np.where(k >= k_max, np.inf, (np.log(k + 0.5)[None] - log_t[:, None]) / sigma[:, None])
    flip = lo > 0
    aa, bb = np.where(flip, -hi, lo), np.where(flip, -lo, hi)
    lb, la = log_ndtr(bb), log_ndtr(aa)
    return np.sum(lb + np.log1p(-np.exp(np.minimum(la - lb, 0.0))), axis=-1)


def log_prob_numpy(theta, k, mask, is_mean, mean_ppb, n_obs, mu, chol, hyper):
    """The same log posterior for one surface in plain NumPy/SciPy (``theta (W, 4)``).

    The reference implementation: tests check the JAX version against it, and the
    benchmark times emcee with it.
    """
    theta = np.atleast_2d(theta)
    log_t, log_s, z1, z2 = theta.T
    s_mu, s_sd, log_a_lo, log_a_hi, k_min, k_max = hyper
    a = mu[0] + chol[0, 0] * z1
    b = mu[1] + chol[1, 0] * z1 + chol[1, 1] * z2
    t, sigma = np.exp(log_t), np.exp(log_s)
    alpha = a + b * t
    with np.errstate(divide="ignore", invalid="ignore"):
        log_alpha = np.log(np.where(alpha > 0, alpha, 1.0))
        ok = (b > 0) & (alpha > 0) & (log_alpha >= log_a_lo) & (log_alpha <= log_a_hi)
        lp = -0.5 * (z1**2 + z2**2) - 0.5 * ((log_s - s_mu) / s_sd) ** 2
        lp = lp + np.log(np.where(ok, b * t, 1.0)) - log_alpha
        kk = None if is_mean else np.asarray(k)[np.asarray(mask, bool)]
        lp = lp + _observer_log_likelihood(log_t, sigma, kk, is_mean, mean_ppb, n_obs, k_min, k_max)
    lp = np.where(ok, lp, -np.inf)
    return np.where(np.isnan(lp), -np.inf, lp)


# ----------------------------------------------------------------------------- inputs


def _as_thresholds(ppb, k_min: int, k_max: int, name: str = "ppb") -> NDArray:
    """Validate individual thresholds: integers in [k_min, k_max]. Returns float64 (M,)."""
    arr = np.asarray(ppb)
    if arr.dtype == bool or not (np.issubdtype(arr.dtype, np.integer) or np.issubdtype(arr.dtype, np.floating)):
        raise TypeError(f"{name} must be integer pixels-per-bar thresholds; got {ppb!r}")
    arr = np.atleast_1d(arr).astype(np.float64)
    if arr.ndim != 1 or arr.size == 0:
        raise ValueError(f"{name} must be a non-empty 1-D list of thresholds; got {ppb!r}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must be finite; got {ppb!r}")
    if np.any(arr != np.round(arr)):
        raise ValueError(
            f"{name} must hold whole pixels per bar (the gratings step in integer pixels); got {ppb!r}."
            " For a published mean use ppb_mean= with n_observers="
        )
    if np.any(arr < k_min) or np.any(arr > k_max):
        raise ValueError(f"{name} must lie in the grating set {k_min}..{k_max} PPB; got {ppb!r}")
    return arr


def _as_rho_d(rho_d, name="rho_d") -> NDArray:
    if rho_d is None:
        raise ValueError(f"{name} is required: a scalar or RGB diffuse reflectance in [0, 1]")
    r = np.asarray(rho_d, dtype=np.float64)
    if not (r.ndim == 0 or r.shape[-1] == 3):
        raise ValueError(f"{name} must be a scalar or RGB (3,); got shape {r.shape}")
    if not np.all(np.isfinite(r)) or np.any(r < 0) or np.any(r > 1):
        raise ValueError(f"{name} must lie in [0, 1]; got {rho_d!r}")
    return r


# ----------------------------------------------------------------------------- results


@dataclass(frozen=True)
class AlphaPosterior:
    """Posterior of α for one surface.

    Attributes
    ----------
    samples
        α draws, shape (n_steps × n_walkers,) (thinned by ``thin`` if set).
    params
        Named draws: ``alpha``, ``sigma_obs``, ``ppb_median`` (t), ``cal_intercept``, ``cal_slope``.
    tau
        Integrated autocorrelation time per sampled coordinate (steps):
        ``log_ppb_median``, ``log_sigma_obs``, ``z1``, ``z2``.
    acceptance
        Mean acceptance fraction.
    n_steps, n_walkers, burn
        Kept steps per walker, walkers, discarded burn-in steps.
    converged
        ``n_steps ≥ 50 · max(tau)``.
    """

    samples: NDArray
    params: dict
    tau: dict
    acceptance: float
    n_steps: int
    n_walkers: int
    burn: int
    converged: bool

    @property
    def mean(self) -> float:
        return float(np.mean(self.samples))

    @property
    def median(self) -> float:
        return float(np.median(self.samples))

    @property
    def std(self) -> float:
        return float(np.std(self.samples))

    @property
    def tau_max(self) -> float:
        return float(max(self.tau.values()))

    def interval(self, level: float = 0.95) -> tuple[float, float]:
        """Equal-tailed credible interval of α holding probability ``level`` (in (0, 1))."""
        if not 0.0 < level < 1.0:
            raise ValueError(f"level must be in (0, 1); got {level}")
        lo, hi = np.quantile(self.samples, [(1 - level) / 2, (1 + level) / 2])
        return float(lo), float(hi)

    def summary(self) -> str:
        lo68, hi68 = self.interval(0.68)
        lo95, hi95 = self.interval(0.95)
        return (
            f"alpha: mean {self.mean:.4f}, median {self.median:.4f}, 68% [{lo68:.4f}, {hi68:.4f}],"
            f" 95% [{lo95:.4f}, {hi95:.4f}]; sigma_obs median {np.median(self.params['sigma_obs']):.3f};"
            f" tau {self.tau_max:.1f} steps, {self.n_steps} steps x {self.n_walkers} walkers"
            f" ({self.n_steps / self.tau_max:.0f} tau), acceptance {self.acceptance:.2f}"
        )


@dataclass(frozen=True)
class AlphaPosteriorBatch:
    """Summaries of ``B`` independent posteriors run in lock step.

    Attributes
    ----------
    quantiles
        α quantiles at ``levels`` (0.025, 0.16, 0.5, 0.84, 0.975), shape (B, 5).
    mean
        Posterior mean of α, (B,).
    tau_max, acceptance, converged
        Per surface, (B,).
    n_steps
        Kept steps per walker (same for all).
    """

    quantiles: NDArray
    mean: NDArray
    tau_max: NDArray
    acceptance: NDArray
    converged: NDArray
    n_steps: int
    levels: tuple = _LEVELS
    params: list | None = None

    def interval(self, level: float = 0.95) -> NDArray:
        """(B, 2) equal-tailed intervals; ``level`` is 0.68 or 0.95."""
        pairs = {0.95: (0, 4), 0.68: (1, 3)}
        if level not in pairs:
            raise ValueError(f"level must be 0.68 or 0.95 for a batch; got {level}")
        i, j = pairs[level]
        return self.quantiles[:, [i, j]]


# ----------------------------------------------------------------------------- runner


def _problem_arrays(model, ppb_list, mean_list, nobs_list, rho_list):
    """Stack per-surface data into padded arrays for the batched log-probability."""
    nb = len(rho_list)
    m = max([1] + [len(k) for k in ppb_list if k is not None])
    k = np.ones((nb, m))
    mask = np.zeros((nb, m), dtype=bool)
    is_mean = np.zeros(nb, dtype=bool)
    mean_ppb = np.ones(nb)
    n_obs = np.ones(nb)
    mus = np.zeros((nb, 2))
    chols = np.zeros((nb, 2, 2))
    for i in range(nb):
        if ppb_list[i] is None:
            is_mean[i] = True
            mean_ppb[i] = mean_list[i]
            n_obs[i] = nobs_list[i]
        else:
            k[i, : len(ppb_list[i])] = ppb_list[i]
            mask[i, : len(ppb_list[i])] = True
        mu, cov = model.line(rho_list[i])
        mus[i] = mu
        chols[i] = np.linalg.cholesky(cov)
    lo, hi = model.alpha_bounds
    hyper = np.array(
        [
            model.log_sigma_obs_prior[0],
            model.log_sigma_obs_prior[1],
            np.log(lo),
            np.log(hi),
            float(model.display.ppb_min),
            float(model.display.ppb_max),
        ]
    )
    return (k, mask, is_mean, mean_ppb, n_obs, mus, chols), hyper


def _initial_walkers(data, hyper, n_walkers, rng, scale=1.0):
    """Walkers near the data's threshold, pulled inside the prior support at z = 0."""
    k, mask, is_mean, mean_ppb, n_obs, mus, chols = data
    nb = k.shape[0]
    centre = np.where(is_mean, mean_ppb, np.exp(np.sum(np.log(k) * mask, 1) / np.maximum(mask.sum(1), 1)))
    a, b = mus[:, 0], mus[:, 1]
    t_lo = np.maximum((np.exp(hyper[2]) - a) / b, 1e-3)
    t_hi = (np.exp(hyper[3]) - a) / b
    centre = np.exp(np.clip(np.log(centre), np.log(t_lo) + 0.1, np.log(t_hi) - 0.1))
    p0 = np.empty((nb, n_walkers, _NDIM))
    p0[..., 0] = np.log(centre)[:, None] + 0.05 * scale * rng.standard_normal((nb, n_walkers))
    p0[..., 1] = hyper[0] + 0.1 * scale * rng.standard_normal((nb, n_walkers))
    p0[..., 2:] = 0.1 * scale * rng.standard_normal((nb, n_walkers, 2))
    return p0


def _run(data, hyper, *, n_walkers, seed, burn, chunk, max_steps, thin, n_tau, use_numpy=False, move="de"):
    """Run the lock-step ensemble; returns the chain (steps, B, W, 4), acceptance (B,), tau (B, 4)."""
    if n_walkers < 2 * _NDIM or n_walkers % 2:
        raise ValueError(f"n_walkers must be even and ≥ {2 * _NDIM}; got {n_walkers}")
    nb = data[0].shape[0]
    rng = np.random.default_rng(seed)
    with jax.enable_x64(True):
        dev = tuple(jnp.asarray(x) for x in data)
        hyp = jnp.asarray(hyper)
        if use_numpy:
            if nb != 1:
                raise ValueError("the NumPy reference log-probability handles one surface")
            host = tuple(np.asarray(x)[0] for x in data)

            def log_prob(q: np.ndarray) -> np.ndarray:
                return log_prob_numpy(q, *host, hyper=hyper)
        else:

            def log_prob(q: np.ndarray) -> np.ndarray:
                lp = _batched(np.reshape(q, (nb, -1, _NDIM)), *dev, hyp)
                return np.asarray(lp).reshape(-1)

        p0 = _initial_walkers(data, hyper, n_walkers, rng).reshape(-1, _NDIM)
        lp0 = log_prob(p0)
        for attempt in range(20):  # redraw the few walkers that started outside the support
            bad = ~np.isfinite(lp0)
            if not bad.any():
                break
            fresh = _initial_walkers(data, hyper, n_walkers, rng, scale=0.5 ** (attempt + 1)).reshape(-1, _NDIM)
            p0[bad] = fresh[bad]
            lp0 = log_prob(p0)
        if np.any(~np.isfinite(lp0)):
            raise ValueError("could not start the walkers inside the prior support; check rho_d and the thresholds")
        sampler = emcee.EnsembleSampler(nb * n_walkers, _NDIM, log_prob, moves=block_moves(nb, move), vectorize=True)
        sampler.random_state = np.random.RandomState(int(rng.integers(2**31))).get_state()
        state = sampler.run_mcmc(p0, burn, skip_initial_state_check=True, progress=False)
        sampler.reset()
        steps, n_new = 0, max(1, min(chunk, max_steps) // thin)
        while True:
            state = sampler.run_mcmc(state, n_new, thin_by=thin, skip_initial_state_check=True, progress=False)
            steps += n_new * thin
            # emcee's get_value is typed Optional for blobs; the chain is always there after run_mcmc.
            chain = sampler.get_chain().reshape(-1, nb, n_walkers, _NDIM)  # pyright: ignore[reportOptionalMemberAccess]
            tau = (
                np.array([emcee.autocorr.integrated_time(chain[:, b], c=5, tol=0, quiet=True) for b in range(nb)])
                * thin
            )
            need = n_tau * tau.max(axis=1)
            if np.all(steps >= need) or steps >= max_steps:
                break
            # extend by what the current τ says is missing, with 15 % margin, at least 200 steps
            more = int(np.ceil(max(1.15 * need.max() - steps, 200)))
            n_new = max(1, min(more, max_steps - steps) // thin)
        acc = sampler.acceptance_fraction.reshape(nb, n_walkers).mean(axis=1)
    return chain, acc, tau, steps


def _derived(chain_b, mu, chol):
    """Named draws from one block's chain (steps, W, 4)."""
    x = chain_b.reshape(-1, _NDIM)
    t = np.exp(x[:, 0])
    a = mu[0] + chol[0, 0] * x[:, 2]
    b = mu[1] + chol[1, 0] * x[:, 2] + chol[1, 1] * x[:, 3]
    return {"alpha": a + b * t, "sigma_obs": np.exp(x[:, 1]), "ppb_median": t, "cal_intercept": a, "cal_slope": b}


def alpha_posterior(
    model,
    *,
    ppb=None,
    rho_d=None,
    ppb_mean=None,
    n_observers=None,
    seed: int,
    n_walkers: int = 32,
    burn: int = 300,
    chunk: int = 1000,
    max_steps: int = 20000,
    n_tau: float = 50.0,
    display=None,
    viewing=None,
    log_prob: str = "jax",
) -> AlphaPosterior:
    """Posterior of a surface's α from grating thresholds (see the module docstring).

    Parameters
    ----------
    model
        An :class:`~wardjax.AlphaModel`.
    ppb
        Individual observers' threshold PPBs: whole numbers in the display's grating set.
    rho_d
        The surface's diffuse reflectance: scalar (grey) or RGB (sRGB primaries, white E).
    ppb_mean, n_observers
        Instead of ``ppb``: a published mean threshold and how many observers it averages.
    seed
        Seed of the sampler (required; no global RNG is touched).
    n_walkers, burn, chunk, max_steps, n_tau
        Walkers; burn-in steps; steps added per round; the step cap; the required chain
        length in autocorrelation times.
    display, viewing
        Set-up the thresholds were measured on, when not the calibration's; thresholds
        are then mapped to the calibration set-up at equal cycles/degree (individual
        thresholds need the calibration set-up, where they are whole pixels).
    log_prob
        ``"jax"`` (jit-compiled, vectorised) or ``"numpy"`` (the plain reference; slower).

    Raises
    ------
    NotConvergedError
        When ``max_steps`` were not enough for ``n_tau`` autocorrelation times.
    """
    k_min, k_max = model.display.ppb_min, model.display.ppb_max
    rho = _as_rho_d(rho_d)
    either = "give either ppb=[...] (individual thresholds) or ppb_mean= with n_observers=, not both"
    if ppb is not None:
        if ppb_mean is not None:
            raise ValueError(either)
        if n_observers is not None:
            raise ValueError("n_observers goes with ppb_mean=; with ppb=[...] each entry is one observer")
        if display is not None or viewing is not None:
            raise ValueError(
                "individual integer thresholds must be measured on the calibration set-up;"
                " convert them with AlphaModel.to_model_ppb and pass ppb_mean="
            )
        k = _as_thresholds(ppb, k_min, k_max)
        plist, mlist, nlist = [k], [None], [None]
    elif ppb_mean is None:
        raise ValueError(either)
    else:
        if (
            n_observers is None
            or isinstance(n_observers, bool)
            or not isinstance(n_observers, (int, np.integer))
            or n_observers < 1
        ):
            raise ValueError(f"n_observers must be a positive integer with ppb_mean; got {n_observers!r}")
        m = float(ppb_mean)
        if not np.isfinite(m) or m <= 0:
            raise ValueError(f"ppb_mean must be a positive number of pixels per bar; got {ppb_mean!r}")
        if display is not None or viewing is not None:
            m = float(model.to_model_ppb(m, display or model.display, viewing or model.viewing))
        if not k_min <= m <= k_max:
            raise ValueError(f"ppb_mean must lie in the grating set {k_min}..{k_max} PPB; got {m:g}")
        plist, mlist, nlist = [None], [m], [int(n_observers)]
    if log_prob not in ("jax", "numpy"):
        raise ValueError(f"log_prob must be 'jax' or 'numpy'; got {log_prob!r}")
    data, hyper = _problem_arrays(model, plist, mlist, nlist, [rho])
    chain, acc, tau, steps = _run(
        data,
        hyper,
        n_walkers=n_walkers,
        seed=seed,
        burn=burn,
        chunk=chunk,
        max_steps=max_steps,
        thin=1,
        n_tau=n_tau,
        use_numpy=log_prob == "numpy",
    )
    tau_d = dict(zip(("log_ppb_median", "log_sigma_obs", "z1", "z2"), (float(v) for v in tau[0])))
    converged = bool(steps >= n_tau * tau[0].max())
    if not converged:
        raise NotConvergedError(
            f"alpha posterior not converged: {steps} steps < {n_tau:g} autocorrelation times"
            f" (tau = {tau[0].max():.0f} steps); raise max_steps (now {max_steps})"
        )
    params = _derived(chain[:, 0], data[5][0], data[6][0])
    return AlphaPosterior(
        samples=params["alpha"],
        params=params,
        tau=tau_d,
        acceptance=float(acc[0]),
        n_steps=steps,
        n_walkers=n_walkers,
        burn=burn,
        converged=converged,
    )


def alpha_posterior_batch(
    model,
    *,
    ppb=None,
    rho_d,
    ppb_mean=None,
    n_observers=None,
    seed: int,
    n_walkers: int = 32,
    burn: int = 300,
    chunk: int = 2500,
    max_steps: int = 8000,
    n_tau: float = 50.0,
    thin: int = 5,
    keep_samples: bool = False,
) -> AlphaPosteriorBatch:
    """``B`` independent posteriors (individual thresholds) in one lock-step emcee run.

    Parameters
    ----------
    ppb
        ``(B, M)`` whole-pixel thresholds, ``M`` observers per surface (pad with 0 for
        fewer; 0 means "no observer"); or
    ppb_mean, n_observers
        ``(B,)`` published mean thresholds and the number of observers behind each.
    rho_d
        ``(B,)`` grey or ``(B, 3)`` RGB.
    thin
        Keep every ``thin``-th step (memory); τ is reported in steps.
    keep_samples
        Also keep each surface's named draws (``params``, a list of dicts).

    Non-converged surfaces are flagged in ``converged``, not raised.
    """
    rho_all = np.asarray(rho_d, dtype=np.float64)
    k_min, k_max = model.display.ppb_min, model.display.ppb_max
    either = "give either ppb (B, M) or ppb_mean (B,) with n_observers (B,), not both"
    if ppb is not None:
        if ppb_mean is not None:
            raise ValueError(either)
        k_all = np.asarray(ppb)
        if k_all.ndim != 2:
            raise ValueError(f"ppb must be (B, M); got shape {k_all.shape}")
        plist = [_as_thresholds(row[row != 0], k_min, k_max) for row in k_all]
        mlist = nlist = [None] * len(plist)
    elif ppb_mean is None:
        raise ValueError(either)
    else:
        mlist = [float(m) for m in np.atleast_1d(ppb_mean)]
        nlist = [int(n) for n in np.broadcast_to(np.asarray(n_observers), (len(mlist),))]
        if any(not (k_min <= m <= k_max) for m in mlist) or any(n < 1 for n in nlist):
            raise ValueError(f"ppb_mean must lie in {k_min}..{k_max} and n_observers be ≥ 1")
        plist = [None] * len(mlist)
    rlist = [_as_rho_d(r) for r in rho_all]
    if len(rlist) != len(plist):
        raise ValueError(f"rho_d has {len(rlist)} surfaces, the thresholds {len(plist)}")
    data, hyper = _problem_arrays(model, plist, mlist, nlist, rlist)
    chain, acc, tau, steps = _run(
        data, hyper, n_walkers=n_walkers, seed=seed, burn=burn, chunk=chunk, max_steps=max_steps, thin=thin, n_tau=n_tau
    )
    nb = len(plist)
    q = np.empty((nb, len(_LEVELS)))
    mean = np.empty(nb)
    draws = []
    for b in range(nb):
        d = _derived(chain[:, b], data[5][b], data[6][b])
        q[b] = np.quantile(d["alpha"], _LEVELS)
        mean[b] = d["alpha"].mean()
        if keep_samples:
            draws.append(d)
    return AlphaPosteriorBatch(
        quantiles=q,
        mean=mean,
        tau_max=tau.max(axis=1),
        acceptance=acc,
        converged=steps >= n_tau * tau.max(axis=1),
        n_steps=steps,
        params=draws if keep_samples else None,
    )


def simulate_observers(model, rho_d, n_observers: int, rng: np.random.Generator) -> tuple[NDArray, dict]:
    """Draw surfaces and observers from the model's prior and likelihood (for coverage tests).

    For each ρd (``(B,)`` grey or ``(B, 3)``): ``z ~ N(0, I)``, ``σ_obs`` from its prior,
    ``log α`` uniform on the bounds, ``t = (α − a)/b`` (redrawn while ``b ≤ 0`` or
    ``t ≤ 0``, exactly the sampler's prior support), then ``n_observers`` thresholds
    ``k = clip(round(t e^{σ ε}), k_min, k_max)``.

    Returns
    -------
    ppb : ndarray, int, shape (B, n_observers)
    truth : dict of (B,) arrays: ``alpha``, ``sigma_obs``, ``ppb_median``, ``cal_intercept``, ``cal_slope``.
    """
    rho = np.asarray(rho_d, dtype=np.float64)
    if rho.ndim == 1:  # greys: R = G = B keeps Y = ρd
        rho = np.repeat(rho[:, None], 3, axis=1)
    nb = rho.shape[0]
    mu, cov = model.line(rho)
    chol = np.linalg.cholesky(cov)
    lo, hi = np.log(model.alpha_bounds[0]), np.log(model.alpha_bounds[1])
    out = {k: np.empty(nb) for k in PARAM_NAMES}
    todo = np.arange(nb)
    while todo.size:
        z = rng.standard_normal((todo.size, 2))
        ab = mu[todo] + np.einsum("bij,bj->bi", chol[todo], z)
        alpha = np.exp(rng.uniform(lo, hi, todo.size))
        t = (alpha - ab[:, 0]) / ab[:, 1]
        good = (ab[:, 1] > 0) & (t > 0)
        idx = todo[good]
        out["alpha"][idx], out["ppb_median"][idx] = alpha[good], t[good]
        out["cal_intercept"][idx], out["cal_slope"][idx] = ab[good, 0], ab[good, 1]
        todo = todo[~good]
    m, sd = model.log_sigma_obs_prior
    out["sigma_obs"] = np.exp(m + sd * rng.standard_normal(nb))
    eps = rng.standard_normal((nb, n_observers))
    latent = out["ppb_median"][:, None] * np.exp(out["sigma_obs"][:, None] * eps)
    k = np.clip(np.round(latent), model.display.ppb_min, model.display.ppb_max).astype(int)
    return k, out
