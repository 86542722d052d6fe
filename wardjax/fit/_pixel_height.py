"""Per-pixel slopes projected onto a height field: the nearest integrable normal map, weighted by precision.

The normals of a surface are the gradient of its height ``h``: the slopes
``g = ∇h`` of every pixel are not free, they are tied to their neighbours
(``∂g_x/∂y = ∂g_y/∂x``, a curl-free field). Given each pixel's fitted slopes
``ĝ_p`` and their precision ``W_p = Σ_p⁻¹`` (``(2, 2)``, the Gauss–Newton
inverse covariance of :mod:`._pixel_normals`), the height is

.. math::

    h^\\star = \\arg\\min_h \\sum_p (D h - ĝ)_p^T\\, W_p\\, (D h - ĝ)_p
    + ε \\sum |∇^2 h|^2, \\qquad g^\\star = D h^\\star

— Frankot & Chellappa (1988), the least-squares projection of a slope field
onto the integrable ones, here with each pixel weighted by what its photos
say (where a pixel's photos miss the highlight, ``W_p ≈ 0`` and its slopes
come from its neighbours). ``D`` is the spectral derivative (``i k`` in the
Fourier domain: exact for a height sampled above its Nyquist rate, where a
finite difference at 8 pixels per bump period is off by 5–10 %). The image
need not be periodic: the height lives on a grid ``margin`` pixels larger in
each direction, the margin holding no data, so that the height can wrap
round smoothly there (mirroring the image instead forces ``∂h/∂n = 0`` at its
edges). The small curvature term (``ε`` = 10⁻⁴ of the mean precision) fixes
the margin's heights; on the data it changes a slope of 8 pixels' period by
under 10⁻⁴ of itself. Up to :data:`_DIRECT` heights the normal equations are
assembled (:mod:`scipy.sparse`) and solved directly; above, by conjugate
gradients (:func:`scipy.sparse.linalg.cg`, FFTs of :mod:`numpy.fft`),
preconditioned by their Fourier-diagonal part. ``h`` is known up to a constant.

That projection is each pixel's χ² replaced by its quadratic model at the
pixel's own optimum. Where a pixel's photos see only the tails of its
highlight, χ² is far from quadratic over the slopes its neighbours ask of it,
and the projected surface is not the one that fits the photos best: from it,
:func:`heights_by_gauss_newton` takes Levenberg–Marquardt steps in the heights
on the summed χ² itself, ``min_h Σ_p χ²_p((D h)_p)``, each step the same
projection of every pixel's Gauss–Newton model at its current slopes.

Heights are in units of the pixel pitch (square pixels); rows run along
``−y`` and columns along ``+x`` (the rectified layout of
:func:`wardjax.render.flash_views`), so ``g_x = ∂h/∂column`` and
``g_y = −∂h/∂row``.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
from numpy import fft
from scipy import sparse
from scipy.sparse.linalg import LinearOperator, cg

from . import _pixel_model as pm
from ._pixel_clusters import STEPS
from ._pixel_normals import fit_normals, normal_from_slopes, slope_systems

__all__ = ["check_image_shape", "heights_by_gauss_newton", "integrable_slopes", "on_height_field"]

MARGIN = 8  # pixels of margin on each axis, where the height wraps round
_EPS = 1e-4  # the curvature term's weight, over the mean precision
_RTOL = 1e-10
_MAX_ITER = 5000
_ROUNDS = 3  # projections onto the height field while the labels change there
_DIRECT = 2500  # up to this many heights (the padded grid) the normal equations are solved directly
_GN_STEPS = 20  # Levenberg–Marquardt steps on the heights (the 32² renders converge in 5–6)


def check_image_shape(image_shape, n_pixels: int) -> tuple[int, int]:
    """``(H, W)`` with ``H·W = n_pixels`` and both ≥ 2, or a ``ValueError`` naming the argument."""
    try:
        h, w = (int(x) for x in image_shape)
    except (TypeError, ValueError):
        raise ValueError(f"height_field must be the image's (H, W), got {image_shape!r}") from None
    if h < 2 or w < 2 or h * w != n_pixels:
        raise ValueError(f"height_field {(h, w)} must hold the {n_pixels} pixels as H·W with H, W ≥ 2")
    return h, w


class _Operators:
    """The spectral gradient ``D`` (heights on the padded grid → slopes on the image), its adjoint and the
    curvature term, on an ``(H + margin) × (W + margin)`` periodic grid."""

    def __init__(self, shape: tuple[int, int], margin: int):
        self.shape = shape
        self.padded = (shape[0] + margin, shape[1] + margin)
        fr = 2.0 * np.pi * fft.fftfreq(self.padded[0])[:, None]
        fc = 2.0 * np.pi * fft.fftfreq(self.padded[1])[None, :]
        self.k4 = (fr * fr + fc * fc) ** 2
        # ik of the derivative, zero at Nyquist (a real field has no derivative there)
        self.ikr = 1j * np.where(np.abs(fr) < np.pi, fr, 0.0)
        self.ikc = 1j * np.where(np.abs(fc) < np.pi, fc, 0.0)

    def grad(self, height: np.ndarray) -> np.ndarray:
        h, w = self.shape
        spec = fft.fft2(height)
        d_row = fft.ifft2(spec * self.ikr).real[:h, :w]
        d_col = fft.ifft2(spec * self.ikc).real[:h, :w]
        return np.stack([d_col, -d_row], -1)

    def grad_adjoint(self, slopes: np.ndarray) -> np.ndarray:
        h, w = self.shape
        col, row = np.zeros(self.padded), np.zeros(self.padded)
        col[:h, :w], row[:h, :w] = slopes[..., 0], -slopes[..., 1]
        # ik is anti-Hermitian: the adjoint of multiplying by it is multiplying by −ik
        return fft.ifft2(-fft.fft2(col) * self.ikc - fft.fft2(row) * self.ikr).real

    def curvature(self, height: np.ndarray) -> np.ndarray:
        return fft.ifft2(fft.fft2(height) * self.k4).real

    def matrices(self) -> tuple:
        """``D_x``, ``D_y`` ``(P, n)`` (sparse: a pixel's x slope reads its row, its y slope its column) and the
        curvature term ``(n, n)``, as matrices of the flattened padded heights."""
        h, w = self.shape
        hp, wp = self.padded

        def circulant(ik: np.ndarray) -> np.ndarray:  # the derivative of a periodic sequence, as a matrix
            return fft.ifft(ik[:, None] * fft.fft(np.eye(ik.size), axis=0), axis=0).real

        d_col = sparse.kron(sparse.eye_array(hp), circulant(self.ikc.ravel()), format="csr")
        d_row = sparse.kron(circulant(self.ikr.ravel()), sparse.eye_array(wp), format="csr")
        data = (np.arange(hp)[:, None] * wp + np.arange(wp)[None, :])[:h, :w].ravel()
        curv = fft.ifft2(self.k4[None] * fft.fft2(np.eye(hp * wp).reshape(-1, hp, wp))).real.reshape(hp * wp, -1)
        return d_col[data], -d_row[data], curv


def integrable_slopes(
    slopes: np.ndarray, precision: np.ndarray, image_shape: tuple[int, int], *, margin: int = MARGIN
) -> tuple[np.ndarray, np.ndarray]:
    """The slopes ``(P, 2)`` of the height field nearest to ``slopes`` in the metric ``precision (P, 2, 2)``.

    Pixels are row-major in an ``image_shape = (H, W)`` image (module docstring). Non-finite
    slopes or precisions count as no information (weight 0). Returns ``g* (P, 2)`` and the
    height ``(H, W)`` in pixel pitches, its mean zero.
    """
    shape = (int(image_shape[0]), int(image_shape[1]))
    g = np.asarray(slopes, np.float64).reshape(shape + (2,))
    wt = np.asarray(precision, np.float64).reshape(shape + (2, 2))
    bad = ~(np.all(np.isfinite(g), -1) & np.all(np.isfinite(wt), (-2, -1)))
    g = np.where(bad[..., None], 0.0, g)
    wt = np.where(bad[..., None, None], 0.0, 0.5 * (wt + np.swapaxes(wt, -1, -2)))
    scale = float(np.mean(np.trace(wt, axis1=-2, axis2=-1))) / 2.0
    wt = wt / (scale if scale > 0 else 1.0)  # the solution does not depend on a common scale
    ops = _Operators(shape, int(margin))
    padded = ops.padded
    n = padded[0] * padded[1]

    def normal(x: np.ndarray) -> np.ndarray:
        x = x.reshape(padded)
        data = ops.grad_adjoint(np.einsum("...ij,...j->...i", wt, ops.grad(x)))
        return (data + _EPS * ops.curvature(x)).ravel()

    rhs = ops.grad_adjoint(np.einsum("...ij,...j->...i", wt, g)).ravel()
    if n <= _DIRECT:
        height = _direct(ops, wt.reshape(-1, 2, 2), rhs)
    else:
        height = _iterative(ops, wt, rhs, normal, shape, padded)
    height = height.reshape(padded)
    out = ops.grad(height)
    height = height[: shape[0], : shape[1]]
    return out.reshape(-1, 2), height - np.mean(height)


def _direct(ops: _Operators, wt: np.ndarray, rhs: np.ndarray) -> np.ndarray:
    """The normal equations assembled and solved (the constant, which no slope sees, pinned at 0)."""
    dx, dy, curv = ops.matrices()

    def weighted(i: int, j: int) -> sparse.csr_array:
        return sparse.diags_array(wt[:, i, j]) @ (dx if j == 0 else dy)

    a = dx.T @ (weighted(0, 0) + weighted(0, 1)) + dy.T @ (weighted(1, 0) + weighted(1, 1))
    a = np.asarray(a.todense()) + _EPS * curv + 1.0 / a.shape[0]  # + 1/n: the constant's row, pinning its mean
    return np.linalg.solve(a, rhs)


def _iterative(ops, wt, rhs, normal, shape, padded) -> np.ndarray:
    """Conjugate gradients with the FFT operators, preconditioned by the Fourier-diagonal part."""
    n = padded[0] * padded[1]
    share = shape[0] * shape[1] / n  # the data cover this share of the padded grid
    diag = share * (np.abs(ops.ikr) ** 2 + np.abs(ops.ikc) ** 2) + _EPS * ops.k4
    diag[0, 0] = 1.0  # the constant: no slope sees it

    def precondition(x: np.ndarray) -> np.ndarray:
        return fft.ifft2(fft.fft2(x.reshape(padded)) / diag).real.ravel()

    op = LinearOperator((n, n), matvec=normal, dtype=np.float64)  # pyright: ignore[reportCallIssue]
    pre = LinearOperator((n, n), matvec=precondition, dtype=np.float64)  # pyright: ignore[reportCallIssue]
    height, _ = cg(op, rhs, rtol=_RTOL, maxiter=_MAX_ITER, M=pre)
    return height


def heights_by_gauss_newton(g, data, theta_p, s_p, tangent, normalization: str, shape, *, steps: int = _GN_STEPS):
    """The height field of least summed χ², ``h* = argmin_h Σ_p χ²_p((D h)_p)``, from integrable slopes ``g (P, 2)``.

    Each pixel's χ² (ρd profiled, its lobe ``theta_p (P, d)``, ``s_p (P,)`` given) is linearised at the
    current slopes (:func:`~._pixel_normals.slope_systems`: ``H_p = JᵀJ``, ``b_p = Jᵀr``), and the step
    is the projection (:func:`integrable_slopes`) of the Levenberg–Marquardt targets
    ``g − (H_p + λ s̄ I)⁻¹ b_p`` with precision ``H_p + λ s̄ I`` (``s̄`` the mean of ``tr H / 2``): one
    Gauss–Newton step in the heights, since ``D`` is linear. A step is kept where the summed χ² falls
    (``λ`` × 0.3), else ``λ`` × 10; at most ``steps`` steps.

    Projecting each pixel's own optimum with its own Gauss–Newton precision (the first step of
    :func:`on_height_field`) is this with every χ² replaced by its quadratic model at that optimum: where a
    pixel's photos see only its highlight's tails, χ² is far from quadratic over the slopes its neighbours
    ask of it, and the projected slopes are not the surface that fits the photos best.

    Returns the slopes ``(P, 2)`` and their summed χ².
    """
    f, w, wi, wo = data
    eye = np.eye(2)[None]

    def system(g):
        out = slope_systems(jnp.asarray(g), f, w, wi, wo, theta_p, s_p, tangent, normalization=normalization)
        return tuple(np.asarray(x) for x in out)

    g = np.asarray(g, np.float64)
    h, b, c = system(g)
    cost, lam = float(np.sum(c)), 1e-3
    for _ in range(steps):
        damped = h + lam * float(np.mean(np.trace(h, axis1=1, axis2=2))) / 2.0 * eye
        target = g - np.linalg.solve(damped, b[..., None])[..., 0]
        trial, _ = integrable_slopes(target, damped, shape)
        h_new, b_new, c_new = system(trial)
        if not float(np.sum(c_new)) < cost:
            lam *= 10.0
            if lam > 1e6:
                break
            continue
        done = cost - float(np.sum(c_new)) < 1e-9 * cost
        g, h, b, cost, lam = trial, h_new, b_new, float(np.sum(c_new)), 0.3 * lam
        if done:
            break
    return g, cost


@jax.jit
def relabel(theta, s, labels, geom, f, w):
    """``(P,)`` each pixel's lobe at fixed normals: the one of lowest ``χ²_pl − 2 log π_l`` (ρd profiled,
    ``π`` the current shares), the assignment step of the hard EM of :mod:`._pixel_clusters`."""
    k, p = theta.shape[0], f.shape[0]
    log_pi = jnp.log(jnp.maximum(jnp.bincount(labels, length=k) / p, 1e-300))
    cost = jnp.stack([pm.pixel_chi2(theta, s, jnp.full(p, i, jnp.int32), geom, f, w) for i in range(k)], 1)
    return jnp.argmin(cost - 2.0 * log_pi[None], 1).astype(jnp.int32)


def on_height_field(theta, s, labels, normal_map, data, t, normalization, shape):
    """Each pixel's slopes refitted from where they are (its own optimum, not left flat) and projected onto
    the nearest height field, weighted by their precision (:mod:`._pixel_height`); then each pixel's lobe
    chosen again at its new normal (:func:`relabel`) and the lobes refitted there.

    A pixel whose photos see only the tails of its highlight may have taken the wrong lobe with a normal
    bent to fit it; on the height field its normal comes from its neighbours, and its lobe is decided
    there. While labels change (at most :data:`_ROUNDS` rounds) the slopes are refitted under the new
    labels and projected again. Returns ``theta``, ``s``, ``labels``, the normal map, the geometry, the
    ``(a, g)`` covariances of the pixels' own fits (an upper bound on the projected slopes' uncertainty),
    and the χ² after, the slopes' RMS move and how many labels changed.
    """
    f, w, wi, wo = data
    c = f.shape[-1]
    g_from = -normal_map[:, :2] / normal_map[:, 2:]
    moved = relabelled = 0
    for _ in range(_ROUNDS):
        g, _, _, _, cov = fit_normals(f, w, wi, wo, theta[labels], s[labels], t, normalization, g_from, grid=False)
        cov_g = np.asarray(cov[:, c:, c:])
        cov_g = np.where(np.all(np.isfinite(cov_g), (1, 2))[:, None, None], cov_g, 0.0)
        g = np.asarray(g)
        g_star, _ = integrable_slopes(g, np.linalg.pinv(cov_g), shape)
        g_star, _ = heights_by_gauss_newton(g_star, data, theta[labels], s[labels], t, normalization, shape)
        moved = moved or float(np.sqrt(np.mean((g_star - g) ** 2)))
        normal_map = normal_from_slopes(jnp.asarray(g_star))
        geom = pm.geometry(wi, wo, normal_map, t, normalization)
        theta, s, _ = pm.lobe_fit(theta, labels, geom, f, w, n_lobes=int(theta.shape[0]), steps=STEPS)
        new = relabel(theta, s, labels, geom, f, w)
        changed = int(jnp.sum(new != labels))
        if not changed:
            break
        relabelled += changed
        labels = new
        theta, s, _ = pm.lobe_fit(theta, labels, geom, f, w, n_lobes=int(theta.shape[0]), steps=STEPS)
        g_from = jnp.asarray(g_star)
    chi2 = float(jnp.sum(pm.pixel_chi2(theta, s, labels, geom, f, w)))
    return (
        theta,
        s,
        labels,
        normal_map,
        geom,
        cov,
        {"chi2": chi2, "slopes_moved_rms": moved, "labels_changed": relabelled},
    )
