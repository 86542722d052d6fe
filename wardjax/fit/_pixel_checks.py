"""The boundary of :func:`~wardjax.fit_pixels`: shapes, directions, weights and normals checked, one
``ValueError`` naming the argument for each mismatch; invalid views are given zero weight.

Shapes are checked on the host (they cost nothing); the values — finite unit directions, finite
non-negative weights — in one compiled pass over the arrays that also masks the unusable views and
computes the flat sample's geometry (:func:`._pixel_model.geometry`): the pass returns
flags, and the error is raised here, outside the compiled code. The arrays go to JAX as they are
(no host copy or cast: float32 photos are read as float64 inside the pass).
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np

from . import _pixel_model as pm

__all__ = ["check_normals", "validate"]

_UNIT_TOL = 1e-6  # |‖ω‖ − 1| allowed of a direction
_HORIZON = 1e-12  # a view whose direction's z is below this is unusable


def _array(x):
    """``x`` as an array without a copy where it is one already (NumPy or JAX)."""
    return x if isinstance(x, (np.ndarray, jax.Array)) else np.asarray(x)


def _check_shapes(f, wi, wo, w, mask):
    if f.ndim != 3:
        raise ValueError(f"f_r must have shape (P, K, C), got {f.shape}")
    p, k, c = f.shape
    if p < 1 or k < 1 or c < 1:
        raise ValueError(f"f_r must have at least one pixel, view and channel, got shape {f.shape}")
    for name, d in (("wi", wi), ("wo", wo)):
        if d.shape != (p, k, 3):
            raise ValueError(f"{name} has shape {d.shape}, expected {(p, k, 3)} (f_r is {f.shape})")
    if w is not None and w.shape not in ((p, k), f.shape):
        raise ValueError(f"weights has shape {w.shape}, expected {f.shape} or {(p, k)}")
    if mask is not None and (mask.shape != (p, k) or mask.dtype != bool):
        raise ValueError(f"mask must be a boolean array of shape {(p, k)}, got {mask.dtype} {mask.shape}")
    for name, d in (("f_r", f), ("wi", wi), ("wo", wo), ("weights", w)):
        if d is not None and not (jnp.issubdtype(d.dtype, jnp.floating) or jnp.issubdtype(d.dtype, jnp.integer)):
            raise ValueError(f"{name} must hold real numbers, got dtype {d.dtype}")


@functools.partial(jax.jit, static_argnames="normalization")
def _prepare(f, wi, wo, w, mask, t, *, normalization: str):
    """One pass: the value checks' flags, the masked ``f`` and ``w`` ``(P, K, C)``, the geometry and ``n``.

    Flags: ``wi`` / ``wo`` not finite unit vectors, ``weights`` not finite and non-negative.
    """
    f, wi, wo = (x.astype(jnp.float64) for x in (f, wi, wo))
    w = jnp.ones_like(f) if w is None else w.astype(jnp.float64)
    if w.ndim == 2:
        w = jnp.broadcast_to(w[..., None], f.shape)

    def not_unit(d):
        return ~jnp.all(jnp.isfinite(d)) | jnp.any(jnp.abs(jnp.linalg.norm(d, axis=-1) - 1.0) > _UNIT_TOL)

    flags = jnp.stack([not_unit(wi), not_unit(wo), jnp.any(w < 0) | ~jnp.all(jnp.isfinite(w))])
    ok = jnp.isfinite(f) & (wi[..., 2:] > _HORIZON) & (wo[..., 2:] > _HORIZON)
    if mask is not None:
        ok &= mask[..., None]
    w = jnp.where(ok, w, 0.0)
    f = jnp.where(ok, f, 0.0)
    geom = pm.flat_geometry(wi, wo, t, normalization)
    return flags, f, wi, wo, w, geom, jnp.sum(w > 0)


def validate(f_r, wi, wo, weights, mask, tangent, normalization="ward1992"):
    """Check the inputs of :func:`~wardjax.fit_pixels`; call with float64 enabled.

    Returns ``f, wi, wo, w, t`` (JAX float64; ``f`` and ``w`` zero where a view is unusable), the
    flat sample's :class:`._pixel_model.PixelGeometry` and the number of usable observations.
    """
    f, wi, wo = _array(f_r), _array(wi), _array(wo)
    w = None if weights is None else _array(weights)
    m = None if mask is None else _array(mask)
    _check_shapes(f, wi, wo, w, m)
    t = np.array([1.0, 0.0, 0.0]) if tangent is None else np.asarray(tangent, np.float64)
    if t.shape != (3,) or not np.all(np.isfinite(t)) or np.hypot(t[0], t[1]) < 1e-6:
        raise ValueError(f"tangent must be a (3,) vector with a component in the sample plane, got {t}")
    t = np.array([t[0], t[1], 0.0]) / np.hypot(t[0], t[1])
    flags, f, wi, wo, w, geom, n_obs = _prepare(
        *(None if x is None else jax.device_put(x) for x in (f, wi, wo, w, m)),
        jnp.asarray(t),
        normalization=normalization,
    )
    bad_i, bad_o, bad_w = (bool(x) for x in np.asarray(flags))
    for name, bad in (("wi", bad_i), ("wo", bad_o)):
        if bad:
            raise ValueError(f"{name} must hold finite unit vectors")
    if bad_w:
        raise ValueError("weights must be finite and non-negative (1/σ²)")
    return f, wi, wo, w, jnp.asarray(t), geom, int(n_obs)


def check_normals(fixed_normals, p, normals, lobe) -> np.ndarray:
    if normals or lobe == "pixel":
        raise ValueError("fixed_normals needs normals=False and lobe='shared' or 'clusters'")
    n = np.asarray(fixed_normals, np.float64)
    if n.shape != (p, 3) or not np.all(np.isfinite(n)) or np.any(n[:, 2] <= 0):
        raise ValueError(f"fixed_normals must be ({p}, 3) finite normals with z > 0, got shape {n.shape}")
    return n / np.linalg.norm(n, axis=-1, keepdims=True)
