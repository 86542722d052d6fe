"""Binned structure test of whitened residuals against one covariate, and each covariate's name and unit.

Shared by the search (``_discover``: which covariate shows structure, what is
left unexplained) and the report's plots (``_report``: binned means before and
after a step), so it lives apart from both and neither imports the other;
so do the covariates' labels, which both print.
"""

from __future__ import annotations

import numpy as np
from scipy.special import chdtrc  # χ² survival function (what scipy.stats.chi2.sf calls), without importing scipy.stats

_N_BINS = 20


def quantile_bins(x: np.ndarray, n_bins: int = _N_BINS) -> tuple[np.ndarray, int]:
    """Each value's bin ``(n,)`` and the number of bins: ``n_bins`` quantile bins of ``x`` (finite, ``(n,)``; fewer
    where there are few values), or one bin per value of a categorical covariate such as the channel."""
    nb = int(max(2, min(n_bins, x.size // 4)))
    ux = np.unique(x)
    if ux.size <= nb:
        return np.searchsorted(ux, x), int(ux.size)
    edges = np.quantile(x, np.linspace(0, 1, nb + 1))
    return np.clip(np.searchsorted(edges, x, side="right") - 1, 0, nb - 1), nb


def _binned_test(r, x, n_bins=_N_BINS):
    """Structure of whitened residuals ``r`` against covariate ``x``: (χ², dof, p, bin centres, means, sems).

    The residuals are averaged in quantile bins of ``x`` (one bin per value
    for a categorical covariate such as the channel); under pure noise
    ``Σ n_b r̄_b²`` is ``χ²`` with one degree of freedom per non-empty bin.
    """
    ok = np.isfinite(r) & np.isfinite(x)
    r, x = r[ok], x[ok]
    bins, nb = quantile_bins(x, n_bins)
    cnt = np.bincount(bins, minlength=nb).astype(float)
    s = np.bincount(bins, weights=r, minlength=nb)
    keep = cnt > 0
    mean = np.where(keep, s / np.maximum(cnt, 1), np.nan)
    xc = np.bincount(bins, weights=x, minlength=nb) / np.maximum(cnt, 1)
    chi2 = float(np.nansum(cnt[keep] * mean[keep] ** 2))
    dof = int(keep.sum())
    p = float(chdtrc(dof, chi2)) if dof > 0 else 1.0
    return chi2, dof, p, xc[keep], mean[keep], 1.0 / np.sqrt(cnt[keep])


# name → (what it is, unit or "" when dimensionless)
COVARIATE_LABELS: dict[str, tuple[str, str]] = {
    "theta_h": ("half-vector angle from the normal θh", "deg"),
    "half_azimuth": ("half-vector azimuth φh", "deg"),
    "theta_d": ("difference angle θd (half vector to light)", "deg"),
    "psi": ("angle between light and view ψ", "deg"),
    "theta_i": ("incidence angle θi", "deg"),
    "theta_o": ("viewing angle θo", "deg"),
    "emission_angle": ("screen emission angle", "deg"),
    "scanline": ("scanline index", ""),
    "channel": ("colour channel (0 R, 1 G, 2 B)", ""),
    "log_f": ("ln(predicted f_r / f_r of the standard)", "natural log"),
    "inv_irradiance": ("1 / irradiance", "relative"),
    "x": ("image column along the scanline", "px"),
    "row": ("image row", "px"),
    "column": ("image column", "px"),
    "radius": ("distance from the image centre", "px"),
    "rho_d": ("diffuse reflectance ρd", "dimensionless"),
    "ppb": ("threshold", "pixels per bar"),
    "rho_d_x_ppb": ("ρd × threshold", "pixels per bar"),
}


def covariate_label(name: str) -> str:
    """Axis label: ``"viewing angle θo (deg)"``; an unknown name is returned as it is."""
    what, unit = COVARIATE_LABELS.get(name, (name, ""))
    return f"{what} ({unit})" if unit else what


def covariate_value(name: str, value: float) -> str:
    """``"θo = 32 deg"``-style text: the covariate's name, its value to 3 digits and its unit."""
    _, unit = COVARIATE_LABELS.get(name, (name, ""))
    return f"{name} = {value:.3g}" + (f" {unit}" if unit and unit != "dimensionless" else "")
