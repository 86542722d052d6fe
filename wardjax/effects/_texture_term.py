"""The probe's ρd texture carried in the scanline model: the whitened data, and the design effect of the rest.

:func:`with_texture` measures the texture on the baseline's residuals and
returns the data whitened by it (:mod:`wardjax.effects._texture`);
:class:`CrossTexture` keeps what the per-scanline whitening leaves out —
the texture shared by neighbouring scanlines — for each candidate's
evidence.
"""

from __future__ import annotations

import dataclasses
from typing import NamedTuple

import numpy as np

from ._texture import (
    cross_covariance,
    design_effect,
    estimate_texture,
    joint_autocovariance,
    lag_covariances,
    level_noise,
    texture_whitening,
)

__all__ = ["CrossTexture", "with_texture"]

_NOISE_FLOOR = 0.02  # white noise off the highlight at least this fraction of the texture variance
_CALIBRATION_SCANLINES = 24  # scanlines the noise calibration whitens


def with_texture(data, pred: np.ndarray):
    """``data`` with the texture carried as a Gaussian process, a summary, and the texture the process leaves out.

    Returns ``(data, summary, CrossTexture)``. The white noise is re-estimated jointly with the texture from the
    baseline's residuals (the lag-1 estimate counted texture as noise); the
    process's autocovariance along the scanline is the measured one
    (:func:`~wardjax.effects._texture.joint_autocovariance`), and the
    covariance between neighbouring scanlines and channels goes into each
    candidate's evidence as a design effect (:class:`CrossTexture`).
    Returns ``None`` if no texture is found.
    """
    if getattr(data, "kind", None) not in ("ratio", "brdf") or data.y.shape[1] < 8:
        return None
    y, m = np.asarray(data.y), np.asarray(data.mask)
    exact = m if data.censored is None else m & ~np.asarray(data.censored)
    # measured off the highlight only (prediction within 15 % of the scanline's diffuse floor), so that a
    # lobe-shaped misfit of the baseline is not taken for texture
    floor = np.nanquantile(np.where(m, pred, np.nan), 0.1, axis=1, keepdims=True)
    off = exact & (pred <= 1.15 * floor)
    e = y - pred
    fit = estimate_texture(e, pred, exact, off=off)
    if not fit.significant().any():
        return None
    c_n = y.shape[-1]
    noise_off = np.array([np.mean(fit.sigma(pred)[..., c][off[..., c]] ** 2) for c in range(c_n)])
    noise = _calibrated_noise(fit, e, pred, off, noise_off)
    fit.acov, noise = joint_autocovariance(e, off, noise)
    n = y.shape[1]
    tex_var = np.array([fit.acov[c * n, c * n] for c in range(c_n)])
    # the noise's level dependence with the texture known, its level off the highlight the calibrated one
    s_lv = level_noise(e, pred, exact, fit.acov)
    f_off = np.array([np.mean(pred[..., c][off[..., c]]) for c in range(c_n)])
    shot = s_lv[:, 1] * f_off + s_lv[:, 2] * f_off**2
    s_lv[:, 0] = np.maximum(noise - shot, 0.0)
    # a white-noise floor keeps the whitening well conditioned where the texture term took all the variance
    s_lv[:, 0] += np.maximum(_NOISE_FLOOR * tex_var - np.maximum(noise, shot), 0.0)
    fit.s = s_lv * (fit.scale[:, None] ** np.arange(3)[None, :])  # TextureFit.sigma takes f / scale
    sigma = np.where(m, fit.sigma(pred), 1.0)
    W = texture_whitening(fit, sigma, exact)
    new = dataclasses.replace(data, sigma=sigma, whiten=W)
    mean_level = np.array([np.mean(pred[..., c][m[..., c]]) for c in range(c_n)])
    summary = {
        "amplitude": [float(v) for v in np.sqrt(tex_var) / np.maximum(mean_level, 1e-30)],
        "rho": [float(fit.acov[c * n, c * n + 1] / max(tex_var[c], 1e-300)) for c in range(c_n)],
    }
    return new, summary, CrossTexture(y, off, W, sigma, exact)


def _calibrated_noise(fit, e: np.ndarray, pred: np.ndarray, off: np.ndarray, noise_off: np.ndarray) -> np.ndarray:
    """The white noise off the highlight ``(C,)``: the estimate scaled by ``λ ∈ [λ_min, 1]`` so that the whitened
    residuals there have unit mean square (bisection on a subset of scanlines).

    The exponential's fit (:func:`~wardjax.effects._texture.estimate_texture`)
    reads the noise from short lags; where the residuals hold less power at
    high frequencies than white noise of that level — a blurred frame blurs
    its noise too — the whitened residuals came out at half their variance
    (gap 0.47 on a blurred noise-textured capture) and any effect was cheap.
    """
    import copy

    from ._texture import off_highlight_variance

    rows = np.linspace(0, e.shape[0] - 1, min(e.shape[0], _CALIBRATION_SCANLINES)).astype(int)
    sub = (e[rows], pred[rows], off[rows])
    lags = lag_covariances(sub[0], sub[2])  # measured once: only the noise changes with λ

    def msq(lam: float) -> float:
        f = copy.copy(fit)
        f.s = fit.s * lam
        f.acov, _ = joint_autocovariance(sub[0], sub[2], noise_off * lam, lags)
        return off_highlight_variance(f, *sub)

    lo, hi = _NOISE_FLOOR, 1.0
    if msq(hi) >= 1.0:
        return noise_off
    if msq(lo) <= 1.0:
        return noise_off * lo
    for _ in range(8):  # λ to within 0.4 % of its range
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if msq(mid) > 1.0 else (lo, mid)
    return noise_off * 0.5 * (lo + hi)


class CrossTexture(NamedTuple):
    """The texture covariance the per-scanline whitening leaves out, and what a design effect needs with it."""

    y: np.ndarray  # (S, N, C) the data
    off: np.ndarray  # (S, N, C) values off the highlight, where the texture is measured
    whiten: np.ndarray  # (S, C N, C N): the channels of a scanline whitened together
    sigma: np.ndarray  # (S, N, C)
    use: np.ndarray  # (S, N, C)

    def design_effect(self, r_cur: np.ndarray, r_new: np.ndarray, pred_new: np.ndarray) -> float:
        """The design effect of a candidate that moves the whitened residuals from ``r_cur`` to ``r_new``.

        The covariance between scanlines is measured on the residuals *with*
        the candidate (``y − pred_new``; the variance under the alternative,
        as a Wald test takes it): a missing effect is smooth and shared by all
        scanlines, and measured on the residuals without it, it would count
        as texture correlated over every lag and discount its own evidence.
        Where the candidate explains nothing, its residuals are the
        baseline's.
        """
        d = (r_cur - r_new).reshape(self.sigma.shape)
        cross = cross_covariance(self.y - pred_new, self.off)
        return design_effect(d, self.whiten, self.sigma, self.use, cross)
