"""What a scanline capture must show before anything is fitted to it: the probe seen, not clipped, measured.

``wardjax fit`` (:func:`wardjax.fit_capture`) and ``wardjax diagnose``
(:func:`wardjax.effects.capture_data`) apply the same checks, so that a
capture one of them refuses is refused by the other with the same line:

* :func:`check_probe`, after :func:`~wardjax.reconstruct.prepare_bands`: some
  pixel sees the probe, and at most :data:`~wardjax._rules.MAX_CLIPPED_FRACTION`
  of the probe's pixels are clipped in their own lit value (the value
  measured there is the clip level, not the surface);
* :func:`check_measured`, after the reconstruction: some probe pixel holds a
  BRDF value (lamp signal above the noise floor, mirror point on the standard,
  nothing clipped); if none does, the reason most pixels were masked for is named.
"""

from __future__ import annotations

import numpy as np

from .._rules import MAX_CLIPPED_FRACTION
from ..capture import CAPTURE_FILE, CaptureError
from ._band import BandSetup
from ._reference import MaskReason

__all__ = ["check_measured", "check_probe", "clipped_fraction", "mask_counts"]


def clipped_fraction(cap, setup: BandSetup, band_rows: int) -> float:
    """The fraction of probe pixels whose own lit value is clipped, from the codes of the probe's box band by band."""
    if setup.box is None:
        return 0.0
    rows_p, cols = setup.box
    n, step = 0, max(1, band_rows)
    for r0 in range(rows_p.start, rows_p.stop, step):
        rows = slice(r0, min(r0 + step, rows_p.stop))
        n += int(np.count_nonzero(cap.images.clipped(rows, cols).any(axis=-1) & setup.probe[rows, cols]))
    return n / max(int(setup.probe.sum()), 1)


def check_probe(cap, setup: BandSetup, band_rows: int) -> None:
    """Refuse a capture whose image does not see the probe, or whose probe is clipped over more than half its pixels.

    Raises
    ------
    CaptureError
        Naming ``capture.toml``'s ``camera`` (no pixel sees the probe) or the lit image (clipped).
    """
    if not setup.probe.any():
        raise CaptureError(
            CAPTURE_FILE,
            "camera",
            "no pixel of the image sees the probe; check rig.camera, camera.look_at and regions.probe",
        )
    sat = clipped_fraction(cap, setup, band_rows)
    if sat > MAX_CLIPPED_FRACTION:
        raise CaptureError(
            cap.config.images.lit,
            None,
            f"{sat:.0%} of the probe's pixels are saturated (at the largest code); reduce the exposure",
        )


def mask_counts(probe: np.ndarray, flags: np.ndarray) -> dict[str, int]:
    """Probe pixels masked for each :class:`~wardjax.MaskReason`, by name in lower case; probe, flags: (H, W)."""
    return {name.lower(): int(np.sum(probe & ((flags & r) != 0))) for name, r in MaskReason.__members__.items()}


def check_measured(cap, counts: dict[str, int], n_valid: int) -> None:
    """Refuse a capture in which no probe pixel holds a BRDF value (``n_valid == 0``), naming why most were masked.

    ``counts`` are :func:`mask_counts` of the probe.
    """
    if n_valid > 0:
        return
    worst = max(counts, key=lambda reason: counts[reason])
    why = {
        "off_standard": "no probe pixel has its mirror point on the standard (check regions and the rig)",
        "saturated": "every probe pixel or its mirror point is saturated; reduce the exposure",
        "below_noise": f"the lamp signal (lit − dark) is below the noise floor ({cap.config.fit.noise_floor}) "
        "everywhere on the probe or the standard; check the exposure and the lamp",
        "nonfinite": "the pixel values are not finite",
    }[worst]
    raise CaptureError(cap.config.images.lit, None, f"no usable probe pixel: {why}")
