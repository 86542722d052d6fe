"""A folder of fits as a table: one row per capture, its parameters ± σ, and the outliers of the batch."""

from __future__ import annotations

import json
from pathlib import Path
from typing import NamedTuple

import numpy as np

__all__ = ["PARAMETERS", "CaptureResult", "flag_outliers", "load_chains", "load_fits", "split_rhat"]

# The parameters compared across captures (ρd as its mean over RGB).
PARAMETERS = ("rho_d", "rho_s", "alpha_x", "alpha_y")
# Robust z beyond which a capture's parameter is flagged: |x − median| / (1.4826 MAD).
OUTLIER_Z = 3.5
MIN_CAPTURES_FOR_OUTLIERS = 4


class CaptureResult(NamedTuple):
    """One capture's fit, as ``wardjax fit`` wrote it.

    Attributes
    ----------
    name
        The capture's name (its output folder).
    folder
        The output folder: ``params.json`` and the images beside it.
    doc
        The parsed ``params.json`` (schema ``wardjax.params/1``).
    """

    name: str
    folder: Path
    doc: dict

    def value(self, key: str) -> tuple[float, float]:
        """``(value, 1-σ)`` of a parameter; ``rho_d`` is the mean over RGB."""
        v, e = self.doc["params"][key], self.doc["stderr"][key]
        if key == "rho_d":
            return float(np.mean(v)), float(np.sqrt(np.mean(np.square(e))))
        return float(v), float(e)


def load_fits(fits_dir) -> list[CaptureResult]:
    """Every finished capture under ``fits_dir`` (a folder holding ``params.json``), sorted by name.

    Raises
    ------
    ValueError
        ``fits_dir`` is not a folder, or holds no finished capture.
    """
    root = Path(fits_dir)
    if not root.is_dir():
        raise ValueError(f"{root}: not a folder (give the --out folder of wardjax fit)")
    out = []
    for params in sorted(root.glob("*/params.json")):
        try:
            doc = json.loads(params.read_text(encoding="utf-8"))
        except (UnicodeDecodeError, json.JSONDecodeError) as e:
            raise ValueError(f"{params}: not valid JSON ({e})") from None
        if doc.get("schema") != "wardjax.params/1":
            raise ValueError(f"{params}: schema {doc.get('schema')!r}, expected 'wardjax.params/1'")
        out.append(CaptureResult(params.parent.name, params.parent, doc))
    if not out:
        raise ValueError(f"{root}: no finished capture (no <capture>/params.json); run wardjax fit --out {root} first")
    return out


def flag_outliers(results: list[CaptureResult]) -> dict[str, set[str]]:
    """Parameters of each capture more than 3.5 robust σ from the batch median.

    ``z = (x − median) / (1.4826 · MAD)`` over the captures of the batch, per
    parameter; with fewer than four captures nothing is flagged (a median of
    two or three says little). A parameter whose MAD is 0 flags nothing.
    """
    flags: dict[str, set[str]] = {r.name: set() for r in results}
    if len(results) < MIN_CAPTURES_FOR_OUTLIERS:
        return flags
    for key in PARAMETERS:
        x = np.array([r.value(key)[0] for r in results])
        med = np.median(x)
        mad = 1.4826 * np.median(np.abs(x - med))
        if not mad > 0:
            continue
        for r, z in zip(results, np.abs(x - med) / mad):
            if z > OUTLIER_Z:
                flags[r.name].add(key)
    return flags


def load_chains(result: CaptureResult) -> dict[str, np.ndarray] | None:
    """The α posterior's stored chains (``posterior.npz``: ``(steps, walkers)`` per parameter), if any."""
    path = result.folder / "posterior.npz" if result.folder is not None else None
    if path is None or not path.is_file():
        return None
    with np.load(path) as z:
        return {k: z[k] for k in z.files}


def split_rhat(chains) -> float:
    r"""Split-:math:`\hat R` of one parameter's chains ``(steps, walkers)`` (Gelman et al., BDA3, §11.4).

    Each walker's chain is cut in halves, giving ``m = 2W`` chains of length
    ``n``; with ``B`` ``n`` times the variance of their means and ``W̄`` the mean
    of their variances,

    .. math:: \hat R = \sqrt{\frac{(n-1)/n\,\bar W + B/n}{\bar W}}.

    It tends to 1 as the chains lengthen: about ``√(1 + τ/n)`` for mixed
    half-chains of ``n`` steps and integrated autocorrelation time ``τ`` (the
    variance of a chain's mean is ``τ/n`` of the parameter's), so an ensemble
    whose walkers are each 50 τ long reads about 1.02. Well above that
    (> 1.1), some walkers have not reached the posterior or still drift.
    """
    x = np.asarray(chains, np.float64)
    n = x.shape[0] // 2
    if n < 2:
        return float("nan")
    halves = np.concatenate([x[:n], x[n : 2 * n]], axis=1)  # (n, 2W)
    w = np.mean(np.var(halves, axis=0, ddof=1))
    b = n * np.var(np.mean(halves, axis=0), ddof=1)
    return float(np.sqrt(((n - 1) / n * w + b / n) / w)) if w > 0 else float("nan")
