"""Binned structure test of whitened residuals against one covariate.

Shared by the search (``_discover``: which covariate shows structure, what is
left unexplained) and the report's plots (``_report``: binned means before and
after a step), so it lives apart from both and neither imports the other.
"""

from __future__ import annotations

import numpy as np
from scipy.special import chdtrc  # χ² survival function (what scipy.stats.chi2.sf calls), without importing scipy.stats

_N_BINS = 20


def _binned_test(r, x, n_bins=_N_BINS):
    """Structure of whitened residuals ``r`` against covariate ``x``: (χ², dof, p, bin centres, means, sems).

    The residuals are averaged in quantile bins of ``x`` (one bin per value
    for a categorical covariate such as the channel); under pure noise
    ``Σ n_b r̄_b²`` is ``χ²`` with one degree of freedom per non-empty bin.
    """
    ok = np.isfinite(r) & np.isfinite(x)
    r, x = r[ok], x[ok]
    n = r.size
    nb = int(max(2, min(n_bins, n // 4)))
    ux = np.unique(x)
    if ux.size <= nb:  # categorical covariate (channel)
        bins = np.searchsorted(ux, x)
        nb = ux.size
    else:
        edges = np.quantile(x, np.linspace(0, 1, nb + 1))
        bins = np.clip(np.searchsorted(edges, x, side="right") - 1, 0, nb - 1)
    cnt = np.bincount(bins, minlength=nb).astype(float)
    s = np.bincount(bins, weights=r, minlength=nb)
    keep = cnt > 0
    mean = np.where(keep, s / np.maximum(cnt, 1), np.nan)
    xc = np.bincount(bins, weights=x, minlength=nb) / np.maximum(cnt, 1)
    chi2 = float(np.nansum(cnt[keep] * mean[keep] ** 2))
    dof = int(keep.sum())
    p = float(chdtrc(dof, chi2)) if dof > 0 else 1.0
    return chi2, dof, p, xc[keep], mean[keep], 1.0 / np.sqrt(cnt[keep])
