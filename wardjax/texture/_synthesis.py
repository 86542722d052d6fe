"""Heeger–Bergen synthesis: histogram matching of noise to a :class:`TextureModel`, in pyramid and pixel space."""

from __future__ import annotations

import concurrent.futures
import os
from collections.abc import Callable
from typing import cast

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from . import _binned
from ._analysis import _groups, _rho_s_vector, _subband_shapes
from ._histogram import _ks_picks, _ks_sorted, _targets
from ._jit import texture_jit
from ._model import TextureModel
from ._pyramid import (
    pyramid_collapse,
    pyramid_shapes,
    pyramid_subbands,
)
from ._rank import _MAX_ROW, _POSITION_BITS, SortMethod, _rank_match
from ._steerable import _device_masks

# ====================================================================== synthesis


class SynthesisResult(eqx.Module):
    """A synthesised texture and how close its statistics came to the model's.

    Attributes
    ----------
    image
        ``(H, W, C)`` float32 linear ρd in ``[0, 1 − ρs]``; tiles seamlessly.
    distance
        ``(iterations,)`` after each iteration, the largest one-sample
        Kolmogorov–Smirnov statistic between a subband of the image (any
        channel, any subband) and the model's distribution for it.
    band_distance
        ``(iterations, C, B)`` the same per channel and subband.
    initial_distance
        The same for the starting noise (after pixel histogram matching).
    seed
        The seed the noise was drawn with.
    """

    image: np.ndarray
    distance: np.ndarray
    band_distance: np.ndarray
    initial_distance: float
    seed: int = eqx.field(static=True)


@texture_jit(static_argnames="shapes")
def _build_groups(d, masks, shapes):
    """Pyramid of the pixels ``d`` (``(C, 1, H W)``) as sorting groups (:func:`_groups`)."""
    c = d.shape[0]
    return _groups(pyramid_subbands(jnp.fft.rfft2(d.reshape(c, *shapes[0]), norm="forward"), masks, shapes), c)


@texture_jit(static_argnames="shapes")
def _collapse(groups, masks, shapes):
    """Inverse of :func:`_build_groups`: collapse matched subband groups into pixels ``(C, 1, H W)``."""
    c = groups[0].shape[0]
    subbands = tuple(g.reshape(c, *s) for g, s in zip(groups, _subband_shapes(shapes)))
    return pyramid_collapse(subbands, masks, shapes).reshape(c, 1, -1)


@texture_jit(static_argnames="sizes")
def _band_ks(picked, tables, probs, sizes):
    """KS distance ``(C, B)`` of every subband from its every-s-th order statistics (:func:`_ks_sorted`)."""
    return jnp.concatenate([_ks_sorted(p, t, probs, n) for p, t, n in zip(picked, tables, sizes)], axis=-1)


def _band_targets(band_q: np.ndarray, probs: np.ndarray, shapes):
    """Sorted target values ``(C, 1, n_b)`` for every subband at this output size.

    Also its quantile table ``(C, 1, Q)``.
    """
    groups, tables = [], []
    for b, (h, w) in enumerate(_subband_shapes(shapes)):
        t = band_q[:, b : b + 1]
        tables.append(jnp.asarray(t, jnp.float32))
        groups.append(_targets(t, probs, h * w))
    return tuple(groups), tuple(tables)


def _heeger_bergen(rng, band_q, pixel_q, probs64, masks, shapes, iterations: int, sort: SortMethod, progress=None):
    """The iterations of :func:`synthesize_texture`, channel by channel, from the noise of ``rng`` (a NumPy Generator).

    Per channel: ``d ← match(noise, pixels)``; then ``iterations`` times: pyramid
    of ``d``, every subband ``← match(subband, its targets)``,
    ``d ← match(collapse, pixels)``; and a last pyramid to measure the final
    distance. ``band_q`` ``(C, B, Q)``, ``pixel_q`` ``(C, Q)`` and ``probs64``
    are the model's tables (float64).

    The channels are independent, so they are interleaved: while the host ranks
    one channel's subbands, XLA builds or collapses another's pyramid
    (asynchronous dispatch); the subband targets are interpolated while XLA
    builds the first pyramids. ``progress(k, iterations)`` is called as the
    ``k``-th iteration's matching is done. Returns the ``C`` channels
    ``(1, 1, H W)`` and the KS distances ``(iterations + 1, C, B)``, the first
    for the starting noise.
    """
    c, n_pix = pixel_q.shape[0], shapes[0][0] * shapes[0][1]
    probs = jnp.asarray(probs64, jnp.float32)
    pix_targets, ds, groups = [], [], []
    for ch in range(c):
        noise = rng.standard_normal((1, 1, n_pix), dtype=np.float32)  # channel by channel: the same stream as (C, n)
        pix_targets.append(_targets(pixel_q[ch : ch + 1, None], probs64, n_pix))
        (d,), _ = _rank_match((noise,), (pix_targets[ch],), ((),), sort)
        ds.append(d)
        groups.append(_build_groups(d, masks, shapes))  # dispatched: runs while the next channel is ranked
    targets, tables = zip(*(_band_targets(band_q[ch : ch + 1], probs64, shapes) for ch in range(c)))
    sizes = tuple(t.shape[-1] for t in targets[0])
    ks_picks = tuple(_ks_picks(n) for n in sizes)
    ks = [[] for _ in range(c)]
    for it in range(iterations + 1):
        last = it == iterations  # the final pyramid only measures the distance: sort, no matching
        collapsed = []
        for ch in range(c):
            matched, picked = _rank_match(groups[ch], None if last else targets[ch], ks_picks, sort)
            ks[ch].append(_band_ks(picked, tables[ch], probs, sizes))
            if not last:
                collapsed.append(_collapse(matched, masks, shapes))
        for ch in range(len(collapsed)):
            (ds[ch],), _ = _rank_match((collapsed[ch],), (pix_targets[ch],), ((),), sort)
            groups[ch] = _build_groups(ds[ch], masks, shapes)
        if progress is not None and not last:
            progress(it + 1, iterations)
    ks = np.stack([np.concatenate([np.asarray(k[it], np.float64) for k in ks]) for it in range(iterations + 1)])
    return ds, ks


def _heeger_bergen_binned(rng, band_q, pixel_q, probs64, shapes, iterations: int, progress, devices):
    """:func:`_heeger_bergen` with Heeger & Bergen's binned matching (:mod:`~wardjax.texture._binned`), all in XLA.

    The same noise stream and iterations; the KS distances are measured from
    the bin counts. With several ``devices`` (or one accelerator) the
    channels, padded to a multiple of their number, are split over them along
    the channel axis (``NamedSharding`` over a 1-D mesh; the channels are
    independent, so no device waits for another). On one CPU device each
    channel is its own (single-threaded) program, the channels run side by
    side on a thread pool. Without ``progress`` one call of
    :func:`~wardjax.texture._binned.run` does every iteration; with it, one
    call per iteration. Returns the ``C`` channels ``(1, 1, H W)`` (NumPy)
    and the KS distances ``(iterations + 1, C, B)``.
    """
    c, n_pix = pixel_q.shape[0], shapes[0][0] * shapes[0][1]
    noise = [rng.standard_normal((1, n_pix), dtype=np.float32) for _ in range(c)]  # the exact path's stream
    mesh = jax.sharding.Mesh(np.asarray(devices), ("channel",))
    split = jax.sharding.NamedSharding(mesh, jax.sharding.PartitionSpec("channel"))
    shared = jax.sharding.NamedSharding(mesh, jax.sharding.PartitionSpec())
    if len(devices) == 1 and devices[0].platform == "cpu":
        groups = [[ch] for ch in range(c)]  # one program per channel, side by side on the host's threads
    else:
        groups = [[min(ch, c - 1) for ch in range(-(-c // len(devices)) * len(devices))]]
    put = lambda a: jax.device_put(np.ascontiguousarray(a), split)
    masks = jax.device_put(_device_masks(shapes[0], len(shapes) - 1, "float32"), shared)
    probs = jax.device_put(np.asarray(probs64, np.float32), shared)
    tables, ds = [], []
    for chans in groups:
        tables.append(
            (
                tuple(put(_binned.quantile_lookup(band_q[chans, b], probs64)) for b in range(band_q.shape[1])),
                tuple(put(band_q[chans, b].astype(np.float32)) for b in range(band_q.shape[1])),
                put(_binned.quantile_lookup(pixel_q[chans], probs64)),
                masks,
                probs,
            )
        )
        ds.append(put(np.stack([noise[ch] for ch in chans])))

    b = band_q.shape[1]
    ks = [put(np.zeros((len(chans), iterations + 1, b), np.float32)) for chans in groups]
    # One call runs every iteration; with a progress bar, one call per iteration (the last also measures).
    spans = [(0, iterations + 1)] if progress is None else [(k, k + 1) for k in range(iterations - 1)]
    if progress is not None:
        spans.append((iterations - 1, iterations + 1))

    def step(g: int, first, last):
        out = _binned.run(ds[g], ks[g], first, last, *tables[g], shapes=shapes, mesh=mesh)
        return jax.block_until_ready(out)

    # Up to two threads a core: three channels on two cores keep both busy (the OS shares them out),
    # where a pool of two would leave one idle while the third channel runs alone.
    with concurrent.futures.ThreadPoolExecutor(min(len(groups), 2 * (os.cpu_count() or 1))) as pool:
        for lo, hi in spans:
            first, last = (jax.device_put(np.int32(v), shared) for v in (lo, hi))
            ds, ks = (list(x) for x in zip(*pool.map(lambda g: step(g, first, last), range(len(groups)))))
            if progress is not None:
                progress(min(hi, iterations), iterations)
    ks_host = np.concatenate([np.asarray(k, np.float64) for k in ks])[:c]  # (C, iterations + 1, B)
    host = np.concatenate([np.asarray(d) for d in ds])
    return [host[ch : ch + 1] for ch in range(c)], ks_host.transpose(1, 0, 2)


@texture_jit
def _channel_moments(ds):
    """Mean ``(C,)`` and covariance ``(C, C)`` (float64, divided by ``n``) of the channels ``ds``.

    Each channel is ``(1, 1, n)``.
    """
    x = jnp.concatenate([d.reshape(1, -1) for d in ds]).astype(jnp.float64)
    mu = x.mean(axis=1)
    x = x - mu[:, None]
    return mu, (x @ x.T) / x.shape[1]


def _decorrelation(cov: np.ndarray) -> np.ndarray:
    """Linear map ``W`` that removes the chance correlation between independently synthesised channels.

    ``W = T^{1/2} S^{−1/2}`` with ``S`` the channels' sample covariance and
    ``T = diag(S)``, applied to the centred channels: afterwards the covariance
    is exactly diagonal, each channel keeps its variance, and ``S^{−1/2}``
    (symmetric) is the whitening closest to the identity, so the channels
    change as little as possible. Without this, the RGB variance of a texture
    with strong low frequencies misses the source's by a few per cent (few
    independent samples of the coarse scales make the sample correlation of
    independent fields non-zero). Channels with (near) zero variance are left
    alone (identity rows and columns).
    """
    c = cov.shape[0]
    var = np.diag(cov).copy()
    w = np.eye(c)
    live = np.flatnonzero(var > 1e-12 * max(var.max(), np.finfo(np.float64).tiny))
    if live.size < 2:
        return w
    evals, evecs = np.linalg.eigh(cov[np.ix_(live, live)])
    w[np.ix_(live, live)] = np.sqrt(var[live])[:, None] * ((evecs / np.sqrt(evals)) @ evecs.T)
    return w


@texture_jit
def _to_rgb(ds, mix, offset, upper):
    """``clip(mix d + offset, 0, upper)`` per pixel, channels last: ``(n, K)`` float32."""
    d = jnp.concatenate([x.reshape(1, -1) for x in ds])
    rgb = jnp.einsum("kc,cn->nk", mix.astype(d.dtype), d) + offset.astype(d.dtype)[None]
    return jnp.clip(rgb, 0.0, upper.astype(d.dtype)[None])


def _check_args(model, shape, iterations, seed, match, sort) -> tuple[int, int]:
    """Refuse bad arguments of :func:`synthesize_texture` with one line each; the shape as two ints."""
    if not isinstance(model, TextureModel):
        raise TypeError(f"model must be a TextureModel, got {type(model).__name__}")
    try:
        hh, ww = (int(s) for s in shape)
    except (TypeError, ValueError):
        raise ValueError(f"shape={shape!r}, expected (height, width)") from None
    if (hh, ww) != tuple(shape) or min(hh, ww) < 1:
        raise ValueError(f"shape={shape!r}, expected two positive integers (height, width)")
    if hh * ww > _MAX_ROW:
        raise ValueError(f"shape={shape!r} has {hh * ww} pixels; at most 2**{_POSITION_BITS} can be synthesised")
    need = 2 ** (model.height + 2)
    if min(hh, ww) < need:
        raise ValueError(
            f"shape={shape!r} is too small for a texture analysed with {model.height} pyramid levels: "
            f"each side must be at least {need} pixels"
        )
    if isinstance(iterations, bool) or not isinstance(iterations, (int, np.integer)) or iterations < 1:
        raise ValueError(f"iterations={iterations!r}, expected an integer >= 1")
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ValueError(f"seed={seed!r}, expected an integer >= 0")
    if match not in MATCHES:
        raise ValueError(f"match={match!r}, expected 'binned' or 'exact'")
    if sort not in ("auto", "numpy", "xla"):
        raise ValueError(f"sort={sort!r}, expected 'auto', 'numpy' or 'xla'")
    return hh, ww


MATCHES = ("binned", "exact")


def synthesize_texture(
    model: TextureModel,
    shape: tuple[int, int],
    *,
    seed: int = 0,
    iterations: int = 5,
    rho_s=None,
    match: str = "binned",
    sort: str = "auto",
    devices=None,
    progress: Callable[[int, int], None] | None = None,
) -> SynthesisResult:
    """Synthesise a texture of any size from a :class:`TextureModel` (Heeger & Bergen 1995, paper section 4.2).

    Per decorrelated channel, starting from seeded Gaussian white noise whose
    pixels are matched to the model's pixel histogram, each iteration

    1. builds the steerable pyramid of the current image,
    2. matches every subband's histogram to the model's quantiles
       (``match``: Heeger & Bergen's binned CDFs and lookup, O(N), or the
       exact sort-based :func:`match_histogram`),
    3. collapses the pyramid and matches the pixel histogram.

    Channels are then mixed back to RGB (``x = V d + μ``) and clamped to
    ``[0, 1 − ρs]``, after a linear correction, closest to the identity, that
    removes the chance correlation between the independently synthesised
    channels (so RGB means and variances are the source's). Every step is circular (FFT pyramid on a periodic grid,
    pointwise histogram maps), so the result tiles seamlessly. The same seed,
    shape and model give the same image.

    Parameters
    ----------
    model
        From :func:`analyze_texture` or :meth:`TextureModel.load`.
    shape
        ``(height, width)`` in pixels, NumPy order (the CLI's ``--size`` is
        ``WIDTHxHEIGHT``); each side at least ``2 ** (model.height + 2)``.
    seed
        Seed of the noise (NumPy's ``default_rng``: the same image on every backend).
    iterations
        Histogram-matching iterations (≥ 1; the paper used 3).
    rho_s
        Override the model's specular reflectance for the clamp.
    match
        ``"binned"`` (default): the paper's histogram matching, binned
        cumulative histograms and a lookup table, O(N) per subband, in XLA
        (:mod:`wardjax.texture._binned`); the reported KS distances are read
        from the bin counts. ``"exact"``: rank matching by sorting, the
        sorted output equals the target quantiles (``sort`` picks where the
        sort runs). Both meet the same statistical bars (subband KS ≤ 0.05
        against the source, mean and variance within 2 %); ``"binned"`` is
        several times faster.
    sort
        For ``match="exact"``: ``"auto"`` (NumPy on CPU, XLA elsewhere),
        ``"numpy"`` or ``"xla"``; all give identical results.
    devices
        For ``match="binned"``: the JAX devices to spread the channels over
        (``NamedSharding`` over a 1-D mesh, channel axis); default
        ``jax.devices()``. Channels are independent, so the image is the same
        on one device or several.
    progress
        Called as ``progress(k, iterations)`` when iteration ``k`` is done (the
        CLI draws its progress bar with it).

    Returns
    -------
    SynthesisResult
    """
    hh, ww = _check_args(model, shape, iterations, seed, match, sort)
    devices = list(jax.devices() if devices is None else devices)
    if not devices or not all(isinstance(d, jax.Device) for d in devices):
        raise ValueError(f"devices={devices!r}, expected a non-empty sequence of jax.Device")
    c = model.channels
    rs = model.rho_s if rho_s is None else _rho_s_vector(rho_s, c)
    shapes = pyramid_shapes((hh, ww), model.height)

    with jax.enable_x64(True):
        tables = (
            np.asarray(model.band_quantiles, np.float64),
            np.asarray(model.pixel_quantiles, np.float64),
            np.asarray(model.probabilities, np.float64),
        )
        rng = np.random.default_rng(int(seed))
        if match == "binned":
            ds, ks = _heeger_bergen_binned(rng, *tables, shapes, iterations, progress, devices)
        else:
            masks = _device_masks((hh, ww), model.height, "float32")
            ds, ks = _heeger_bergen(rng, *tables, masks, shapes, iterations, cast(SortMethod, sort), progress)
        mu, cov = (np.asarray(a) for a in _channel_moments(ds))
        # x = V (μ + W (d − μ)) + m: decorrelate, back to RGB, clamp, in one pass over the pixels.
        mix = model.pca_basis @ _decorrelation(cov)
        offset = model.pca_basis @ mu - mix @ mu + model.pca_mean
        rgb = np.array(_to_rgb(tuple(ds), mix, offset, 1.0 - np.asarray(rs, np.float64))).reshape(hh, ww, c)
    return SynthesisResult(
        image=rgb,
        distance=ks[1:].max(axis=(1, 2)),
        band_distance=ks[1:],
        initial_distance=float(ks[0].max()),
        seed=int(seed),
    )
