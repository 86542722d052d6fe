"""Square-wave gratings on a phone screen: PPB ↔ cycles per degree, and the PNG set.

A grating of ``PPB`` pixels per bar has a period of ``2·PPB`` pixels, i.e.
``2·PPB·p`` millimetres on a screen of pixel pitch ``p = 25.4 / ppi``. Seen (directly or
in a mirror-like reflection) from a distance ``D`` along a line of sight that makes an
angle ``φ`` with the screen normal, one period centred on the line of sight subtends

.. math::

    \\theta = 2\\arctan\\frac{\\mathrm{PPB}\\,p\\cos\\varphi}{D}, \\qquad
    \\mathrm{CPD} = \\frac{1}{\\theta\\ [\\mathrm{deg}]}

(smartphone paper, section 5: iPhone 5s, 326 ppi, ``D`` = 19.1 in, ``φ`` = 0 gives
54.3 CPD at 1 PPB — the paper prints 54.2 — and 0.45 CPD at 120 PPB).
"""

from __future__ import annotations

import csv
import io
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._files import write_bytes_atomic, write_image
from ..capture import Display, Viewing, load_display, load_viewing

__all__ = [
    "cpd_to_ppb",
    "grating_image",
    "ppb_to_cpd",
    "write_gratings",
]


def _geometry(display, viewing) -> tuple[float, float]:
    d, v = load_display(display), load_viewing(viewing)
    if not v.eye_to_screen_mm > 0:
        raise ValueError(f"eye_to_screen_mm must be > 0; got {v.eye_to_screen_mm}")
    if not 0.0 <= v.screen_obliquity_deg < 90.0:
        raise ValueError(f"screen_obliquity_deg must be in [0, 90); got {v.screen_obliquity_deg}")
    if not d.ppi > 0:
        raise ValueError(f"ppi must be > 0; got {d.ppi}")
    return d.pixel_pitch_mm * np.cos(np.deg2rad(v.screen_obliquity_deg)), v.eye_to_screen_mm


def ppb_to_cpd(
    ppb: ArrayLike, display: str | Display = "iphone5s", viewing: str | Viewing = "paper"
) -> NDArray | np.floating:
    """Cycles per degree at the eye of a grating with ``ppb`` pixels per bar (any shape, > 0)."""
    p = np.asarray(ppb, dtype=np.float64)
    if np.any(~(p > 0)):
        raise ValueError(f"ppb must be > 0; got {ppb!r}")
    pitch, dist = _geometry(display, viewing)
    theta_deg = np.rad2deg(2.0 * np.arctan(p * pitch / dist))
    return 1.0 / theta_deg


def cpd_to_ppb(
    cpd: ArrayLike, display: str | Display = "iphone5s", viewing: str | Viewing = "paper"
) -> NDArray | np.floating:
    """Inverse of :func:`ppb_to_cpd` (continuous PPB)."""
    c = np.asarray(cpd, dtype=np.float64)
    if np.any(~(c > 0)):
        raise ValueError(f"cpd must be > 0; got {cpd!r}")
    pitch, dist = _geometry(display, viewing)
    return dist * np.tan(np.deg2rad(1.0 / c) / 2.0) / pitch


def grating_image(ppb: int, width_px: int, height_px: int, *, orientation: str = "vertical") -> NDArray:
    """Black/white square-wave grating, ``uint8 (height_px, width_px)``; bars ``ppb`` pixels wide.

    ``orientation="vertical"``: bars run top to bottom (period along x); ``"horizontal"``: along y.
    The first bar (at pixel 0) is white.
    """
    if isinstance(ppb, bool) or not isinstance(ppb, (int, np.integer)) or ppb < 1:
        raise ValueError(f"ppb must be an integer ≥ 1; got {ppb!r}")
    if orientation not in ("vertical", "horizontal"):
        raise ValueError(f"orientation must be 'vertical' or 'horizontal'; got {orientation!r}")
    n = width_px if orientation == "vertical" else height_px
    line = np.where((np.arange(n) // int(ppb)) % 2 == 0, 255, 0).astype(np.uint8)
    if orientation == "vertical":
        return np.broadcast_to(line[None, :], (height_px, width_px)).copy()
    return np.broadcast_to(line[:, None], (height_px, width_px)).copy()


def write_gratings(
    out_dir: str | Path,
    display: str | Display = "iphone5s",
    viewing: str | Viewing = "paper",
    *,
    orientation: str = "vertical",
) -> list[Path]:
    """Write the display's grating set ``grating_PPB.png`` (ppb_min…ppb_max) and ``gratings.csv``.

    The CSV lists each file with its PPB and the cycles per degree at the eye for
    ``viewing``. Returns the PNG paths, coarsest-bar last.
    """
    d, v = load_display(display), load_viewing(viewing)
    if orientation not in ("vertical", "horizontal"):
        raise ValueError(f"orientation={orientation!r}, expected 'vertical' or 'horizontal'")
    # every value computed (and every refusal made) before the first file is written
    rows = [(f"grating_{ppb:03d}.png", ppb, float(ppb_to_cpd(ppb, d, v))) for ppb in range(d.ppb_min, d.ppb_max + 1)]
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = []
    for name, ppb, _ in rows:
        path = out / name
        write_image(path, grating_image(ppb, d.width_px, d.height_px, orientation=orientation))
        paths.append(path)
    buf = io.StringIO()
    w = csv.writer(buf)
    w.writerow(["file", "ppb", "cycles_per_degree"])
    for name, ppb, cpd in rows:
        w.writerow([name, ppb, f"{cpd:.4f}"])
    write_bytes_atomic(out / "gratings.csv", buf.getvalue().encode())
    return paths
