"""The dark frame's word on the texture: a texture the lit frame shows must be in the dark frame too.

Why
    The texture term (:mod:`wardjax.effects._texture_term`) reads the probe's ρd
    texture off the baseline's residuals. Any smooth misfit there has the same
    look: on an untextured satin that a second, weak lamp lights (the Radiance
    bench's ``second_lamp``), the residuals of the second highlight read as a
    texture of 3–4 % with a correlation of 0.9 between neighbouring samples,
    and the covariance built from them takes the gap from 9.7 (white noise) to
    1.04 — the effect the discovery should see is in the noise model.

    ρd multiplies whatever light reaches the probe: the room's light in the
    dark frame as much as the lamp's. A texture present in the lit frame is in
    the dark frame with the same *relative* amplitude; the lamp's misfit is not
    there at all. So the lit frame's residual and the dark frame's relative
    fluctuation must covary by the texture's relative variance.

The check
    With ``y = (L_p − D_p)/span`` (``span = (L_s − D_s)/s``, the standard's
    levels, :mod:`~wardjax.effects._pixel_levels`), the lit frame's own residual
    ``a = (y − f̂ + (D_p − R)/span) / f̂`` (``f̂`` the baseline, ``R`` the room's
    light, the dark frame smoothed over 10 px) holds no dark-frame noise, and
    ``b = (D_p − R)/R`` is the dark frame's relative fluctuation. Off the
    highlight, per channel, their covariance is averaged over the scanlines
    (each scanline's covariance about its own means), its SE from the spread
    between scanlines (the noise of the two frames is independent; a scanline's
    values are not). The claim is the texture term's relative variance
    ``v = Var(t)/f̄²``; a real texture gives about ``v`` less what the room's
    smoothing removes. The texture is *refuted* where the covariance over
    ``v``, pooled over the channels by inverse variance, lies 3 SE below
    :data:`_SHOWN` — a quarter of the claim would have been seen. Elsewhere (a
    dark frame too dark or too noisy to show it, none at all) nothing changes.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["dark_refutes"]

_SHOWN = 0.25  # a texture is refuted where the dark frame shows less than this share of it, by 3 SE
_MIN_VALUES = 8  # a scanline's channel enters with at least this many values off the highlight
_MIN_SCANLINES = 8  # and the check with at least this many such scanlines


def dark_refutes(data, resid: np.ndarray, off: np.ndarray, pred: np.ndarray, claim: np.ndarray) -> dict | None:
    """Whether the dark frame refutes the texture the lit frame's residuals claim: ``{"shown", "se", "refuted"}``,
    or ``None`` where it cannot tell (no dark frame, no room light, too few values).

    ``resid`` ``(S, N, C)``: ``y − f̂`` of the baseline; ``off`` ``(S, N, C)``: the values off the highlight
    where the texture was measured; ``pred`` ``(S, N, C)``: ``f̂``; ``claim`` ``(C,)``: the texture's relative
    variance. ``shown`` is the share of the claim the dark frame shows, pooled over the channels, ``se`` its SE.
    """
    dark, px = getattr(data, "dark", None), getattr(data, "pixels", None)
    if dark is None or px is None:
        return None
    d, room = (np.asarray(x, np.float64) for x in dark)
    span = (np.asarray(px["lit_std"]) - np.asarray(px["dark_std"])) / np.asarray(px["ref"])
    with np.errstate(divide="ignore", invalid="ignore"):
        a = (resid + (d - room) / span) / pred
        b = (d - room) / room
    use = off & np.isfinite(a) & np.isfinite(b) & (room > 0) & (span > 0) & (pred > 0)
    shares, ses = [], []
    for c in range(resid.shape[-1]):
        covs, counts = [], []
        for s in range(resid.shape[0]):
            u = use[s, :, c]
            if u.sum() < _MIN_VALUES:
                continue
            x, y = a[s, u, c], b[s, u, c]
            covs.append(float(np.mean((x - x.mean()) * (y - y.mean()))))
            counts.append(int(u.sum()))
        if len(covs) < _MIN_SCANLINES or not claim[c] > 0:
            continue
        w = np.asarray(counts, float) / np.sum(counts)
        cv = np.asarray(covs)
        mean = float(np.sum(w * cv))
        se = float(math.sqrt(np.sum(w**2 * (cv - mean) ** 2) * len(cv) / (len(cv) - 1)))
        if se > 0:
            shares.append(mean / claim[c])
            ses.append(se / claim[c])
    if not shares:
        return None
    wt = 1.0 / np.square(ses)
    shown = float(np.sum(wt * np.asarray(shares)) / np.sum(wt))
    se = float(1.0 / math.sqrt(np.sum(wt)))
    return {"shown": shown, "se": se, "refuted": bool(shown + 3.0 * se < _SHOWN)}
