"""What discovery on a photograph checks beside the evidence: a physical lobe, what one photo can tell, where the
residual lives.

* :func:`unphysical`: a fitted model whose lobe breaks the rules every
  entry point applies (:mod:`wardjax._rules`: ``median ρd + ρs ≤ 1`` per
  channel, energy conservation of the image-based paper's eq. 1) or whose
  ``α`` leaves the range a Ward lobe describes (``α > 1``, or at the search
  bound ``10⁻³``) stands in for an effect the model lacks. Discovery then
  tries the radial effects first rather than build on that lobe.
* :func:`not_identifiable`: with one photo each pixel is seen once; a normal
  per block moves the highlight inside the block, and a ρd varying inside the
  block makes the same picture. ``normals`` is then not tried, and the report
  says why.
* :func:`residual_where`: the final model's residual summarised — its share
  in the centre, middle and edge of the image (radius over the largest),
  the share its worst 5 % of blocks hold, and the share a ρd per pixel
  (instead of per block) would absorb: all of it with one photo (each pixel's
  one value fitted exactly), where texture finer than a block and any effect
  are not told apart.
"""

from __future__ import annotations

import numpy as np

from .._rules import RuleError, check_rho_sum
from ._photo_held import HeldStructure
from ._photo_model import PhotoData, gains, shared_residuals, shared_rho_d

__all__ = ["BANDS", "not_identifiable", "residual_where", "unphysical", "where_text"]

BANDS = (("centre", 0.0, 0.5), ("middle", 0.5, 0.8), ("edge", 0.8, np.inf))  # radius over the largest
_ALPHA_MAX = 1.0  # beyond this a "lobe" is a diffuse tilt, not a specular peak
_ALPHA_MIN = 1.01e-3  # the search's lower bound (with a margin): a spike, not a lobe
_WORST = 0.05


def _lobes(fit, state, data: PhotoData) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``ρd (P, C)``, ``ρs (L,)``, ``α (L,)`` of a fitted state."""
    if fit.pixel is None:
        rho_d = shared_rho_d(data, fit.shared, state.radial)
        return rho_d, np.array([fit.shared.rho_s]), np.array([fit.shared.alpha])
    res = fit.pixel
    return np.asarray(res.rho_d), np.asarray(res.rho_s), np.asarray(res.alpha_x)


def unphysical(fit, state, data: PhotoData) -> str | None:
    """Why the lobe of ``fit`` (a :class:`~wardjax.effects._photo_states.StateFit` of ``state``) is no
    material's; ``None`` when it is one."""
    rho_d, rho_s, alpha = _lobes(fit, state, data)
    why = []
    for i, (s, a) in enumerate(zip(rho_s, alpha)):
        name = "the lobe" if rho_s.size == 1 else f"lobe {i}"
        try:
            check_rho_sum(name, rho_d[:, None, :], float(s))
        except RuleError as e:
            why.append(f"{name}: {e.message.split(': ρs may')[0]}")
        if a > _ALPHA_MAX or a < _ALPHA_MIN:
            why.append(f"{name}: α = {a:.3g} outside ({_ALPHA_MIN:g}, {_ALPHA_MAX:g}]")
    return "; ".join(why) or None


def not_identifiable(data: PhotoData) -> dict[str, str]:
    """The candidates ``data`` cannot identify, each with the reason."""
    if data.n_photos == 1:
        why = "one photo: a normal per block and ρd varying inside the block make the same picture"
        return {"normals": why, "height_field": why}
    rows, cols, _ = data.grid
    if min(rows, cols) < 2:
        return {"height_field": f"a height field needs a grid of 2 × 2 problems or more, got {rows} × {cols}"}
    return {}


def _errors(fit, state, data: PhotoData) -> np.ndarray:
    """``(P, V, C)`` the weighted residuals ``√w (f − model)`` of a fitted state."""
    if fit.pixel is None:
        return shared_residuals(data, fit.shared, state.radial)
    held = HeldStructure.of(fit.pixel, data)
    a = np.nan_to_num(np.asarray(fit.pixel.rho_d)) / np.pi
    g = gains(data, fit.shared.effects)[..., None]
    model = g * (held.q[..., None] * a[:, None, :] + held.spec[..., None])
    return np.sqrt(data.w) * (data.f - model)


def residual_where(fit, state, data: PhotoData) -> dict:
    """Where the residual of ``fit`` (of ``state``) lives (module docstring); ``chi2_map`` ``(rows, cols)`` each
    block's χ² per observation."""
    r = _errors(fit, state, data)
    rows, cols, b = data.grid
    k = data.n_photos
    w = data.w
    chi_p = np.sum(r * r, (1, 2))
    total = max(float(chi_p.sum()), 1e-300)
    n_p = np.sum(w > 0, (1, 2))
    # a ρd per pixel: each pixel's weighted mean residual over its photos removed
    e = np.where(w > 0, r / np.sqrt(np.where(w > 0, w, 1.0)), 0.0).reshape(r.shape[0], b * b, k, -1)
    wk = w.reshape(e.shape)
    m = np.sum(wk * e, 2, keepdims=True) / np.maximum(np.sum(wk, 2, keepdims=True), 1e-300)
    left = float(np.sum(wk * (e - m) ** 2))
    radius = np.sqrt(np.clip(data.radius2, 0, None))
    bands = []
    for name, lo, hi in BANDS:
        sel = ((radius >= lo) & (radius < hi))[..., None] & (w > 0)
        bands.append(
            {
                "band": name,
                "chi2_share": float(np.sum(np.where(sel, r * r, 0.0)) / total),
                "obs_share": float(sel.sum() / max(int(np.sum(w > 0)), 1)),
            }
        )
    worst = np.sort(chi_p)[::-1][: max(1, int(round(_WORST * chi_p.size)))]
    return {
        "pixel_rho_d_share": 1.0 - left / total,
        "bands": bands,
        "worst_5pc_share": float(worst.sum() / total),
        "chi2_map": (chi_p / np.maximum(n_p, 1)).reshape(rows, cols),
    }


def where_text(where: dict, n_photos: int) -> str:
    """One sentence: where the residual lives."""
    band = max(where["bands"], key=lambda x: x["chi2_share"] / max(x["obs_share"], 1e-12))
    parts = [
        f"the {band['band']} of the image holds {100 * band['chi2_share']:.0f} % of χ² on "
        f"{100 * band['obs_share']:.0f} % of the observations",
        f"the worst 5 % of blocks hold {100 * where['worst_5pc_share']:.0f} %",
    ]
    if n_photos == 1:
        parts.append(
            "a ρd per pixel would absorb all of it (one photo: texture finer than a block and an effect "
            "are not told apart)"
        )
    else:
        parts.append(f"a ρd per pixel would absorb {100 * where['pixel_rho_d_share']:.0f} %")
    return "; ".join(parts)
