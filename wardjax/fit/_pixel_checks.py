"""The boundary of :func:`~wardjax.fit_pixels`: shapes, directions, weights and normals checked, one
``ValueError`` naming the argument for each mismatch; invalid views are given zero weight."""

from __future__ import annotations

import numpy as np

__all__ = ["check_normals", "validate"]


def validate(f_r, wi, wo, weights, mask, tangent):
    f = np.asarray(f_r, np.float64)
    if f.ndim != 3:
        raise ValueError(f"f_r must have shape (P, K, C), got {f.shape}")
    p, k, c = f.shape
    if p < 1 or k < 1 or c < 1:
        raise ValueError(f"f_r must have at least one pixel, view and channel, got shape {f.shape}")
    wi = np.asarray(wi, np.float64)
    wo = np.asarray(wo, np.float64)
    for name, d in (("wi", wi), ("wo", wo)):
        if d.shape != (p, k, 3):
            raise ValueError(f"{name} has shape {d.shape}, expected {(p, k, 3)} (f_r is {f.shape})")
        norm = np.linalg.norm(d, axis=-1)
        if not np.all(np.isfinite(d)) or np.any(np.abs(norm - 1.0) > 1e-6):
            raise ValueError(f"{name} must hold finite unit vectors")
    w = np.ones_like(f) if weights is None else np.asarray(weights, np.float64)
    if w.shape == (p, k):
        w = np.broadcast_to(w[..., None], f.shape)
    if w.shape != f.shape:
        raise ValueError(f"weights has shape {w.shape}, expected {f.shape} or {(p, k)}")
    if np.any(w < 0) or not np.all(np.isfinite(w)):
        raise ValueError("weights must be finite and non-negative (1/σ²)")
    ok = np.isfinite(f) & (wi[..., 2:] > 1e-12) & (wo[..., 2:] > 1e-12)
    if mask is not None:
        m = np.asarray(mask)
        if m.shape != (p, k) or m.dtype != bool:
            raise ValueError(f"mask must be a boolean array of shape {(p, k)}, got {m.dtype} {m.shape}")
        ok &= m[..., None]
    w = np.where(ok, w, 0.0)
    f = np.where(ok, f, 0.0)
    t = np.array([1.0, 0.0, 0.0]) if tangent is None else np.asarray(tangent, np.float64)
    if t.shape != (3,) or not np.all(np.isfinite(t)) or np.hypot(t[0], t[1]) < 1e-6:
        raise ValueError(f"tangent must be a (3,) vector with a component in the sample plane, got {t}")
    t = np.array([t[0], t[1], 0.0]) / np.hypot(t[0], t[1])
    return f, wi, wo, w, t


def check_normals(fixed_normals, p, normals, lobe) -> np.ndarray:
    if normals or lobe == "pixel":
        raise ValueError("fixed_normals needs normals=False and lobe='shared' or 'clusters'")
    n = np.asarray(fixed_normals, np.float64)
    if n.shape != (p, 3) or not np.all(np.isfinite(n)) or np.any(n[:, 2] <= 0):
        raise ValueError(f"fixed_normals must be ({p}, 3) finite normals with z > 0, got shape {n.shape}")
    return n / np.linalg.norm(n, axis=-1, keepdims=True)
