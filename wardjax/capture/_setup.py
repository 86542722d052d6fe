"""The smartphone method's set-up: the phone display and the viewing geometry.

Named set-ups are read from ``calibration/smartphone_setup.toml`` (the
smartphone paper, section 5: iPhone 5s, 326 ppi, 19.1 in from the eye).
"""

from __future__ import annotations

import tomllib
from dataclasses import dataclass
from functools import lru_cache

from .._data import calibration_path

__all__ = ["MM_PER_IN", "Display", "Viewing", "load_display", "load_viewing"]

MM_PER_IN = 25.4


@dataclass(frozen=True)
class Display:
    """A phone display.

    Attributes
    ----------
    name
        Label.
    ppi
        Pixels per inch (> 0).
    width_px, height_px
        Panel size in pixels (portrait).
    luminance_max, luminance_min
        White and black luminance, cd/m².
    ppb_min, ppb_max
        The integer grating set shown, pixels per bar.
    """

    name: str
    ppi: float
    width_px: int
    height_px: int
    luminance_max: float = 505.5
    luminance_min: float = 0.5
    ppb_min: int = 1
    ppb_max: int = 120

    @property
    def pixel_pitch_mm(self) -> float:
        return MM_PER_IN / self.ppi

    @property
    def contrast(self) -> float:
        """Michelson contrast of a full-swing grating, (Lmax − Lmin)/(Lmax + Lmin)."""
        return (self.luminance_max - self.luminance_min) / (self.luminance_max + self.luminance_min)


@dataclass(frozen=True)
class Viewing:
    """Where the eye is relative to the (reflected) screen.

    Attributes
    ----------
    name
        Label.
    eye_to_screen_mm
        Optical path from the eye to the screen via the surface (> 0).
    screen_obliquity_deg
        Angle between the line of sight and the screen normal, in [0, 90): the bars'
        period is foreshortened by ``cos`` of it. 0 in the paper's set-up.
    eye_to_surface_mm, view_angle_deg, phone_angle_deg
        The rest of the set-up (informative; the paper's 18 in, 45°, 45°).
    """

    name: str
    eye_to_screen_mm: float
    screen_obliquity_deg: float = 0.0
    eye_to_surface_mm: float | None = None
    view_angle_deg: float | None = None
    phone_angle_deg: float | None = None


@lru_cache(maxsize=1)
def _setup() -> dict:
    with open(calibration_path("smartphone_setup.toml"), "rb") as fh:
        return tomllib.load(fh)


def load_display(name: str | Display = "iphone5s") -> Display:
    """A :class:`Display` from ``calibration/smartphone_setup.toml`` by name (or pass one through)."""
    if isinstance(name, Display):
        return name
    table = _setup()["display"]
    if name not in table:
        raise ValueError(f"display must be one of {sorted(table)} or a Display; got {name!r}")
    d = table[name]
    return Display(
        name=name,
        ppi=float(d["ppi"]),
        width_px=int(d["width_px"]),
        height_px=int(d["height_px"]),
        luminance_max=float(d["luminance_max_cd_m2"]),
        luminance_min=float(d["luminance_min_cd_m2"]),
        ppb_min=int(d["ppb_min"]),
        ppb_max=int(d["ppb_max"]),
    )


def load_viewing(name: str | Viewing = "paper") -> Viewing:
    """A :class:`Viewing` from ``calibration/smartphone_setup.toml`` by name (or pass one through)."""
    if isinstance(name, Viewing):
        return name
    table = _setup()["viewing"]
    if name not in table:
        raise ValueError(f"viewing must be one of {sorted(table)} or a Viewing; got {name!r}")
    v = table[name]
    return Viewing(
        name=name,
        eye_to_screen_mm=float(v["eye_to_screen_in"]) * MM_PER_IN,
        screen_obliquity_deg=float(v.get("screen_obliquity_deg", 0.0)),
        eye_to_surface_mm=float(v["eye_to_surface_in"]) * MM_PER_IN,
        view_angle_deg=float(v["view_angle_deg"]),
        phone_angle_deg=float(v["phone_angle_deg"]),
    )
