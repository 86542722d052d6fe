"""Access to the plain-file data shipped in ``calibration/``."""

from __future__ import annotations

import csv
from importlib import resources
from pathlib import Path

from .ward import WardParams

__all__ = ["calibration_path", "table1_materials"]


def calibration_path(name: str) -> Path:
    """Path of a file in ``calibration/`` (installed as package data or beside the source)."""
    here = Path(__file__).resolve().parent
    for root in (here / "calibration", here.parent / "calibration"):
        if (root / name).exists():
            return root / name
    pkg = resources.files("wardjax") / "calibration" / name
    if pkg.is_file():
        return Path(str(pkg))
    raise FileNotFoundError(f"calibration file {name!r} not found beside the wardjax package")


def table1_materials() -> dict[str, WardParams]:
    """The desk and marble of the image-based paper's Table 1 (grey ρd)."""
    with open(calibration_path("table1_image_based.csv"), encoding="utf-8") as fh:
        rows = [r for r in fh if not r.startswith("#")]
    out = {}
    for row in csv.DictReader(rows):
        rd = float(row["rho_d"])
        out[row["material"]] = WardParams(
            rho_d=(rd, rd, rd),
            rho_s=float(row["rho_s"]),
            alpha_x=float(row["alpha_x"]),
            alpha_y=float(row["alpha_y"]),
        )
    return out
