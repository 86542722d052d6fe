"""Per-pixel slopes projected onto a height field: the nearest integrable normal map, weighted by precision.

The normals of a surface are the gradient of its height ``h``: the slopes
``g = ∇h`` of every pixel are not free, they are tied to their neighbours
(``∂g_x/∂y = ∂g_y/∂x``, a curl-free field). Given each pixel's fitted slopes
``ĝ_p`` and their precision ``W_p = Σ_p⁻¹`` (``(2, 2)``, the Gauss–Newton
inverse covariance of :mod:`._pixel_normals`), the height is

.. math::

    h^\\star = \\arg\\min_h \\sum_p (D h - ĝ)_p^T\\, W_p\\, (D h - ĝ)_p
    + R(h), \\qquad g^\\star = D h^\\star

— Frankot & Chellappa (1988), the least-squares projection of a slope field
onto the integrable ones, here with each pixel weighted by what its photos
say (where a pixel's photos miss the highlight, ``W_p ≈ 0`` and its slopes
come from its neighbours). ``D`` is a finite difference of order 6 on the
image's own heights (:data:`STENCIL` = 7 samples, Fornberg's weights: off by
0.15 % at 8 pixels per bump period, where the 3-point difference is off by
10 %), central where the samples allow and shifted inwards within 3 pixels of
an edge (2.9 % off at the edge itself), so that every pixel's slopes are the
derivative of heights the photos constrain. A derivative that reads heights
beyond the image — a spectral one on a grid padded with a margin where the
height wraps round — leaves an edge pixel's slope across the edge free (the
margin bends to fit it): the edge pixels then keep the noise of their own fits,
and the photo whose highlight falls near an edge is predicted worst. The
image need not be periodic. A central difference does not see a sawtooth at
the pixel pitch (its response ``sin kδ`` vanishes at the Nyquist frequency)
while an edge's shifted one reads it at 28 times its amplitude, so a sawtooth
under a smooth envelope would again leave the edge slopes free (and carry
the imprecise pixels' noise): the penalty ``R``

.. math::

    R(h) = ε \\sum (Δ^2 h)^2 + \\sum (Δ^6 h / 64)^2

along rows and columns (weights over the mean precision, ``ε`` = 10⁻⁴) holds
it. The sixth difference over ``2⁶`` answers ``sin⁶(kδ/2)``: 1 at the pixel
pitch, 0.003 at 8 pixels per period, where it moves a slope by 10⁻⁵ of
itself (the prior that the surface has nothing at the pitch its pixels sample
it at). The constant, which no slope sees, is pinned at 0. The normal equations
are sparse (a 13-sample cross per height) and solved directly
(:func:`scipy.sparse.linalg.spsolve`).

A finite difference is off by 0.8 % at 6 pixels per bump period, 7 % at 4 and
26 % at 3 (its shifted stencils 14 %, 114 %, 385 %). The other ``D`` on the same
heights is the spectral derivative of the image taken as one period of the
surface (``i k``, its Nyquist term zero; ``R`` its second-difference term
only, the sawtooth being invisible to it everywhere): exact above the Nyquist
rate where the surface repeats over the image, while where it does not the
edges are tied to the opposite ones and the photos there are fitted worse.
Both are fitted and the one whose heights fit the photos with the lower summed
χ² is kept (:func:`heights_of_least_chi2`): the same ``H × W`` heights, so the
χ² compare like for like (its normal equations are dense, so it is tried up to
:data:`_PERIODIC_MAX` pixels).

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

import functools
import math

import jax
import jax.numpy as jnp
import numpy as np
from scipy import sparse
from scipy.sparse.linalg import spsolve

from . import _pixel_model as pm
from ._pixel_clusters import STEPS
from ._pixel_normals import fit_normals, normal_from_slopes, slope_systems

__all__ = [
    "check_image_shape",
    "heights_by_gauss_newton",
    "heights_of_least_chi2",
    "integrable_slopes",
    "on_height_field",
]

STENCIL = 7  # samples per derivative: order 6 in the interior (0.15 % off at 8 pixels per period)
_EPS = 1e-4  # the second difference's weight, over the mean precision
_SAWTOOTH = 1.0  # the 6th difference's weight, over the mean precision (module docstring)
_RIDGE = 1e-12  # pins the constant height, over the mean precision
_ROUNDS = 3  # projections onto the height field while the labels change there
# pixels up to which the periodic spectral derivative is tried too (its normal equations are dense)
_PERIODIC_MAX = 4096
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


def _derivative_matrix(n: int) -> sparse.csr_array:
    """``(n, n)``: the derivative at each of ``n`` unit-spaced samples from the :data:`STENCIL` nearest of them.

    Fornberg's weights: exact for polynomials of degree ``STENCIL − 1``; central (order 6) where the
    samples allow, shifted inwards near the ends, so that every derivative reads heights of the image.
    """
    width = min(STENCIL, n)
    rows, cols, vals = [], [], []
    for i in range(n):
        lo = min(max(i - width // 2, 0), n - width)
        x = np.arange(lo, lo + width, dtype=np.float64) - i
        rhs = np.zeros(width)
        rhs[1] = 1.0
        w = np.linalg.solve(np.vander(x, width, increasing=True).T, rhs)
        rows += [i] * width
        cols += list(range(lo, lo + width))
        vals += list(w)
    return sparse.csr_array((vals, (rows, cols)), shape=(n, n))


def _spectral_matrix(n: int) -> sparse.csr_array:
    """``(n, n)``: the derivative of ``n`` samples of a period-``n`` sequence, ``i k`` in the Fourier domain
    (zero at the Nyquist frequency, where a real sequence has no derivative): exact for a periodic height
    sampled above its Nyquist rate."""
    k = 2.0 * np.pi * np.fft.fftfreq(n)
    ik = 1j * np.where(np.abs(k) < np.pi, k, 0.0)
    return sparse.csr_array(np.fft.ifft(ik[:, None] * np.fft.fft(np.eye(n), axis=0), axis=0).real)


def _difference(n: int, order: int) -> sparse.csr_array:
    """``(n − order, n)``: the ``order``-th difference ``Σ_j (−1)^j C(order, j) h[i + j]`` / ``2^order``
    (response ``sin^order(kδ/2)``: 1 at the Nyquist frequency)."""
    m = max(n - order, 0)
    c = np.array([(-1.0) ** j * math.comb(order, j) for j in range(order + 1)]) / 2.0**order
    i = np.arange(m)
    return sparse.csr_array(
        (np.tile(c, m), (np.repeat(i, order + 1), (i[:, None] + np.arange(order + 1)).ravel())), shape=(m, n)
    )


class _Operators:
    """The derivative ``D`` (heights of the ``H × W`` image → its slopes, ``(2P, P)``), its adjoint and the
    penalty's matrix (module docstring), as sparse matrices of the row-major flattened heights; ``periodic``:
    the spectral derivative of the image's heights taken as one period (no sixth-difference penalty: it
    does not read a sawtooth at the pixel pitch anywhere)."""

    def __init__(self, shape: tuple[int, int], periodic: bool = False):
        self.shape = shape
        h, w = shape
        derivative = _spectral_matrix if periodic else _derivative_matrix
        d_col = sparse.kron(sparse.eye_array(h), derivative(w), format="csr")
        d_row = sparse.kron(derivative(h), sparse.eye_array(w), format="csr")
        self.dx, self.dy = d_col, -d_row  # g_x = ∂h/∂column, g_y = −∂h/∂row
        self.curv = sparse.csr_array((h * w, h * w))
        for order, weight in ((2, 16.0 * _EPS), (6, 0.0 if periodic else _SAWTOOTH)):
            c_col = sparse.kron(sparse.eye_array(h), _difference(w, order))
            c_row = sparse.kron(_difference(h, order), sparse.eye_array(w))
            self.curv = self.curv + weight * (c_col.T @ c_col + c_row.T @ c_row)
        self.curv = self.curv.tocsr()

    def grad(self, height: np.ndarray) -> np.ndarray:
        x = np.asarray(height).ravel()
        return np.stack([self.dx @ x, self.dy @ x], -1).reshape(self.shape + (2,))

    def grad_adjoint(self, slopes: np.ndarray) -> np.ndarray:
        g = np.asarray(slopes).reshape(-1, 2)
        return (self.dx.T @ g[:, 0] + self.dy.T @ g[:, 1]).reshape(self.shape)

    def curvature(self, height: np.ndarray) -> np.ndarray:
        return (self.curv @ np.asarray(height).ravel()).reshape(self.shape)


@functools.lru_cache(maxsize=8)
def _operators(shape: tuple[int, int], periodic: bool) -> _Operators:
    """The :class:`_Operators` of an image shape, built once: the height fit projects at every step."""
    return _Operators(shape, periodic)


def integrable_slopes(
    slopes: np.ndarray, precision: np.ndarray, image_shape: tuple[int, int], *, periodic: bool = False
) -> tuple[np.ndarray, np.ndarray]:
    """The slopes ``(P, 2)`` of the height field nearest to ``slopes`` in the metric ``precision (P, 2, 2)``.

    Pixels are row-major in an ``image_shape = (H, W)`` image (module docstring). Non-finite
    slopes or precisions count as no information (weight 0). Returns ``g* (P, 2)`` and the
    height ``(H, W)`` in pixel pitches, its mean zero. ``periodic``: the image's heights as one period of a
    periodic surface, differentiated spectrally (:class:`_Operators`).
    """
    shape = (int(image_shape[0]), int(image_shape[1]))
    g = np.asarray(slopes, np.float64).reshape(-1, 2)
    wt = np.asarray(precision, np.float64).reshape(-1, 2, 2)
    bad = ~(np.all(np.isfinite(g), -1) & np.all(np.isfinite(wt), (-2, -1)))
    g = np.where(bad[..., None], 0.0, g)
    wt = np.where(bad[..., None, None], 0.0, 0.5 * (wt + np.swapaxes(wt, -1, -2)))
    scale = float(np.mean(np.trace(wt, axis1=-2, axis2=-1))) / 2.0
    wt = wt / (scale if scale > 0 else 1.0)  # the solution does not depend on a common scale
    ops = _operators(shape, bool(periodic))
    dx, dy = ops.dx, ops.dy

    def weighted(i: int, j: int) -> sparse.csr_array:
        return sparse.diags_array(wt[:, i, j]) @ (dx if j == 0 else dy)

    a = dx.T @ (weighted(0, 0) + weighted(0, 1)) + dy.T @ (weighted(1, 0) + weighted(1, 1)) + ops.curv
    wg = np.einsum("pij,pj->pi", wt, g)
    rhs = dx.T @ wg[:, 0] + dy.T @ wg[:, 1]
    # the constant, which no slope sees (rhs ⟂ it: every stencil sums to 0), pinned at 0 by a ridge far below the rest
    a = (a + _RIDGE * sparse.eye_array(a.shape[0])).tocsc()
    if periodic:  # every slope reads its whole row and column: the normal equations are dense
        height = np.linalg.solve(a.toarray(), rhs).reshape(shape)
    else:
        height = np.asarray(spsolve(a, rhs)).reshape(shape)
    return ops.grad(height).reshape(-1, 2), height - np.mean(height)


def heights_by_gauss_newton(
    g, data, theta_p, s_p, tangent, normalization: str, shape, *, steps: int = _GN_STEPS, periodic: bool = False
):
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
        trial, _ = integrable_slopes(target, damped, shape, periodic=periodic)
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


def heights_of_least_chi2(g, precision, data, theta_p, s_p, tangent, normalization: str, shape):
    """The slopes ``(P, 2)`` projected (:func:`integrable_slopes`) and moved to the least summed χ²
    (:func:`heights_by_gauss_newton`) with each derivative, the finite difference and the periodic spectral
    one (images of up to :data:`_PERIODIC_MAX` pixels); returns those of the lower χ², it, and whether
    the spectral derivative gave them.

    Both fit the same ``H × W`` heights, so their summed χ² on the same photos compare like for like. The
    finite difference is off by 7 % at 4 pixels per bump period and 26 % at 3 (more at the edges); the
    spectral one is exact there where the surface repeats over the image, and wraps the edges onto each
    other where it does not, which costs χ² at the edges.
    """
    n_pixels = int(shape[0]) * int(shape[1])
    best = None
    for periodic in (False, True) if n_pixels <= _PERIODIC_MAX else (False,):
        start, _ = integrable_slopes(g, precision, shape, periodic=periodic)
        g_star, cost = heights_by_gauss_newton(
            start, data, theta_p, s_p, tangent, normalization, shape, periodic=periodic
        )
        if best is None or cost < best[1]:
            best = (g_star, cost, periodic)
    assert best is not None
    return best


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
    labels and projected again. The heights are those of least summed χ² with either derivative
    (:func:`heights_of_least_chi2`). Returns ``theta``, ``s``, ``labels``, the normal map, the geometry, the
    ``(a, g)`` covariances of the pixels' own fits (an upper bound on the projected slopes' uncertainty),
    and the χ² after, the slopes' RMS move, how many labels changed and the derivative kept.
    """
    f, w, wi, wo = data
    c = f.shape[-1]
    g_from = -normal_map[:, :2] / normal_map[:, 2:]
    moved = relabelled = 0
    periodic = False
    for _ in range(_ROUNDS):
        g, _, _, _, cov = fit_normals(f, w, wi, wo, theta[labels], s[labels], t, normalization, g_from, grid=False)
        cov_g = np.asarray(cov[:, c:, c:])
        cov_g = np.where(np.all(np.isfinite(cov_g), (1, 2))[:, None, None], cov_g, 0.0)
        g = np.asarray(g)
        g_star, _, periodic = heights_of_least_chi2(
            g, np.linalg.pinv(cov_g), data, theta[labels], s[labels], t, normalization, shape
        )
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
        {
            "chi2": chi2,
            "slopes_moved_rms": moved,
            "labels_changed": relabelled,
            "derivative": "spectral" if periodic else "difference",
        },
    )
