"""Access to the plain-file data shipped in ``calibration/`` and ``examples/``."""

from __future__ import annotations

import csv
from importlib import resources
from pathlib import Path

from .ward import WardParams

__all__ = ["calibration_path", "example_path", "table1_materials"]


def _shipped(folder: str, name: str) -> Path:
    """Path of ``folder/name`` (installed as package data or beside the source)."""
    here = Path(__file__).resolve().parent
    for root in (here / folder, here.parent / folder):
        if (root / name).exists():
            return root / name
    pkg = resources.files("wardjax") / folder / name
    if pkg.is_file() or pkg.is_dir():
        return Path(str(pkg))
    raise FileNotFoundError(f"{folder} file {name!r} not found beside the wardjax package")


def calibration_path(name: str) -> Path:
    """Path of a file in ``calibration/`` (installed as package data or beside the source)."""
    return _shipped("calibration", name)


def example_path(name: str) -> Path:
    """Path of a file or folder in ``examples/`` (e.g. ``"smartphone/colorchecker-red"``)."""
    return _shipped("examples", name)


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
