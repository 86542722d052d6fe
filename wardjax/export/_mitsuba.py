"""Mitsuba 3 materials: the Ward fit as a diffuse + rough-conductor blend.

Mitsuba 3 has no Ward BSDF. The export is the exact sum of a Lambertian
``ρd/π`` and the microfacet lobe `fit_microfacet` found
closest to the Ward lobe (``roughconductor``, ``material = "none"`` so that
``F = 1``, scaled by ``specular_reflectance = k_s``). Mitsuba's ``blendbsdf``
mixes ``(1 − w) f₀ + w f₁``; with ``m = max ρd`` and ``w = k_s/(k_s + m)`` the
parts are ``diffuse(ρd/(1 − w))`` and ``roughconductor(k_s/w)``, so that

.. math::

    f = (1 − w)\\,\\frac{ρ_d/(1-w)}{π} + w\\,\\frac{k_s}{w}\\,\\frac{D G}{4 \\cos θ_i \\cos θ_o}
      = \\frac{ρ_d}{π} + k_s \\frac{D G}{4 \\cos θ_i \\cos θ_o},

every reflectance staying in [0, 1] whenever ``k_s + max ρd ≤ 1``. ``alpha_u``
lies along the surface's first tangent (``∂p/∂u``): the material tangent.
Colours are linear RGB with sRGB primaries, taken as they are by Mitsuba's
``*_rgb`` variants.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ._microfacet import MicrofacetFit
from ._radiance import fmt

__all__ = ["mitsuba_dict", "mitsuba_xml"]


def _parts(rho_d, fit: MicrofacetFit, rho_s_colour) -> tuple[float, np.ndarray, np.ndarray]:
    rho_d = np.broadcast_to(np.asarray(rho_d, np.float64), (3,))
    tint = np.broadcast_to(np.asarray(rho_s_colour, np.float64), (3,))
    ks = fit.k_s * tint / np.mean(tint)
    m = float(np.max(rho_d))
    k = float(np.max(ks))
    w = k / (k + m) if k + m > 0 else 0.0
    return w, rho_d / (1.0 - w), ks / w if w > 0 else ks


def mitsuba_dict(rho_d, fit: MicrofacetFit, rho_s_colour: Any = 1.0) -> dict:
    """The material as a dict for ``mitsuba.load_dict`` (module docstring).

    Parameters
    ----------
    rho_d
        Diffuse reflectance RGB (linear, sRGB primaries).
    fit
        A ``"conductor"`` `MicrofacetFit`.
    rho_s_colour
        ``ρs`` as fitted, grey or RGB: a coloured ``ρs`` tints ``k_s``.
    """
    if fit.target != "conductor":
        raise ValueError(f"Mitsuba's export takes a 'conductor' microfacet fit, got {fit.target!r}")
    w, diffuse, spec = _parts(rho_d, fit, rho_s_colour)
    return {
        "type": "blendbsdf",
        "weight": w,
        "diffuse": {"type": "diffuse", "reflectance": {"type": "rgb", "value": diffuse.tolist()}},
        "specular": {
            "type": "roughconductor",
            "material": "none",
            "distribution": fit.distribution,
            "alpha_u": fit.alpha_x,
            "alpha_v": fit.alpha_y,
            "specular_reflectance": {"type": "rgb", "value": spec.tolist()},
        },
    }


def mitsuba_xml(name: str, rho_d, fit: MicrofacetFit, rho_s_colour: Any = 1.0, comment: str = "") -> str:
    """The same material as a Mitsuba 3 XML fragment (a ``<bsdf id=name>``, loadable on its own)."""
    d = mitsuba_dict(rho_d, fit, rho_s_colour)
    spec = d["specular"]
    rgb = lambda v: ", ".join(fmt(c) for c in v)
    note = "".join(f"<!-- {line.replace('--', '-')} -->\n" for line in comment.splitlines())
    return (
        f"{note}"
        f'<bsdf type="blendbsdf" id="{name}" version="3.0.0">\n'
        f'    <float name="weight" value="{fmt(d["weight"])}"/>\n'
        f'    <bsdf type="diffuse">\n'
        f'        <rgb name="reflectance" value="{rgb(d["diffuse"]["reflectance"]["value"])}"/>\n'
        f"    </bsdf>\n"
        f'    <bsdf type="roughconductor">\n'
        f'        <string name="material" value="none"/>\n'
        f'        <string name="distribution" value="{spec["distribution"]}"/>\n'
        f'        <float name="alpha_u" value="{fmt(spec["alpha_u"])}"/>\n'
        f'        <float name="alpha_v" value="{fmt(spec["alpha_v"])}"/>\n'
        f'        <rgb name="specular_reflectance" value="{rgb(spec["specular_reflectance"]["value"])}"/>\n'
        f"    </bsdf>\n"
        f"</bsdf>\n"
    )
