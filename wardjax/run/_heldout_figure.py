"""``heldout.png``: a held-out photo, its prediction and the residual, each with axes in pixels and a colour bar.

The photo and the prediction are drawn on one scale: the mean of the
channels of the linear pixel values (full scale 1, before the photos'
encoding), with the same colour limits on both panels. The residual is drawn
in units of the pixel noise:

.. math::

    z = \\frac{1}{\\sqrt{C}} \\sum_c \\frac{v_\\text{pred}[c] - v_\\text{photo}[c]}{σ_v[c]}

(``σ_v`` the noise model's σ of each linear value, ``C`` the channels), which
has unit variance where the prediction is right and the noise model holds;
its colour limits are symmetric, at least ±3.
"""

from __future__ import annotations

import io

import numpy as np

__all__ = ["heldout_figure", "heldout_png"]

_Z_MIN = 3.0  # the residual's colour bar spans at least ±3 σ


def _residual_z(held) -> np.ndarray:
    """``(H, W)`` the channel-summed residual over its noise (NaN where the photo was not compared)."""
    sigma = np.asarray(held.sigma, np.float64)
    with np.errstate(invalid="ignore", divide="ignore"):
        z = np.where(sigma > 0, held.residual / sigma, np.nan)
    return np.sum(z, -1) / np.sqrt(z.shape[-1])


def heldout_figure(held):
    """The figure of a :class:`~wardjax.run.HeldOut` ``held``: photo | prediction | residual."""
    from matplotlib.figure import Figure

    photo = np.mean(held.photo, -1)
    pred = np.mean(held.prediction, -1)
    both = np.concatenate([photo[np.isfinite(photo)], pred[np.isfinite(pred)]])
    lo, hi = (float(np.min(both)), float(np.max(both))) if both.size else (0.0, 1.0)
    z = _residual_z(held)
    zf = np.abs(z[np.isfinite(z)])
    zlim = max(_Z_MIN, float(np.percentile(zf, 99))) if zf.size else _Z_MIN
    h, w = photo.shape
    fig = Figure(figsize=(3.6 * 3 * max(w / max(h, 1), 0.6) ** 0.5 + 1.0, 3.4), dpi=100, layout="constrained")
    axes = fig.subplots(1, 3)
    linear = "linear value (mean of channels, full scale 1)"
    panels = (
        (photo, f"photo {held.k} ({held.name})", "gray", (lo, hi), linear),
        (pred, "prediction from the other photos", "gray", (lo, hi), linear),
        (
            z,
            f"residual, RMSE {held.rmse_linear / held.rmse_noise:.2f}× noise",
            "RdBu_r",
            (-zlim, zlim),
            "(prediction − photo) / σ (noise σ)",
        ),
    )
    for ax, (img, title, cmap, (vmin, vmax), unit) in zip(axes, panels):
        im = ax.imshow(img, cmap=cmap, vmin=vmin, vmax=vmax, interpolation="nearest")
        ax.set_title(title, fontsize=9)
        ax.set_xlabel("x (pixels)")
        ax.set_ylabel("y (pixels)")
        fig.colorbar(im, ax=ax, shrink=0.85).set_label(unit, fontsize=8)
    return fig


def heldout_png(held) -> bytes:
    """``heldout.png`` as PNG bytes (:func:`heldout_figure` rendered)."""
    buf = io.BytesIO()
    heldout_figure(held).savefig(buf, format="png", dpi=100)
    return buf.getvalue()
