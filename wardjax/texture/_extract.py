"""Per-pixel diffuse texture: what is left of the measurement once the specular lobe is removed.

Image-based paper, section 4.1: ``ρd,texture = π (f_measured − ρs K / √(cos θi cos θo))``,
i.e. π times the measured BRDF minus the fitted specular term (in whichever
normalisation the fit used).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from .._rules import RuleError
from ..ward import (
    NORMALIZATIONS,
    WardParams,
    _broadcast_leading,
    _rho_s_rgb,
    ward_geometry,
    ward_specular,
)
from ._jit import texture_jit

__all__ = ["RHO_D_RANGE", "extract_rho_d"]

# Physical range of a diffuse reflectance. Values a little outside [0, 1] are
# measurement noise and are clamped; values far outside (below −0.05 or above
# 1.05 before clamping) mean the specular model or the reference failed there
# and become NaN.
RHO_D_RANGE = (0.0, 1.0)
_REJECT_MARGIN = 0.05


@texture_jit(static_argnames="normalization")
def _extract(f_r, wi, wo, params, normalization):
    geom = ward_geometry(wi, wo, normalization)
    spec = ward_specular(geom, params.alpha_x, params.alpha_y)[..., None]
    rho_s, spec, f_r, valid = _broadcast_leading(
        (_rho_s_rgb(params), 1), (spec, 1), (f_r, 1), (geom.valid[..., None], 1)
    )
    rho = jnp.pi * (f_r - rho_s * spec)
    lo, hi = RHO_D_RANGE
    ok = valid & jnp.isfinite(rho) & (rho >= lo - _REJECT_MARGIN) & (rho <= hi + _REJECT_MARGIN)
    return jnp.where(ok, jnp.clip(rho, lo, hi), jnp.nan)


def _check_lobe(params: WardParams) -> None:
    """Refuse a lobe the specular term cannot be evaluated with: ρs finite and ≥ 0, αx, αy finite and > 0.

    ``params`` may come from :meth:`~wardjax.WardParams.from_estimate` (a failed fit is NaN), so the
    rule is applied here again rather than trusted from construction.
    """
    for name in ("rho_s", "alpha_x", "alpha_y"):
        a = np.asarray(getattr(params, name), np.float64)
        if not np.all(np.isfinite(a)):
            raise RuleError(name, f"must be finite to remove the specular lobe, got {a.reshape(-1)[:3].tolist()}")
        if np.any(a <= 0 if name != "rho_s" else a < 0):
            raise RuleError(name, f"must be {'≥ 0' if name == 'rho_s' else '> 0'}, got {a.reshape(-1)[:3].tolist()}")


def extract_rho_d(f_r, wi, wo, params: WardParams, *, normalization: str = "ward1992") -> np.ndarray:
    """Per-pixel diffuse reflectance ``ρd = π (f_r − specular)``, eq. "ρd,texture".

    Parameters
    ----------
    f_r
        ``(..., 3)`` measured BRDF values (e.g. ``(H, W, 3)`` for an image).
    wi, wo
        ``(..., 3)`` directions to lamp and camera for each value.
    params
        The fitted material (unbatched, or broadcastable against ``f_r[..., 0]``).
        Only ρs, αx, αy are used: the texture *is* the per-pixel ρd.
    normalization
        The normalisation the parameters were fitted in.

    Returns
    -------
    ndarray ``(..., 3)`` float64
        ρd clamped to ``[0, 1]``; NaN where a direction is below the horizon,
        the input is not finite, or the value lies more than 0.05 outside
        ``[0, 1]`` (the model or the reference does not hold there).
    """
    if normalization not in NORMALIZATIONS:
        raise ValueError(f"normalization={normalization!r} is not one of {NORMALIZATIONS}")
    f_r = np.asarray(f_r, dtype=np.float64)
    if f_r.shape[-1:] != (3,):
        raise ValueError(f"f_r must end in an RGB axis of 3, got shape {f_r.shape}")
    for name, d in (("wi", wi), ("wo", wo)):
        if np.shape(d) != f_r.shape:
            raise ValueError(f"{name} has shape {np.shape(d)}, expected {f_r.shape} like f_r")
    _check_lobe(params)
    with jax.enable_x64(True):
        p = jax.tree_util.tree_map(lambda x: jnp.asarray(x, jnp.float64), params)
        out = _extract(jnp.asarray(f_r), jnp.asarray(wi, jnp.float64), jnp.asarray(wo, jnp.float64), p, normalization)
        return np.asarray(out)
