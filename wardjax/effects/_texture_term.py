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

from ._dark_texture import dark_refutes
from ._levels import level_whitening, relative_levels
from ._noise import noise_columns
from ._texture import (
    cross_covariance,
    design_effect,
    estimate_texture,
    joint_autocovariance,
    lag_covariances,
    level_noise,
    texture_whitening,
)

__all__ = [
    "CrossTexture",
    "TextureReading",
    "identity_whitened",
    "is_identity_whitening",
    "white_noise_share",
    "with_texture",
]

_NOISE_FLOOR = 0.02  # white noise off the highlight at least this fraction of the texture variance
# the variogram's Hann window, a fraction of half a scanline (0.35–0.7 read clean captures alike)
_VARIOGRAM_WINDOW = 0.5


class TextureReading(NamedTuple):
    """What :func:`with_texture` read: the data whitened by the texture (``None`` where the dark frame refused it),
    a summary for the report, and the texture between scanlines (``None`` where refused)."""

    data: object | None
    summary: dict
    cross: CrossTexture | None

    @property
    def refused(self) -> bool:
        """Whether the dark frame refuted the texture the residuals claimed (the run stays with white noise)."""
        return self.data is None


def with_texture(
    data, pred: np.ndarray, rho: np.ndarray | None = None, variogram: bool = False
) -> TextureReading | None:
    """``data`` with the texture carried as a Gaussian process, a summary, and the texture the process leaves out.

    Returns a :class:`TextureReading` ``(data, summary, cross)``. The white noise is re-estimated with the
    texture from the baseline's residuals (the lag-1 estimate counted texture as noise): its level off the
    highlight from the channels' cross-covariance (:func:`white_noise_share`), its shape in the level and the
    lamp's inverse irradiance from lag-1 differences (:func:`~wardjax.effects._texture.level_noise`); the
    process's autocovariance along the scanline is the measured one
    (:func:`~wardjax.effects._texture.joint_autocovariance`), and the
    covariance between neighbouring scanlines and channels goes into each
    candidate's evidence as a design effect (:class:`CrossTexture`).
    With the baseline's profiled ρd ``rho`` ``(S, 1, C)``, the texture between
    scanlines in their diffuse levels is carried too (:mod:`~wardjax.effects._levels`).
    ``variogram``: the covariance along the scanline from the cross-variogram
    (:func:`~wardjax.effects._texture.lag_covariances`), windowed over a quarter
    scanline: the guard's second opinion (:mod:`~wardjax.effects._recheck`).
    Returns ``None`` if no texture is found, and a reading that is ``refused`` (no data, no cross term) where the
    dark frame refutes the texture the residuals claim (``summary["refused"]``, with the claimed ``amplitude`` and
    the share of it the dark frame shows, ``dark_shown`` ``[share, SE]``): the run then stays with white noise.
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
    w = _inv_irradiance(data, m)
    fit = estimate_texture(e, pred, exact, off=off, w=w)
    if not fit.significant().any():
        return None
    n, c_n = y.shape[1], y.shape[-1]
    lags = lag_covariances(e, off, variogram)
    nu = white_noise_share(lags)
    fit.acov, nu = joint_autocovariance(e, off, nu, lags, _VARIOGRAM_WINDOW if variogram else 1.0)
    tex_var = np.array([fit.acov[c * n, c * n] for c in range(c_n)])
    mean_level = np.array([np.mean(pred[..., c][m[..., c]]) for c in range(c_n)])
    # the dark frame holds the probe's texture under the room's light, and none of the lamp's misfit
    dark = dark_refutes(data, e, off, pred, tex_var / np.maximum(mean_level, 1e-30) ** 2)
    amplitude = [float(v) for v in np.sqrt(tex_var) / np.maximum(mean_level, 1e-30)]
    if dark is not None and dark["refuted"]:
        refused = {"refused": "dark frame", "amplitude": amplitude, "dark_shown": [dark["shown"], dark["se"]]}
        return TextureReading(None, refused, None)
    # a white-noise floor keeps the whitening well conditioned where the texture term took all the variance
    nu = np.maximum(nu, _NOISE_FLOOR * tex_var)
    # its shape in level and irradiance from lag-1 differences over all values (the highlight's shot noise), the
    # texture's share known; its mean off the highlight ν
    fit.s = _unit_shape(level_noise(e, pred, exact, fit.acov, w), pred, w, off) * nu[:, None]
    fit.s = fit.s * (fit.scale[:, None] ** np.arange(3))  # TextureFit.sigma takes f / scale
    sigma = np.where(m, fit.sigma(pred, w), 1.0)
    W = texture_whitening(fit, sigma, exact)
    new = dataclasses.replace(data, sigma=sigma, whiten=W)
    summary: dict = {
        "amplitude": amplitude,
        "rho": [float(fit.acov[c * n, c * n + 1] / max(tex_var[c], 1e-300)) for c in range(c_n)],
    }
    if dark is not None:
        summary["dark_shown"] = [dark["shown"], dark["se"]]
    lv = _levels(data, rho, m)
    if lv is None:  # no term, in the layout that has one (one compiled program for every fit of the run)
        return TextureReading(
            dataclasses.replace(new, levels=_no_levels(data)), summary, CrossTexture(y, off, W, sigma, exact)
        )
    P = np.zeros((y.shape[0], y.shape[0]))
    P[: lv[0].shape[0]] = lv[0]
    summary["levels"] = lv[2]
    cross = CrossTexture(y, off, W, sigma, exact, lv[2]["deff"])
    return TextureReading(dataclasses.replace(new, levels=(P, lv[1])), summary, cross)


def _no_levels(data) -> tuple[np.ndarray, np.ndarray]:
    """The scanline levels' term with nothing in it: ``P = 0`` ``(S, S)``, ``a = 0`` ``(C,)``."""
    s_n, _, c_n = np.shape(data.y)
    return np.zeros((s_n, s_n)), np.zeros(c_n)


def _levels(data, rho: np.ndarray | None, m: np.ndarray):
    """``(P, a, summary)`` of :func:`~wardjax.effects._levels.level_whitening` for the baseline's ρd, the trend
    the scanline's mean field coordinate ``s̄`` (``None`` without ρd or the coordinate)."""
    s = data.cov.get("illum_s")
    if rho is None or s is None:
        return None
    seen = np.asarray(np.any(m, axis=-1), bool)  # (S, N)
    ell, a, ok = relative_levels(rho, np.any(seen, axis=1))
    s_bar = np.array([np.mean(np.asarray(s)[j][seen[j]]) if seen[j].any() else 0.0 for j in range(len(ell))])
    out = level_whitening(ell, ok, s_bar)
    return None if out is None else (out[0], a, out[1])


def identity_whitened(data):
    """``data`` whitened by the identity (``L⁻¹ = I`` per scanline, the channels together): white noise, the same
    numbers, in the layout :func:`with_texture` gives (so that one compiled program fits both)."""
    if getattr(data, "whiten", None) is not None:
        return data
    s_n, n, c_n = np.shape(data.y)
    eye = np.broadcast_to(np.eye(c_n * n), (s_n, c_n * n, c_n * n))
    return dataclasses.replace(data, whiten=eye, levels=_no_levels(data))


def is_identity_whitening(W: np.ndarray) -> bool:
    """Whether ``W`` is :func:`identity_whitened`'s (white noise in the texture's layout), not a texture's."""
    return W.ndim == 3 and bool(np.array_equal(W, np.broadcast_to(np.eye(W.shape[-1]), W.shape)))


def _inv_irradiance(data, m: np.ndarray) -> np.ndarray:
    """The lamp's inverse irradiance ``(S, N, 1)`` (:func:`~wardjax.effects.scanline_data` scales it to mean 1 where
    observed), 1 where the data carry no lamp."""
    w = data.cov.get("inv_irradiance")
    return np.ones(m.shape[:2] + (1,)) if w is None else np.asarray(w, float)[..., None]


def _unit_shape(s_lv: np.ndarray, pred: np.ndarray, w: np.ndarray, off: np.ndarray) -> np.ndarray:
    """Noise coefficients ``(C, 3)`` (units of ``pred``) scaled so that ``σ²`` averages 1 off the highlight."""
    out = np.array(s_lv, float)
    for c in range(out.shape[0]):
        v = noise_columns(pred[..., c][off[..., c]], w[..., 0][off[..., c]]) @ out[c]
        mv = float(np.mean(v)) if v.size else 0.0
        out[c] = out[c] / mv if mv > 0 else np.array([1.0, 0.0, 0.0])  # no shape read: read noise alone
    return out


def white_noise_share(lags: np.ndarray) -> np.ndarray:
    """The white noise in the residuals' lag-0 variance, per channel ``(C,)``, from :func:`lag_covariances`.

    Noise is independent between channels, the texture is not: the
    cross-covariance of two channels has no nugget at lag 0, so its decay
    from lag 0 to lag 1, ``ρ₁ = X_{cc'}(±1)/X_{cc'}(0)``, is the texture's
    own. The texture's variance in channel ``c`` is then ``X_{cc}(1)/ρ₁``
    (averaged over the other channels) and the noise what is left of
    ``X_{cc}(0)``, clipped to ``[0, X_{cc}(0) − X_{cc}(1)]``. This needs the
    channels' textures to share their spatial scale, not their amplitude (a
    hue that varies with the pattern is fine). One channel: the lag-0 value
    less the straight line through lags 1 and 2.

    On simulated captures it reads the sensor's noise within about 10 %
    (``tests/test_texture_covariance.py``). The lag regression of
    :func:`~wardjax.effects._texture.estimate_texture` cannot (its
    exponential takes the whole drop from lag 0 to 1), and neither can a
    calibration of the whitened residuals' mean square off the highlight (a
    lag-0 share moves the whitened sum only through the positive
    semi-definite clip): the noise would then sit in the stationary texture
    term, while it grows along a scanline with the lamp's distance.
    """
    c_n, half = lags.shape[0], (lags.shape[2] - 1) // 2
    out = np.zeros(c_n)
    for c in range(c_n):
        a0, a1, a2 = lags[c, c, half], lags[c, c, half + 1], lags[c, c, half + 2]
        rhos = [
            0.5 * (lags[c, c2, half + 1] + lags[c, c2, half - 1]) / lags[c, c2, half]
            for c2 in range(c_n)
            if c2 != c and lags[c, c2, half] > 0
        ]
        rhos = [r for r in rhos if 0.0 < r <= 1.0]
        tex0 = a1 / float(np.mean(rhos)) if rhos else 2.0 * a1 - a2
        out[c] = min(max(a0 - tex0, 0.0), max(a0 - a1, 0.0))
    return out


class CrossTexture(NamedTuple):
    """The texture covariance the per-scanline whitening leaves out, and what a design effect needs with it."""

    y: np.ndarray  # (S, N, C) the data
    off: np.ndarray  # (S, N, C) values off the highlight, where the texture is measured
    whiten: np.ndarray  # (S, C N, C N): the channels of a scanline whitened together
    sigma: np.ndarray  # (S, N, C)
    use: np.ndarray  # (S, N, C)
    level_deff: float = 1.0  # the scanline levels' own inflation (wardjax.effects._levels)

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

    def deflate(self, dchi2: float, r_cur, chi2_cur: float, r_new, chi2_new: float, pred_new) -> tuple[float, float]:
        """A candidate's Δχ² with its share in the values divided by :meth:`design_effect`, and that effect.

        ``r_*`` are the values' whitened residuals, ``chi2_*`` the whole χ²:
        what they differ by is the scanline levels' share
        (:mod:`~wardjax.effects._levels`), which has its own covariance
        between scanlines and is divided by its own inflation,
        ``level_deff``, instead. A share that got worse is not shrunk.
        """
        r_cur, r_new = np.asarray(r_cur), np.asarray(r_new)
        deff = self.design_effect(r_cur, r_new, np.asarray(pred_new))
        d_lv = (chi2_cur - float(np.sum(r_cur**2))) - (chi2_new - float(np.sum(r_new**2)))
        d_px = dchi2 - d_lv
        d_lv = d_lv / self.level_deff if d_lv > 0 else d_lv
        return max((d_px / deff if d_px > 0 else d_px) + d_lv, 0.0), deff
