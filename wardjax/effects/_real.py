"""Real data for the discovery workflow: the smartphone paper's Table 1 and CUReT.

Table 1 (smartphone paper, section 6, Fig. 8a)
    Measured lobe SD (Table 1a, degrees) against threshold PPB (Table 1b) for
    the NCS gloss standards at gloss 95, 75, 50, 30 — the range the paper
    fits (it distrusts the lobe SDs at gloss 12 and 6) — and four
    lightnesses with ρd 0.853, 0.485, 0.245, 0.010 (section 7). Noise: the
    threshold is the mean of three observers whose log-threshold SD
    ``σ_obs`` is the one :mod:`wardjax._alpha_model` estimates from Table 1
    itself, plus the quantisation of a mean of three integer PPBs; it is
    carried into SD units through the pooled slope ``b``::

        σ_SD = b · PPB · sqrt(σ_obs²/3 + 1/(36 PPB²))

CUReT (Dana, van Ginneken, Nayar, Koenderink, ACM TOG 18(1), 1999)
    61 samples × 205 BRDF values averaged over RGB, with each measurement's
    viewing and illumination directions (``calibration/curet/``, shipped with the package). The noise is
    not published; it is estimated per sample from the scatter between
    measurements whose direction pairs are nearest neighbours (a relative
    error, an upper bound since the BRDF also changes between neighbours).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .._data import calibration_path
from ._models import ScanlineData, ThresholdData, scanline_data, threshold_data

__all__ = ["table1_threshold_data", "load_curet", "curet_data", "CURET_DIR"]

CURET_DIR = calibration_path("curet")


def table1_threshold_data() -> ThresholdData:
    """Table 1a/1b of the smartphone paper (gloss 95–30) as :class:`ThresholdData`."""
    from ..smartphone import load_table1, physical_lines
    from ..smartphone._alpha_model import GLOSS_ORDER, NCS_ORDER, PHYSICAL_GLOSS

    t = load_table1()
    cols = [GLOSS_ORDER.index(g) for g in PHYSICAL_GLOSS]
    ppb = t["ppb"][:, cols]
    sd = t["lobe_sd_deg"][:, cols]
    rho = np.broadcast_to(t["rho_d"][:, None], ppb.shape)
    grp = np.broadcast_to(np.arange(4)[:, None], ppb.shape)
    x, y = ppb.ravel(), sd.ravel()
    b = np.polyfit(x, y, 1)[0]
    s_obs = physical_lines().sigma_obs
    sigma = b * x * np.sqrt(s_obs**2 / 3.0 + 1.0 / (36.0 * x**2))
    return threshold_data(x, y, sigma, rho.ravel(), grp.ravel(), labels=NCS_ORDER)


def load_curet(folder: str | Path | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Read CUReT's ``abrdf.dat`` and ``table.txt``.

    Returns
    -------
    sample_ids : (61,) int
    brdf : (61, 205) float
    wi, wo : (205, 3) unit directions to light and camera (z = normal).
    """
    d = Path(folder) if folder is not None else CURET_DIR
    for name in ("abrdf.dat", "table.txt"):
        if not (d / name).is_file():
            raise FileNotFoundError(f"{d / name}: CUReT file missing (see calibration/curet/README.md)")
    a = np.loadtxt(d / "abrdf.dat")
    t = np.loadtxt(d / "table.txt")
    if a.ndim != 2 or a.shape[1] != 206 or t.shape != (205, 5):
        raise ValueError(
            f"{d}: expected abrdf.dat rows of 1 + 205 values and a 205 × 5 table.txt, got {a.shape} and {t.shape}"
        )

    def unit(theta, phi):
        return np.stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)], -1)

    wo = unit(t[:, 1], t[:, 2])
    wi = unit(t[:, 3], t[:, 4])
    return a[:, 0].astype(int), a[:, 1:], wi, wo


def curet_noise(brdf: np.ndarray, wi: np.ndarray, wo: np.ndarray) -> float:
    """Relative noise of one sample from nearest-neighbour differences in direction space.

    For each measurement the nearest other direction pair (distance
    ``|Δwi|² + |Δwo|²``, reciprocity taken into account) gives
    ``log f_a − log f_b``; half the median of their squares (a robust variance
    of a difference of two values) estimates the relative variance.
    """
    x1 = np.concatenate([wi, wo], -1)
    x2 = np.concatenate([wo, wi], -1)
    d = np.minimum(((x1[:, None] - x1[None]) ** 2).sum(-1), ((x1[:, None] - x2[None]) ** 2).sum(-1))
    np.fill_diagonal(d, np.inf)
    nn = np.argmin(d, axis=1)
    lf = np.log(np.maximum(brdf, 1e-6))
    diff = lf - lf[nn]
    return float(np.sqrt(np.median(diff**2) / 0.4549 / 2.0))  # median of χ²₁ is 0.4549


def curet_data(index: int, folder: str | Path | None = None) -> tuple[ScanlineData, float, int]:
    """One CUReT sample as :class:`ScanlineData` (one "scanline" of 205 values, one channel).

    Returns the data, the relative noise used and the sample number.
    """
    ids, brdf, wi, wo = load_curet(folder)
    if not 0 <= index < len(ids):
        raise ValueError(f"index must be in 0..{len(ids) - 1}, got {index}")
    f = brdf[index]
    rel = curet_noise(f, wi, wo)
    sigma = rel * np.abs(f)
    data = scanline_data(f[None, :, None], wi[None], wo[None], sigma[None, :, None], kind="brdf")
    return data, rel, int(ids[index])
