"""Bayesian α from grating thresholds by inverting the physical threshold model.

Beside the paper's calibrated lines (:mod:`wardjax.smartphone._alpha_posterior`), α is
estimated here through :func:`wardjax.smartphone.threshold_ppb`, whose CSF constants come
from castleCSF data only, so that the posterior carries the model's own uncertainty.

Model (one surface)
-------------------
Parameters, sampled as ``θ = (log α, η, log σ_obs)``:

- ``α`` — Ward roughness; its lobe SD is ``SD = α / k(L*)`` with ``k`` the α-per-degree
  scale of the published model at the surface's lightness
  (:attr:`PhysicalLines.sd_to_alpha`, interpolated like :meth:`AlphaModel.line`);
- ``η ~ N(0, 1)`` — the model error: the population's median threshold is

  .. math::

      \\log t = \\log T(SD) + \\sigma_m(SD)\\,\\eta,

  where ``T`` is the physical model and ``σ_m`` the spread of ``log T`` when the CSF is
  off by its own out-of-sample scatter: ``σ_m = |log T(S e^{s}) − log T(S e^{−s})| / 2``
  with ``s = ln 10 · RMS`` of the CSF's leave-one-out errors of log10 S on its castleCSF
  calibration data (:func:`wardjax.smartphone.csf_cv_scatter`; 0.158 for Barten on the
  gratings), never Table 1. ``model_error=False`` sets ``σ_m = 0``; a number sets a
  constant ``σ_m`` (natural-log units of the threshold), e.g. a scatter measured elsewhere;
- ``σ_obs`` — observer noise, as in the calibrated-lines posterior (same prior).

Priors: ``log α`` uniform on the model's ``alpha_bounds``, ``η ~ N(0, 1)``,
``log σ_obs ~ N(m, s²)`` (:attr:`AlphaModel.log_sigma_obs_prior`). The likelihood of the
thresholds is the calibrated-lines posterior's (whole-pixel intervals of a log-normal
observer, censored at the grating set's ends; or a published mean of ``n`` observers).
``T`` and ``σ_m`` are tabulated once per surface on 161 lobe SDs (log-spaced over the
prior's range) and interpolated in log SD.

Sampler: emcee, burn-in then chunks until the chain is ``n_tau`` autocorrelation times long.
"""

from __future__ import annotations

import emcee
import numpy as np
from numpy.typing import NDArray

from ._alpha_model import AlphaModel, physical_lines
from ._alpha_posterior import (
    AlphaPosterior,
    NotConvergedError,
    _as_rho_d,
    _as_thresholds,
    _observer_log_likelihood,
)
from ._color import luminance_from_rho_d
from ._threshold_model import csf_cv_scatter, threshold_ppb

__all__ = ["alpha_posterior_physical", "physical_threshold_table"]

_NDIM = 3
_N_GRID = 161


def _sd_per_alpha(model: AlphaModel, rho_d) -> float:
    """``1 / k``: lobe SD (degrees) per unit α at the surface's lightness."""
    k = float(model._weights(rho_d) @ physical_lines().sd_to_alpha)
    return 1.0 / k


def physical_threshold_table(
    model: AlphaModel,
    rho_d,
    *,
    model_error: bool | float = True,
    csf: str = "Barten 1999",
    calibration: str = "gratings",
    **physics,
) -> tuple[NDArray, NDArray, NDArray]:
    """Tabulated ``(log α, log T, σ_m)`` on 161 points over the model's α bounds (see module docstring).

    ``physics`` passes ``rho_s``, ``ambient_cd_m2``, ``display`` and ``viewing`` to
    :func:`wardjax.smartphone.threshold_ppb`.
    """
    rho = _as_rho_d(rho_d)
    y = float(luminance_from_rho_d(rho))
    log_a = np.linspace(np.log(model.alpha_bounds[0]), np.log(model.alpha_bounds[1]), _N_GRID)
    sd = np.exp(log_a) * _sd_per_alpha(model, rho)
    kw: dict = {"csf": csf, "calibration": calibration, **physics}
    log_t = np.log(threshold_ppb(sd, y, **kw))
    if isinstance(model_error, bool) and not model_error:
        return log_a, log_t, np.zeros_like(log_t)
    if not isinstance(model_error, bool):
        if not (np.isfinite(model_error) and model_error >= 0):
            raise ValueError(f"model_error must be True, False or a log-threshold SD >= 0; got {model_error!r}")
        return log_a, log_t, np.full_like(log_t, float(model_error))
    s = np.log(10.0) * csf_cv_scatter(csf, calibration)
    up = np.log(threshold_ppb(sd, y, sensitivity_scale=float(np.exp(s)), **kw))
    down = np.log(threshold_ppb(sd, y, sensitivity_scale=float(np.exp(-s)), **kw))
    return log_a, log_t, 0.5 * np.abs(down - up)


def _log_prob(theta, table, data, hyper):
    """Log posterior (up to a constant) of walkers ``theta (W, 3)``."""
    log_a_grid, log_t_grid, sig_grid = table
    k, is_mean, mean_ppb, n_obs = data
    s_mu, s_sd, k_min, k_max = hyper
    log_a, eta, log_s = np.atleast_2d(theta).T
    ok = (log_a >= log_a_grid[0]) & (log_a <= log_a_grid[-1])
    log_t = np.interp(log_a, log_a_grid, log_t_grid) + np.interp(log_a, log_a_grid, sig_grid) * eta
    sigma = np.exp(log_s)
    lp = -0.5 * eta**2 - 0.5 * ((log_s - s_mu) / s_sd) ** 2
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        lp = lp + _observer_log_likelihood(log_t, sigma, k, is_mean, mean_ppb, n_obs, k_min, k_max)
    lp = np.where(ok, lp, -np.inf)
    return np.where(np.isnan(lp), -np.inf, lp)


def _thresholds(model, ppb, ppb_mean, n_observers):
    k_min, k_max = model.display.ppb_min, model.display.ppb_max
    if (ppb is None) == (ppb_mean is None):
        raise ValueError("give either ppb=[...] (individual thresholds) or ppb_mean= with n_observers=, not both")
    if ppb is not None:
        k = _as_thresholds(ppb, k_min, k_max)
        return (k, False, 1.0, 1.0), float(np.exp(np.mean(np.log(k))))
    if isinstance(n_observers, bool) or not isinstance(n_observers, (int, np.integer)) or n_observers < 1:
        raise ValueError(f"n_observers must be a positive integer with ppb_mean; got {n_observers!r}")
    m = float(ppb_mean)
    if not k_min <= m <= k_max:
        raise ValueError(f"ppb_mean must lie in the grating set {k_min}..{k_max} PPB; got {ppb_mean!r}")
    return (np.ones(1), True, m, float(n_observers)), m


def alpha_posterior_physical(
    model: AlphaModel,
    *,
    ppb=None,
    rho_d=None,
    ppb_mean=None,
    n_observers=None,
    seed: int,
    model_error: bool | float = True,
    csf: str = "Barten 1999",
    calibration: str = "gratings",
    n_walkers: int = 32,
    burn: int = 300,
    chunk: int = 1000,
    max_steps: int = 20000,
    n_tau: float = 50.0,
    **physics,
) -> AlphaPosterior:
    """Posterior of α from thresholds through the physical threshold model (module docstring).

    Arguments as :func:`wardjax.smartphone.alpha_posterior` (``model`` supplies the α
    bounds, the observer-noise prior, the display's grating set and the SD → α scale);
    ``model_error`` switches the CSF's out-of-sample scatter on or off (or, a number, sets
    a constant log-threshold SD); ``csf``,
    ``calibration`` and ``physics`` (``rho_s``, ``ambient_cd_m2``, ``display``,
    ``viewing``) configure :func:`wardjax.smartphone.threshold_ppb`.

    ``params`` holds ``alpha``, ``lobe_sd_deg``, ``ppb_median`` (t), ``sigma_obs`` and
    ``model_error`` (η); ``tau`` is keyed ``log_alpha``, ``eta``, ``log_sigma_obs``.

    Raises
    ------
    NotConvergedError
        When ``max_steps`` were not enough for ``n_tau`` autocorrelation times.
    """
    rho = _as_rho_d(rho_d)
    data, centre = _thresholds(model, ppb, ppb_mean, n_observers)
    table = physical_threshold_table(model, rho, model_error=model_error, csf=csf, calibration=calibration, **physics)
    hyper = (*model.log_sigma_obs_prior, float(model.display.ppb_min), float(model.display.ppb_max))
    rng = np.random.default_rng(seed)
    start = table[0][np.argmin(np.abs(table[1] - np.log(centre)))]
    p0 = np.empty((n_walkers, _NDIM))
    p0[:, 0] = np.clip(start + 0.1 * rng.standard_normal(n_walkers), table[0][0] + 1e-6, table[0][-1] - 1e-6)
    p0[:, 1] = 0.1 * rng.standard_normal(n_walkers)
    p0[:, 2] = hyper[0] + 0.1 * rng.standard_normal(n_walkers)

    def log_prob(q):
        return _log_prob(q, table, data, hyper)

    sampler = emcee.EnsembleSampler(n_walkers, _NDIM, log_prob, vectorize=True)
    sampler.random_state = np.random.RandomState(int(rng.integers(2**31))).get_state()
    state = sampler.run_mcmc(p0, burn, progress=False)
    sampler.reset()
    steps, n_new = 0, chunk
    while True:
        state = sampler.run_mcmc(state, n_new, progress=False)
        steps += n_new
        tau = emcee.autocorr.integrated_time(sampler.get_chain(), c=5, tol=0, quiet=True)
        if steps >= n_tau * tau.max() or steps >= max_steps:
            break
        n_new = int(min(max(np.ceil(1.15 * n_tau * tau.max() - steps), 200), max_steps - steps))
    if steps < n_tau * tau.max():
        raise NotConvergedError(
            f"alpha posterior (physical) not converged: {steps} steps < {n_tau:g} autocorrelation times"
            f" (tau = {tau.max():.0f} steps); raise max_steps (now {max_steps})"
        )
    x = np.asarray(sampler.get_chain(flat=True))
    log_a_grid, log_t_grid, sig_grid = table
    log_t = np.interp(x[:, 0], log_a_grid, log_t_grid) + np.interp(x[:, 0], log_a_grid, sig_grid) * x[:, 1]
    alpha = np.exp(x[:, 0])
    params = {
        "alpha": alpha,
        "lobe_sd_deg": alpha * _sd_per_alpha(model, rho),
        "ppb_median": np.exp(log_t),
        "sigma_obs": np.exp(x[:, 2]),
        "model_error": x[:, 1],
    }
    return AlphaPosterior(
        samples=alpha,
        params=params,
        tau=dict(zip(("log_alpha", "eta", "log_sigma_obs"), (float(v) for v in tau))),
        acceptance=float(np.mean(sampler.acceptance_fraction)),
        n_steps=steps,
        n_walkers=n_walkers,
        burn=burn,
        converged=True,
    )
