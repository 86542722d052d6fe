"""Texture-field errors: how the ρd texture aliases into the joint fit's ρs and α.

The joint fit's own covariance treats the residuals as independent noise.
On a textured probe they are not: the texture is a correlated field, and its
projection on the lobe's derivatives moves ρs and α in a way no residual-based
error sees. :func:`texture_field_covariance` estimates that covariance from
the texture's measured autocovariance.
"""

from __future__ import annotations

import dataclasses
import functools
import warnings
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from .. import _shapes
from ..ward import WardParams, ward_geometry, ward_specular
from ._joint import CombinedFit

__all__ = [
    "TextureErrors",
    "lobe",
    "placement_covariance",
    "plane_covariance",
    "sample_raster",
    "texture_field_covariance",
    "with_texture_errors",
]


def _fft_shape(n: int) -> int:
    """A length ≥ ``n`` that FFTs fast (2^a 3^b 5^c)."""
    from scipy.fft import next_fast_len

    # scipy's Python stub of next_fast_len has an empty body (so pyright infers None); the C function returns int.
    return next_fast_len(int(n), real=True)  # pyright: ignore[reportReturnType]


class TextureErrors(NamedTuple):
    """What :func:`texture_field_covariance` returns.

    Attributes
    ----------
    covariance
        ``(P, P)`` covariance of ``(ρs, α)`` or ``(ρs, αx, αy)`` (natural units).
    information
        ``A = JᵀJ`` of the profiled joint problem (equals the fit's, a cross-check).
    rho_d_grad
        ``(3, P)`` ``∂ρ̄d/∂θ`` of the mean ρd over scanlines (ρd is profiled, so it follows θ).
    texture_rms
        RMS of ``π r``: the ρd texture (and noise) left in the residual.
    """

    covariance: np.ndarray
    information: np.ndarray
    rho_d_grad: np.ndarray
    texture_rms: float


@functools.partial(jax.jit, static_argnames="normalization")
def _lobe_and_grad(wi, wo, a, normalization):
    """The specular basis ``b(α)`` per unit ρs ``(S, N)``, ``∂b/∂α`` ``(k, S, N)`` and the valid mask.

    ``a`` is ``(αx, αy)`` or ``(α,)`` (isotropic: both axes move together).
    """
    geom = ward_geometry(wi, wo, normalization)

    def lobe(a):
        return ward_specular(geom, a[0], a[-1])

    return lobe(a), jnp.moveaxis(jax.jacfwd(lobe)(a), -1, 0), geom.valid


def lobe(wi, wo, a, normalization):
    """:func:`_lobe_and_grad` (float64 NumPy) on ``(S, N, 3)`` directions padded to bucketed ``S`` and ``N``.

    Elementwise, so the padding (sliced off) changes nothing; it lets captures
    of one rig share the compiled program.
    """
    s, n = wi.shape[:2]
    shape = (_shapes.bucket(s), _shapes.bucket(n))
    with jax.enable_x64(True):
        b, db, valid = _lobe_and_grad(
            *(jnp.asarray(_shapes.pad_to_shape(d, shape), jnp.float64) for d in (wi, wo)),
            jnp.asarray(a, jnp.float64),
            normalization,
        )
    return np.asarray(b)[:s, :n], np.asarray(db)[:, :s, :n], np.asarray(valid)[:s, :n]


def sample_raster(points, ok) -> tuple[np.ndarray, np.ndarray, tuple[int, int]]:
    """Cells of a regular grid on the sample plane for the ``(S, N)`` samples: ``(ix, iy, shape)``.

    ``points`` ``(S, N, 2)`` are the samples' positions (mm); the cell is the
    median spacing between neighbouring scanlines in x and between
    neighbouring samples along them in y, so each sample gets about one
    cell. The texture is stationary in these coordinates; the image grid is
    not (perspective slants each image column across the sample plane).
    """
    x, y = (np.where(ok, points[..., k], np.nan) for k in (0, 1))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN scanlines or rows
        steps = [np.nanmedian(np.abs(np.diff(np.nanmedian(a, axis=ax)))) for a, ax in ((x, 1), (y, 0))]
    steps = [float(d) if np.isfinite(d) and d > 0 else 1.0 for d in steps]
    idx = []
    for a, d in zip((x, y), steps, strict=True):
        lo = float(np.nanmin(a))
        idx.append(np.rint((np.where(ok, a, lo) - lo) / d).astype(np.intp))
    shape = (int(idx[0][ok].max()) + 1, int(idx[1][ok].max()) + 1)
    return idx[0], idx[1], shape


def placement_covariance(r, occupied, g, min_overlap: float = 0.5) -> np.ndarray:
    r"""Covariance of ``θ = Σ_u g(u)·x(u)`` for a stationary field ``x``, from one sample ``r`` of it.

    Every shift ``Δ`` of the response ``g`` over the sample is a placement:
    ``h(Δ) = Σ_u r(u)·g(u + Δ)`` is what θ would have been with the field
    shifted by ``Δ``. For a stationary field each full placement is an
    unbiased draw of θ's covariance, ``E h hᵀ = gᵀ C g``; a placement that
    overlaps the sample in part sees only that part, and is scaled up by the
    fraction ``o_p(Δ)`` of ``g_p``'s energy it covers (exact for an
    uncorrelated field, and for full overlap):

    .. math::

        \widehat{\mathrm{Cov}}(θ_p, θ_q) = \frac{1}{|D|} \sum_{Δ ∈ D}
            \frac{h_p(Δ)}{\sqrt{o_p(Δ)}} \frac{h_q(Δ)}{\sqrt{o_q(Δ)}},
        \qquad D = \{Δ ≠ 0 : o_p(Δ) ≥ o_{min}\ ∀p\}.

    A mean of outer products, so positive semi-definite by construction
    (the unbiased autocovariance ``Σ r r / n(Δ)`` is not); it holds no
    taper, where the biased autocovariance ``Σ r r / n`` shrinks lag ``Δ`` by
    the overlap and misreads a response that changes sign. ``Δ = 0`` is left
    out: in a fit's residual the placement at hand has been absorbed
    (``h(0) = 0``). Sums over ``D`` by FFT on a zero-padded grid.

    Parameters
    ----------
    r
        ``(G1, G2, C)`` the field's sample on a regular grid, 0 where unobserved.
    occupied
        ``(G1, G2)`` bool: where it is observed.
    g
        ``(G1, G2, P, C)`` the response of each of ``P`` statistics (summed over channels ``C``).
    min_overlap
        Least fraction ``o_min`` of each response's energy a placement must cover.

    Returns
    -------
    ``(P, P)`` covariance (zeros when no placement qualifies).
    """
    from scipy.fft import irfft2, rfft2

    r, g = np.asarray(r, np.float64), np.asarray(g, np.float64)
    shape = (_fft_shape(2 * r.shape[0]), _fft_shape(2 * r.shape[1]))
    fft = lambda a: np.asarray(rfft2(a, s=shape, axes=(0, 1)))
    ifft = lambda a: np.asarray(irfft2(a, s=shape, axes=(0, 1)))
    h = ifft(np.einsum("abc,abpc->abp", np.conj(fft(r)), fft(g)))  # (L1, L2, P): h(Δ) = Σ r(u) g(u + Δ)
    energy = np.einsum("abpc->abp", g**2)
    cover = ifft(np.conj(fft(np.asarray(occupied, np.float64)))[..., None] * fft(energy))
    cover = cover / np.maximum(energy.sum(axis=(0, 1)), np.finfo(float).tiny)  # o_p(Δ)
    keep = np.all(cover >= min_overlap - 1e-9, axis=-1)  # (rounding of the FFT)
    keep[0, 0] = False
    if not keep.any():
        return np.zeros((g.shape[2], g.shape[2]))
    ht = h[keep] / np.sqrt(cover[keep])  # (|D|, P)
    return ht.T @ ht / len(ht)


def _design(F, WI, WO, params: WardParams, model: str, normalization: str):
    """The profiled joint problem at ``params``: valid mask ``w`` ``(S, N, 3)``, Jacobian ``J`` ``(P, S, N, 3)``
    centred per scanline and channel, ``A = JᵀJ``, the lobe ``b`` ``(S, N)`` and its channel means ``(P, S, 3)``."""
    iso = model == "isotropic"
    rs, ax, ay = float(params.rho_s), float(params.alpha_x), float(params.alpha_y)
    b, dlobe, valid = lobe(
        np.asarray(WI, np.float64), np.asarray(WO, np.float64), [ax] if iso else [ax, ay], normalization
    )
    w = (np.isfinite(F) & valid[..., None]).astype(np.float64)  # (S, N, 3)
    basis = np.concatenate([b[None], rs * dlobe], 0)  # (P, S, N): ∂(ρs b)/∂θ
    n_w = np.maximum(w.sum(axis=1), 1.0)  # (S, 3)
    mean = np.einsum("psn,snc->psc", basis, w) / n_w  # (P, S, 3)
    jac = (basis[..., None] - mean[:, :, None, :]) * w  # (P, S, N, 3)
    return w, jac, np.einsum("psnc,qsnc->pq", jac, jac), b, mean


def plane_covariance(resid, w, g, cols, points=None) -> np.ndarray:
    """:func:`placement_covariance` of the response ``g`` ``(P, S, N, 3)`` to the field ``resid`` ``(S, N, 3)``
    (valid where ``w > 0``), both moved onto a regular grid of the sample plane by :func:`sample_raster`.

    ``points`` ``(S, N, 2)`` (mm); without them, scanline ``s`` lies at ``cols[s]`` and sample ``n`` at ``n``.
    A cell holding several samples takes the mean of the field and the sum of the responses.
    """
    ok = w[..., 0] > 0
    if points is None:
        s_idx = np.broadcast_to(np.asarray(cols, np.float64)[:, None], ok.shape)
        points = np.stack([s_idx, np.broadcast_to(np.arange(ok.shape[1], dtype=np.float64), ok.shape)], -1)
    ix, iy, shape = sample_raster(np.asarray(points, np.float64), ok)
    at = (ix[ok], iy[ok])

    def on_raster(a):  # (S, N, ...) summed into the cells of the sample plane
        out = np.zeros(shape + a.shape[2:])
        np.add.at(out, at, a[ok])
        return out

    count = on_raster(w)  # samples per cell (and channel)
    r_cells = on_raster(np.where(w > 0, resid, 0.0)) / np.maximum(count, 1.0)
    return placement_covariance(r_cells, count[..., 0] > 0, on_raster(np.moveaxis(g, 0, -2)))


def texture_field_covariance(
    F, WI, WO, cols, params: WardParams, model: str, normalization: str, points=None
) -> TextureErrors:
    r"""Covariance of the joint (ρs, α…) with the ρd texture treated as a stationary random field.

    The joint fit (:meth:`~wardjax.ScanlineFit.combined`) takes ρd constant
    along a scanline. A real ρd texture varies along it, on scales
    comparable to the specular lobe, and part of it aliases into ρs, αx, αy.
    Linearised at the optimum ``θ = (ρs, α…)``, with ``J`` the Jacobian of
    the model ``ρs · b(ωi, ωo; α)`` in ``θ``, centred per scanline and
    channel (every ρd profiled out), and ``A = JᵀJ``,

    .. math::

        δθ = A^{-1} J^T δf = g\, δf,

    so a texture ``δf = δρd/π`` of covariance ``C`` gives ``Cov θ = g C gᵀ``.
    Residual-based (sandwich) errors cannot see this: the aliased part has
    been absorbed into θ (``Jᵀ r = 0``), and neighbouring scanlines see
    nearly the same texture, so clustering by scanline does not help
    either. Instead ``g C gᵀ`` is estimated from the joint fit's residual
    ``r = f_r − ρd,s/π − ρs b`` by :func:`placement_covariance`: the mean
    square response of θ to the residual shifted against the lobe, on a
    regular grid of the sample plane (``points``), where the texture is
    stationary. ``r(0)`` carries the pixel noise, so its contribution is
    included.

    Calibration (the simulator's textures alone on one 240 × 180 capture's
    response, 24 draws each; ``python -m benchmarks.capture_z --texture-alone
    24``): the root-mean σ over the Monte-Carlo SD of ρs, αx, αy reads
    0.97/0.81/1.14 on wood, 1.10/1.23/0.94 on broadband noise and
    0.78/0.99/0.85 on marble, whose veins are as large as the probe: the fit
    absorbs part of them, and the residual no longer shows it.

    Parameters
    ----------
    F, WI, WO
        ``(S, N, 3)`` fitted BRDF values (NaN where unusable) and directions
        (material frame) of the ``S`` scanlines.
    cols
        ``(S,)`` integer position of each scanline on the fit grid (image column / binning).
    params
        The joint fit (unbatched ρs, αx, αy).
    model, normalization
        As fitted: ``"isotropic"`` shares one α.
    points
        ``(S, N, 2)`` the samples' positions on the sample plane (mm); without
        them the fit grid (``cols`` by sample index) stands in for the plane.
    """
    rs = float(params.rho_s)
    F = np.asarray(F, np.float64)
    w, jac, info, b, mean = _design(F, WI, WO, params, model, normalization)
    if not np.all(np.isfinite(info)):
        nan = np.full_like(info, np.nan)
        return TextureErrors(nan, info, np.full((3, len(info)), np.nan), float("nan"))
    g = np.einsum("pq,qsnc->psnc", np.linalg.pinv(info), jac)
    resid = np.where(w > 0, np.nan_to_num(F) - rs * b[..., None], 0.0)
    n_w = np.maximum(w.sum(axis=1), 1.0)
    resid -= w * (resid.sum(axis=1, keepdims=True) / n_w[:, None, :])  # ρd,s/π profiled out
    cov = plane_covariance(resid, w, g, cols, points)
    rho_d_grad = -np.pi * mean.mean(axis=1).T  # (3, P): ρ̄d = π mean_s ⟨f − ρs b⟩_s
    n_valid = w.sum(axis=(0, 1))
    rms = float(np.pi * np.sqrt(np.sum(resid**2) / max(float(n_valid.sum()), 1.0)))
    return TextureErrors(cov, info, rho_d_grad, rms)


def with_texture_errors(comb: CombinedFit, te: TextureErrors) -> CombinedFit:
    """``comb`` reporting the texture-field covariance (its model and sandwich ones kept).

    ρd's error keeps the fit's noise term and swaps the propagated (ρs, α) part:
    ``σ²(ρ̄d) = σ²_noise + ∇ρ̄d · Cov θ · ∇ρ̄d``.
    """
    cov = te.covariance
    if not np.all(np.isfinite(cov)):
        return comb
    se = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    grad = te.rho_d_grad
    quad = lambda c: np.einsum("ip,pq,iq->i", grad, c, grad)
    noise_var = np.clip(np.asarray(comb.stderr.rho_d, float) ** 2 - quad(comb.covariance), 0.0, None)
    iso = comb.model == "isotropic"
    stderr = WardParams.from_estimate(
        rho_d=np.sqrt(noise_var + quad(cov)), rho_s=se[0], alpha_x=se[1], alpha_y=se[1] if iso else se[2]
    )
    return dataclasses.replace(comb, stderr=stderr, covariance=cov, errors="texture_field")
