"""What each covariate is, with its unit: axis labels and values in the discovery's words."""

from __future__ import annotations

__all__ = ["COVARIATE_LABELS", "covariate_label", "covariate_value"]

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
