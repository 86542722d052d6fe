"""The white-noise model of reconstructed BRDF values: what the sensor's noise becomes after the ratio."""

from __future__ import annotations

import numpy as np

__all__ = ["noise_columns"]


def noise_columns(level: np.ndarray, w: np.ndarray) -> np.ndarray:
    """The regressors of the white-noise variance at BRDF ``level`` and inverse irradiance ``w``: ``[w², f w, f²]``.

    The reconstruction divides the lit pixel ``v ∝ f E`` by the standard's
    ``∝ E`` (``E`` the lamp's irradiance, ``w ∝ 1/E``), so the sensor's
    read noise (``σ_v² = r²``) and shot noise (``σ_v² ∝ v``) reach the BRDF
    as ``r² w²`` and ``∝ f w``; a relative term (gain, flat field) as ``f²``.
    With ``σ²`` a function of ``f`` alone the whitened residuals of a clean
    simulated capture ran from 0.5 where the lamp is near to 2.2 where it is
    far (mean 1.05): the fit weighted them wrongly and the far end read as
    structure.
    """
    w = np.broadcast_to(w, np.shape(level))
    return np.stack([w * w, level * w, level * level], -1)
