"""``wardjax diagnose`` on a photograph capture: its problems as discovery reads them, the discovery, the report.

The problems are those :func:`~wardjax.run.fit_photo_capture` fits (blocks
of ``[fit] block``² pixels sharing ρd, each with its views in every photo);
the radial covariates come from the photos' geometry
(:func:`wardjax.effects._photo_model.photo_covariates`: the camera looks at
``[camera] look_at`` of a flash capture, at the sample's centre otherwise).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from ..capture import FlashFile, PhotoCapture
from ..effects._photo_model import PhotoData, photo_covariates
from ._fit_photo import to_problems

__all__ = ["diagnose_photo_capture", "diagnose_photo_cli", "photo_data"]


def photo_data(cap: PhotoCapture) -> PhotoData:
    """The :class:`~wardjax.effects._photo_model.PhotoData` of a loaded flash or multiview capture."""
    h, w, k, _ = cap.f_r.shape
    b = cap.config.fit.block
    hh, ww = (h // b) * b, (w // b) * b
    if hh == 0 or ww == 0:
        from ..capture import CAPTURE_FILE, CaptureError

        raise CaptureError(CAPTURE_FILE, "fit.block", f"{b} is larger than the {w}×{h} pixels fitted")
    crop = (slice(0, hh), slice(0, ww))
    cfg = cap.config
    target = np.zeros(3)
    if isinstance(cfg, FlashFile) and cfg.camera.position is not None:
        target = np.asarray(cfg.camera.look_at, np.float64)
    r2, cos_psi, offset = photo_covariates(cap.points[crop], cap.wi[crop], cap.wo[crop], cap.mask[crop], target)
    sig, m = cap.sigma[crop], cap.mask[crop]
    wgt = np.where(m[..., None] & (sig > 0), 1.0 / np.where(sig > 0, sig, 1.0) ** 2, 0.0)
    i, j = np.mgrid[0:hh, 0:ww]
    fold = np.broadcast_to(((i + j)[..., None] + np.arange(k)) % 2, (hh, ww, k))
    column = (np.arange(ww // b) + 0.5) / (ww // b)
    return PhotoData(
        f=to_problems(np.nan_to_num(cap.f_r[crop]), b),
        w=to_problems(wgt, b),
        wi=to_problems(cap.wi[crop], b),
        wo=to_problems(cap.wo[crop], b),
        radius2=to_problems(r2, b),
        lamp_cos=to_problems(cos_psi, b),
        column=np.tile(column, hh // b),
        fold=to_problems(np.ascontiguousarray(fold), b),
        grid=(hh // b, ww // b, b),
        lamp_offset=offset,
        normalization=cfg.fit.normalization,
    )


def diagnose_photo_capture(
    cap: PhotoCapture, *, max_steps: int = 4, progress: Callable[[str], object] = lambda _: None
):
    """Discovery on a photograph capture: :func:`wardjax.effects.discover_photo` on :func:`photo_data`."""
    from ..effects import discover_photo

    progress("building the problems (blocks of pixels, their views) and the radial covariates")
    data = photo_data(cap)
    progress("baseline fit (the paper's model: ρd per block, one shared lobe)")
    return discover_photo(data, max_steps=max_steps, progress=progress, name=cap.name)


def diagnose_photo_cli(cap: PhotoCapture, out_dir, *, max_steps: int, progress: Callable[[str], object]):
    """``wardjax diagnose`` of a photograph capture: the discovery, its report written into ``out_dir``."""
    rep = diagnose_photo_capture(cap, max_steps=max_steps, progress=progress)
    progress("writing report.json, report.md, gap.png, residual.png and the label image")
    rep.save(out_dir)
    return rep
