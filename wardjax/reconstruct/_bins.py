"""Binning a reconstruction for the fit: ``b × b`` bins, image columns as scanlines."""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from ._band import Reconstruction

__all__ = ["MIN_SCANLINE_SAMPLES", "ScanlineBinner", "ScanlineBins", "bin_layout", "bin_scanlines", "bin_sums"]

# A scanline (image column) with fewer usable bins than this is not fitted.
MIN_SCANLINE_SAMPLES = 8


def _block_sum(a: np.ndarray, b: int) -> np.ndarray:
    h, w = a.shape[:2]
    return a.reshape(h // b, b, w // b, b, *a.shape[2:]).sum(axis=(1, 3))


def _pad_to(a: np.ndarray, b: int, fill) -> np.ndarray:
    h, w = a.shape[:2]
    ph, pw = (-h) % b, (-w) % b
    if ph == 0 and pw == 0:
        return a
    pad = [(0, ph), (0, pw)] + [(0, 0)] * (a.ndim - 2)
    return np.pad(a, pad, constant_values=fill)


def bin_sums(a: np.ndarray, b: int) -> np.ndarray:
    """Sums of ``a`` over ``b × b`` bins, float64: ``(H, W, ...)`` → ``(⌈H/b⌉, ⌈W/b⌉, ...)``, padded with zeros."""
    return _block_sum(_pad_to(a, b, 0).astype(np.float64), b)


class ScanlineBins(NamedTuple):
    """What :func:`bin_scanlines` returns: the probe binned ``b × b``, image columns as scanlines.

    Attributes
    ----------
    f_r
        ``(S, N, 3)`` float64 bin means of ``f_r``; NaN where fewer than half
        of the bin's pixels carry a value. Where :attr:`censored`, a lower
        bound (see :func:`bin_scanlines`).
    censored
        ``(S, N, 3)`` bool: the bin holds a clipped pixel; its value bounds the true mean from below.
    wi, wo
        ``(S, N, 3)`` unit bin-mean directions (material frame); ``(0, 0, 1)`` off the probe.
    points
        ``(S, N, 3)`` bin-mean sample-plane positions (mm) of the probe pixels.
    b
        The bin size (pixels).
    box
        Row and column slices of the probe's bounding box in the image.
    """

    f_r: np.ndarray
    censored: np.ndarray
    wi: np.ndarray
    wo: np.ndarray
    points: np.ndarray
    b: int
    box: tuple[slice, slice]


def bin_layout(probe: np.ndarray, max_samples: int) -> tuple[tuple[slice, slice], int]:
    """The probe's bounding box and the bin size ``b = ⌈√(n_probe / max_samples)⌉`` of :func:`bin_scanlines`."""
    n_probe = int(probe.sum())
    rows = np.flatnonzero(probe.any(axis=1))
    colz = np.flatnonzero(probe.any(axis=0))
    box = (slice(rows[0], rows[-1] + 1), slice(colz[0], colz[-1] + 1))
    return box, max(1, math.ceil(math.sqrt(n_probe / max_samples)))


class ScanlineBinner:
    """:func:`bin_scanlines` fed band by band: the block sums of each band kept, its pixels not.

    Bands (see :func:`~wardjax.reconstruct.reconstruct_bands`) are given in
    order, each over the box's columns, starting at the box's first row plus a
    multiple of ``b`` and holding a multiple of ``b`` rows (the last one any);
    the result is that of :func:`bin_scanlines` on the whole reconstruction.
    """

    def __init__(self, probe: np.ndarray, box: tuple[slice, slice], b: int) -> None:
        self.probe, self.box, self.b = probe, box, b
        self.sums: dict[str, list[np.ndarray]] = {}

    def _total(self, a: np.ndarray, fill) -> np.ndarray:  # block sums over the b × b bins, float64
        return _block_sum(_pad_to(a, self.b, fill).astype(np.float64), self.b)

    def add(self, rows: slice, f_r, wi, wo, points, f_clip=None) -> None:
        """Add the band of image ``rows`` (values over the box's columns)."""
        total, keep = self._total, self.sums.setdefault
        fin = np.isfinite(f_r)
        keep("n_f", []).append(total(fin, False))
        keep("s_f", []).append(total(np.where(fin, f_r, 0.0), 0.0))
        if f_clip is not None:
            cin = np.isfinite(f_clip)
            keep("n_c", []).append(total(cin, False))
            keep("s_c", []).append(total(np.where(cin, f_clip, 0.0), 0.0))
        keep("n_p", []).append(total(self.probe[rows, self.box[1]], False))
        keep("wi", []).append(total(wi, 0.0))
        keep("wo", []).append(total(wo, 0.0))
        keep("p", []).append(total(np.nan_to_num(points), 0.0))

    def result(self) -> ScanlineBins:
        """The bins of every band added (see :func:`bin_scanlines`)."""
        t = {k: np.concatenate(v, axis=0) for k, v in self.sums.items()}
        b = self.b
        half = max(1.0, b * b / 2)
        n_f, s_f = t["n_f"], t["s_f"]
        f_bin = np.where(n_f >= half, s_f / np.maximum(n_f, 1), np.nan)
        cens = np.zeros(f_bin.shape, bool)
        if "n_c" in t:
            n_c = t["n_c"]
            cens = (n_c > 0) & (n_f + n_c >= half)
            f_bin = np.where(cens, (s_f + t["s_c"]) / np.maximum(n_f + n_c, 1), f_bin)
        n_p = np.maximum(t["n_p"], 1)[..., None]
        wi_bin, wo_bin = t["wi"] / n_p, t["wo"] / n_p
        for d in (wi_bin, wo_bin):
            nrm = np.linalg.norm(d, axis=-1, keepdims=True)
            d /= np.where(nrm > 0, nrm, 1.0)
            d[nrm[..., 0] == 0] = (0.0, 0.0, 1.0)
        p_bin = t["p"] / n_p
        scan = lambda a: np.ascontiguousarray(a.transpose(1, 0, 2))
        return ScanlineBins(scan(f_bin), scan(cens), scan(wi_bin), scan(wo_bin), scan(p_bin), b, self.box)


def bin_scanlines(rec: Reconstruction, max_samples: int) -> ScanlineBins:
    r"""Bin a reconstruction's probe ``b × b`` (at most ``max_samples`` bins), image columns as scanlines.

    ``b = ⌈√(n_probe / max_samples)⌉``; the probe's bounding box is padded to
    a multiple of ``b``. Per bin and channel, with ``E`` its exact values
    (finite ``f_r``) and ``C`` its clip bounds (finite ``f_clip``, when the
    reconstruction has them):

    * no clipped pixel: the mean of ``E`` if ``|E| ≥ b²/2``, else NaN;
    * a clipped pixel (``|C| ≥ 1``, ``|E| + |C| ≥ b²/2``): *censored*, the
      value ``(Σ_E f + Σ_C f_clip)/(|E| + |C|)``. Each ``f_clip`` bounds its
      pixel's true value from below, so this bounds the bin's true mean from
      below: a bin of mixed clipped and unclipped pixels is censored, never
      the mean of its unclipped pixels alone (that would drop the brightest).

    Directions and positions are the means over the bin's probe pixels, the
    directions renormalised. :class:`ScanlineBinner` does the same band by band.
    """
    box, b = bin_layout(rec.probe, max_samples)
    binner = ScanlineBinner(rec.probe, box, b)
    clip = None if rec.f_clip is None else rec.f_clip[box]
    binner.add(box[0], rec.f_r[box], rec.wi[box], rec.wo[box], rec.points[box], clip)
    return binner.result()
