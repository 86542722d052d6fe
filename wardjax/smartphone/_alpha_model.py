"""The threshold-PPB → Ward α model of the smartphone paper, calibrated on its Table 1.

Published model (paper section 6, Fig. 8b)
    One straight line per NCS lightness ``i`` (white 0500, light grey 2500, dark grey
    5000, black 9000): ``α = a_i + b_i · PPB``. The lines are fitted here by least squares
    to the (Table 1b PPB, Table 1c α) pairs of each lightness; they give Table 1c back to
    within the table's rounding (±0.0005; tested at ±0.001 in every cell).

Lightness interpolation
    A surface's ρd (scalar grey or RGB with sRGB primaries, white E) gives its luminance
    factor ``Y`` and CIE 1976 lightness ``L* = 116 f(Y) − 16``. The anchors are the
    lightnesses of the NCS set's own ρd estimates (0.853, 0.485, 0.245, 0.010); ``a`` and
    ``b`` are interpolated linearly in ``L*`` between them (held constant beyond the ends).

Physical lines (paper section 6, Fig. 8a)
    ``SD_i = c_i + d_i · PPB`` on Table 1a/1b over gloss 95–30 (the paper leaves out 12
    and 6, whose lobe SDs it distrusts), with R² per lightness. The ratio ``b_i / d_i`` is
    the scale from lobe SD (degrees) to Ward α that the published model implies.

Uncertainty carried into the posterior (see :mod:`wardjax.smartphone._alpha_posterior`)
    - calibration: the published lines are a point estimate; their uncertainty is taken
      from the physical fits, whose covariance ``s² (XᵀX)⁻¹`` (``s²`` pooled over the
      four lines, 8 degrees of freedom) is carried into α units by ``(b_i/d_i)²``;
    - observer noise: each observer's latent threshold is log-normal around the median
      threshold with SD ``σ_obs`` (natural-log units). Table 1 gives its scale: the pooled
      relative PPB residual of the physical lines, ``δ = (SD − ŜD)/(d·PPB)``, minus the
      quantisation variance of a mean of three rounded values, times 3 (Table 1b means
      three observers). This over-estimates ``σ_obs`` (it also holds the glossmeter's
      error), so the prior on ``log σ_obs`` is centred there with a wide SD of 0.5.
"""

from __future__ import annotations

import csv
from dataclasses import dataclass, field
from functools import lru_cache

import colour
import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._data import calibration_path
from ..capture import Display, Viewing, load_display, load_viewing
from ._alpha_posterior import alpha_posterior, alpha_posterior_batch
from ._color import luminance_from_rho_d
from ._gratings import cpd_to_ppb, ppb_to_cpd

__all__ = ["AlphaModel", "PhysicalLines", "lightness_from_rho_d", "load_table1", "physical_lines"]

NCS_ORDER = ("0500", "2500", "5000", "9000")
GLOSS_ORDER = (95, 75, 50, 30, 12, 6)
PHYSICAL_GLOSS = (95, 75, 50, 30)


def _read_csv(name: str) -> list[dict]:
    """Rows of a ``calibration/`` CSV, skipping ``#`` comment lines."""
    with open(calibration_path(name), encoding="utf-8") as fh:
        return list(csv.DictReader(r for r in fh if not r.startswith("#")))


@lru_cache(maxsize=1)
def load_table1() -> dict[str, NDArray]:
    """Table 1 as arrays of shape (4 lightness, 6 gloss): ``lobe_sd_deg``, ``ppb``, ``alpha``.

    Rows follow :data:`NCS_ORDER`, columns :data:`GLOSS_ORDER`; also ``rho_d`` (4,), the
    NCS ρd estimates of the paper's section 7.
    """
    out = {k: np.full((4, 6), np.nan) for k in ("lobe_sd_deg", "ppb", "alpha")}
    for row in _read_csv("smartphone_table1.csv"):
        i, j = NCS_ORDER.index(row["ncs"]), GLOSS_ORDER.index(int(row["gloss"]))
        for k in out:
            out[k][i, j] = float(row[k])
    rho = {r["ncs"]: float(r["rho_d"]) for r in _read_csv("smartphone_ncs_rho_d.csv")}
    out["rho_d"] = np.array([rho[n] for n in NCS_ORDER])
    return out


def lightness_from_rho_d(rho_d: ArrayLike, *, grey: bool = False) -> NDArray:
    """CIE 1976 L* of ρd: a scalar (grey), RGB on the last axis (sRGB primaries, white E),
    or, with ``grey=True``, an array of grey values (Y = ρd)."""
    r = np.asarray(rho_d, dtype=np.float64)
    y = r if grey else luminance_from_rho_d(r)
    return np.asarray(colour.lightness(np.clip(y, 0.0, None) * 100.0, method="CIE 1976"))


def _line_fit(x: NDArray, y: NDArray) -> tuple[NDArray, NDArray, float]:
    """Least-squares ``y = c0 + c1 x``: coefficients, (XᵀX)⁻¹, R²."""
    X = np.stack([np.ones_like(x), x], axis=-1)
    coef, *_ = np.linalg.lstsq(X, y, rcond=None)
    res = y - X @ coef
    r2 = 1.0 - (res @ res) / np.sum((y - y.mean()) ** 2)
    return coef, np.linalg.inv(X.T @ X), float(r2)


@dataclass(frozen=True)
class PhysicalLines:
    """Fits of lobe SD on threshold PPB (Table 1a on 1b), one per NCS lightness.

    Attributes
    ----------
    intercept, slope
        ``SD = intercept + slope · PPB`` (degrees; degrees per PPB), shape (4,).
    r2
        Coefficient of determination per line (the paper: all > 0.96).
    cov
        Covariance of (intercept, slope) per line, pooled residual variance, (4, 2, 2).
    sd_to_alpha
        ``b_i / slope_i``: Ward α per degree of lobe SD implied by the published model.
    sigma_obs
        Per-observer log-threshold SD implied by the residuals (see module docstring).
    residual_dof
        Degrees of freedom of the pooled residual variance.
    """

    intercept: NDArray
    slope: NDArray
    r2: NDArray
    cov: NDArray
    sd_to_alpha: NDArray
    sigma_obs: float
    residual_dof: int


def _published_lines() -> tuple[NDArray, NDArray]:
    t = load_table1()
    coefs = np.array([_line_fit(t["ppb"][i], t["alpha"][i])[0] for i in range(4)])
    return coefs[:, 0], coefs[:, 1]


def physical_lines() -> PhysicalLines:
    """Fit the physical PPB→SD lines on Table 1a/1b, gloss 95–30 (see :class:`PhysicalLines`)."""
    t = load_table1()
    cols = [GLOSS_ORDER.index(g) for g in PHYSICAL_GLOSS]
    _, b = _published_lines()
    coefs, xtx_inv, r2s, res_all, rel_all, q_all = [], [], [], [], [], []
    for i in range(4):
        x, y = t["ppb"][i, cols], t["lobe_sd_deg"][i, cols]
        coef, inv, r2 = _line_fit(x, y)
        res = y - (coef[0] + coef[1] * x)
        coefs.append(coef)
        xtx_inv.append(inv)
        r2s.append(r2)
        res_all.append(res)
        rel_all.append(res / (coef[1] * x))
        q_all.append(1.0 / (12.0 * 3.0 * x**2))
    coefs = np.array(coefs)
    dof = 4 * (len(cols) - 2)
    s2 = float(np.sum(np.concatenate(res_all) ** 2) / dof)
    rel_var = float(np.sum(np.concatenate(rel_all) ** 2) / dof)
    sigma_obs = float(np.sqrt(3.0 * max(rel_var - float(np.mean(np.concatenate(q_all))), 1e-4)))
    return PhysicalLines(
        intercept=coefs[:, 0],
        slope=coefs[:, 1],
        r2=np.array(r2s),
        cov=s2 * np.array(xtx_inv),
        sd_to_alpha=b / coefs[:, 1],
        sigma_obs=sigma_obs,
        residual_dof=dof,
    )


@dataclass(frozen=True)
class AlphaModel:
    """Threshold PPB → Ward α for a surface of given ρd, with its uncertainty.

    Build it with :meth:`from_calibration`. ``alpha(ppb, rho_d)`` is the published point
    model; :meth:`posterior` the full Bayesian estimate (emcee).

    Attributes
    ----------
    anchor_lightness
        L* of the four NCS anchors (descending: white … black), (4,).
    intercept, slope
        Published lines ``α = intercept + slope · PPB`` per anchor, (4,).
    cov
        Calibration covariance of (intercept, slope) per anchor, (4, 2, 2).
    log_sigma_obs_prior
        (mean, sd) of the normal prior on ``log σ_obs``.
    alpha_bounds
        Support of the log-uniform prior on α.
    display, viewing
        The set-up the model was calibrated for (the paper's).
    """

    anchor_lightness: NDArray
    intercept: NDArray
    slope: NDArray
    cov: NDArray
    log_sigma_obs_prior: tuple[float, float]
    alpha_bounds: tuple[float, float] = (5e-4, 0.3)
    display: Display = field(default_factory=lambda: load_display("iphone5s"))
    viewing: Viewing = field(default_factory=lambda: load_viewing("paper"))

    @classmethod
    def from_calibration(cls, *, sigma_obs_prior_sd: float = 0.5, alpha_bounds=(5e-4, 0.3)) -> AlphaModel:
        """The model calibrated on ``calibration/smartphone_table1.csv`` (see module docstring)."""
        t = load_table1()
        a, b = _published_lines()
        phys = physical_lines()
        scale = b / phys.slope
        cov = phys.cov * (scale**2)[:, None, None]
        return cls(
            anchor_lightness=lightness_from_rho_d(t["rho_d"], grey=True),
            intercept=a,
            slope=b,
            cov=cov,
            log_sigma_obs_prior=(float(np.log(phys.sigma_obs)), float(sigma_obs_prior_sd)),
            alpha_bounds=(float(alpha_bounds[0]), float(alpha_bounds[1])),
        )

    # ------------------------------------------------------------------ point model

    def _weights(self, rho_d: ArrayLike) -> NDArray:
        """Interpolation weights over the 4 anchors, shape (..., 4), from ρd's lightness."""
        lstar = lightness_from_rho_d(rho_d)
        xp = self.anchor_lightness[::-1]  # ascending
        eye = np.eye(4)[::-1]
        return np.stack([np.interp(lstar, xp, eye[:, k]) for k in range(4)], axis=-1)

    def line(self, rho_d: ArrayLike) -> tuple[NDArray, NDArray]:
        """Mean (intercept, slope) and their 2×2 covariance at the lightness of ``rho_d``."""
        w = self._weights(rho_d)
        mean = np.stack([w @ self.intercept, w @ self.slope], axis=-1)
        cov = np.einsum("...k,kij->...ij", w**2, self.cov)
        return mean, cov

    def alpha(self, ppb: ArrayLike, rho_d: ArrayLike) -> NDArray | np.floating:
        """The published point model ``α = a(L*) + b(L*) · PPB`` (broadcasts ``ppb`` with ρd's lightness)."""
        (mean, _) = self.line(rho_d)
        return mean[..., 0] + mean[..., 1] * np.asarray(ppb, dtype=np.float64)

    def ppb_for_alpha(self, alpha: ArrayLike, rho_d: ArrayLike) -> NDArray | np.floating:
        """Inverse of :meth:`alpha`: the (continuous) threshold PPB the model predicts."""
        (mean, _) = self.line(rho_d)
        return (np.asarray(alpha, dtype=np.float64) - mean[..., 0]) / mean[..., 1]

    def to_model_ppb(self, ppb: ArrayLike, display: str | Display, viewing: str | Viewing) -> NDArray | np.floating:
        """PPB measured on another set-up → the PPB of the calibration set-up with the same CPD.

        The model is calibrated only for the paper's set-up; other set-ups are mapped by
        matching the grating's angular frequency at the eye (an approximation: it ignores
        how the surface-to-screen distance changes the blur in the reflection).
        """
        return cpd_to_ppb(ppb_to_cpd(ppb, display, viewing), self.display, self.viewing)

    # ------------------------------------------------------------------ posterior

    def posterior(self, ppb=None, rho_d=None, *, ppb_mean=None, n_observers=None, seed: int, **kwargs):
        """Posterior of α from grating thresholds (emcee); see :func:`wardjax.smartphone.alpha_posterior`."""
        return alpha_posterior(
            self, ppb=ppb, rho_d=rho_d, ppb_mean=ppb_mean, n_observers=n_observers, seed=seed, **kwargs
        )

    def posterior_batch(self, ppb=None, rho_d=None, *, seed: int, **kwargs):
        """Many independent posteriors in one lock-step emcee run.

        See :func:`wardjax.smartphone.alpha_posterior_batch`.
        """
        return alpha_posterior_batch(self, ppb=ppb, rho_d=rho_d, seed=seed, **kwargs)
