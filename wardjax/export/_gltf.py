"""glTF 2.0 materials: the Ward fit as a metallic-roughness dielectric with ``KHR_materials_*``.

glTF's dielectric (specification, Appendix B, with ``KHR_materials_specular``
and ``KHR_materials_anisotropy``) is

.. math::

    f = (1 - F)\\,\\frac{c_\\mathrm{base}}{π} + F\\,\\frac{D_\\mathrm{GGX}\\,G}{4\\,|n·ω_i|\\,|n·ω_o|},
    \\qquad F = F_0 + (F_{90} - F_0)(1 - |ω_o·h|)^5

with ``F0 = 0.04 · specularFactor · specularColorFactor``, ``F90 = specularFactor``,
``α_b = roughnessFactor²`` across and ``α_t = α_b + (1 − α_b) · anisotropyStrength²``
along the direction ``anisotropyRotation`` (radians, from the mesh tangent
towards the bitangent). The export sets ``metallicFactor = 0``, the lobe from
`fit_microfacet` (``target = "gltf"``: ``F0``, ``F90``,
``α_x``, ``α_y`` fitted together with the diffuse coupling) and
``baseColorFactor = ρd / (1 − F0)`` (glTF's diffuse is ``(1 − F) c_base/π``).

The file carries one quad (the sample, ``width × height`` metres, normal
``+Y``, its tangent the material tangent) so that a viewer shows the material
as it is; glTF's axes are the sample frame's ``(x, z, −y)``.
`gltf_material_brdf` evaluates a material of such a file from its JSON
fields, written from the specification's text alone.
"""

from __future__ import annotations

import base64
import math

import numpy as np

from ._microfacet import MicrofacetFit

__all__ = ["GLTF_F0_DIELECTRIC", "base_color_image", "gltf_document", "gltf_material_brdf"]

GLTF_F0_DIELECTRIC = 0.04  # glTF's normal-incidence reflectance of its default dielectric (ior 1.5)


def _material(name: str, rho_d, fit: MicrofacetFit, extras: dict, textured: bool) -> tuple[dict, list[str]]:
    if fit.target != "gltf":
        raise ValueError(f"glTF's export takes a 'gltf' microfacet fit, got {fit.target!r}")
    rho_d = np.broadcast_to(np.asarray(rho_d, np.float64), (3,))
    base = np.clip(rho_d / (1.0 - fit.k_s), 0.0, 1.0)
    a_t, a_b, rot = fit.alpha_x, fit.alpha_y, 0.0
    if a_b > a_t:  # glTF stretches along the rotated tangent: swap the axes
        a_t, a_b, rot = a_b, a_t, math.pi / 2
    a_t, a_b = min(a_t, 1.0), min(a_b, 1.0)
    ext = {
        "KHR_materials_specular": {
            "specularFactor": fit.f90,
            "specularColorFactor": [fit.k_s / (GLTF_F0_DIELECTRIC * fit.f90)] * 3,
        }
    }
    if a_t > a_b:
        strength = math.sqrt((a_t - a_b) / (1.0 - a_b)) if a_b < 1 else 0.0
        ext["KHR_materials_anisotropy"] = {"anisotropyStrength": strength, "anisotropyRotation": rot}
    mat = {
        "name": name,
        "pbrMetallicRoughness": {
            "baseColorFactor": [1.0, 1.0, 1.0, 1.0] if textured else [*base.tolist(), 1.0],
            "metallicFactor": 0.0,
            "roughnessFactor": math.sqrt(a_b),
            **({"baseColorTexture": {"index": 0, "texCoord": 0}} if textured else {}),
        },
        "doubleSided": False,
        "extensions": ext,
        "extras": extras,
    }
    return mat, sorted(ext)


def _quad(width_m: float, height_m: float, tangent) -> tuple[bytes, list[dict], list[dict], dict]:
    """One quad on the sample plane: buffer bytes, buffer views, accessors, mesh primitive attributes."""
    hw, hh = width_m / 2, height_m / 2
    # sample frame (x, y, 0) → glTF (x, 0, −y); corners counter-clockwise seen from +Y
    xy = np.array([[-hw, -hh], [hw, -hh], [hw, hh], [-hw, hh]])
    pos = np.stack([xy[:, 0], np.zeros(4), -xy[:, 1]], -1).astype(np.float32)
    nrm = np.tile(np.array([0.0, 1.0, 0.0], np.float32), (4, 1))
    t = np.asarray(tangent, np.float64) / np.linalg.norm(tangent)
    tan = np.tile(np.array([t[0], 0.0, -t[1], 1.0], np.float32), (4, 1))
    uv = np.array([[0.0, 1.0], [1.0, 1.0], [1.0, 0.0], [0.0, 0.0]], np.float32)  # image row 0 at the largest y
    idx = np.array([0, 1, 2, 0, 2, 3], np.uint16)
    blobs = [pos, nrm, tan, uv, idx]
    views, accessors, offset, data = [], [], 0, b""
    kinds = [("VEC3", 5126), ("VEC3", 5126), ("VEC4", 5126), ("VEC2", 5126), ("SCALAR", 5123)]
    for i, (a, (typ, comp)) in enumerate(zip(blobs, kinds)):
        raw = a.tobytes()
        view = {"buffer": 0, "byteOffset": offset, "byteLength": len(raw)}
        view["target"] = 34963 if typ == "SCALAR" else 34962
        views.append(view)
        acc = {"bufferView": i, "componentType": comp, "count": len(a), "type": typ}
        if i == 0:
            acc |= {"min": pos.min(0).tolist(), "max": pos.max(0).tolist()}
        accessors.append(acc)
        data += raw + b"\0" * (-len(raw) % 4)
        offset = len(data)
    attributes = {"POSITION": 0, "NORMAL": 1, "TANGENT": 2, "TEXCOORD_0": 3}
    return data, views, accessors, attributes


def gltf_document(
    name: str,
    rho_d,
    fit: MicrofacetFit,
    *,
    size_m: tuple[float, float] = (0.1, 0.1),
    tangent=(1.0, 0.0),
    generator: str = "wardjax",
    extras: dict | None = None,
    base_color_uri: str | None = None,
) -> dict:
    """A self-contained glTF 2.0 document (JSON, buffer embedded) with the material on one quad.

    Parameters
    ----------
    name
        The material's (and node's) name.
    rho_d
        Diffuse reflectance RGB (linear, sRGB primaries).
    fit
        A ``"gltf"`` `MicrofacetFit`.
    size_m
        The quad's ``(width, height)`` in metres (glTF's unit).
    tangent
        ``(tx, ty)``: the material tangent (the direction of ``α_x``) in the sample plane.
    extras
        Stored in the material's ``extras`` (the Ward fit and the conversion error).
    base_color_uri
        An sRGB image of ``ρd/(1 − F0)`` over the quad (`base_color_image`),
        row 0 at the sample's largest ``y``: the base colour becomes this
        texture (``baseColorFactor`` 1).
    """
    mat, used = _material(name, rho_d, fit, extras or {}, base_color_uri is not None)
    data, views, accessors, attributes = _quad(*size_m, tangent)
    uri = "data:application/octet-stream;base64," + base64.b64encode(data).decode()
    doc = {
        "asset": {"version": "2.0", "generator": generator},
        "extensionsUsed": used,
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0, "name": name}],
        "meshes": [{"name": name, "primitives": [{"attributes": attributes, "indices": 4, "material": 0}]}],
        "materials": [mat],
        "buffers": [{"byteLength": len(data), "uri": uri}],
        "bufferViews": views,
        "accessors": accessors,
    }
    if base_color_uri is not None:
        clamp, linear = 33071, 9729  # CLAMP_TO_EDGE, LINEAR
        doc["images"] = [{"uri": base_color_uri}]
        doc["samplers"] = [{"magFilter": linear, "minFilter": linear, "wrapS": clamp, "wrapT": clamp}]
        doc["textures"] = [{"source": 0, "sampler": 0}]
    return doc


def base_color_image(rho_d_plane, fit: MicrofacetFit) -> np.ndarray:
    """The glTF base-colour texture of a rectified ρd: ``ρd/(1 − F0)`` as 8-bit sRGB ``(H, W, 3)``."""
    from .._files import srgb8

    return srgb8(np.clip(np.asarray(rho_d_plane, np.float64) / (1.0 - fit.k_s), 0.0, 1.0))


def gltf_material_brdf(material: dict, wi, wo) -> np.ndarray:
    """``f_r (..., 3)`` (sr⁻¹) of a glTF material (metallic 0) for local directions (z = normal, x = mesh tangent).

    Read from the material's JSON as the specification defines it (module
    docstring): base colour (its factor: a texture is not read), roughness, ``KHR_materials_specular``,
    ``KHR_materials_anisotropy``. Separable Smith–GGX masking. NumPy, float64.
    """
    pbr = material.get("pbrMetallicRoughness", {})
    ext = material.get("extensions", {})
    base = np.asarray(pbr.get("baseColorFactor", [1.0, 1.0, 1.0, 1.0])[:3], np.float64)
    alpha = float(pbr.get("roughnessFactor", 1.0)) ** 2
    spec = ext.get("KHR_materials_specular", {})
    s = float(spec.get("specularFactor", 1.0))
    c = np.asarray(spec.get("specularColorFactor", [1.0, 1.0, 1.0]), np.float64)
    f0, f90 = np.minimum(GLTF_F0_DIELECTRIC * c * s, 1.0), s
    aniso = ext.get("KHR_materials_anisotropy", {})
    k = float(aniso.get("anisotropyStrength", 0.0))
    rot = float(aniso.get("anisotropyRotation", 0.0))
    a_t, a_b = alpha + (1.0 - alpha) * k * k, alpha
    wi, wo = np.asarray(wi, np.float64), np.asarray(wo, np.float64)
    # into the anisotropy frame: t = (cos rot, sin rot), b = (−sin rot, cos rot)
    cr, sr = math.cos(rot), math.sin(rot)

    def frame(w):
        return w[..., 0] * cr + w[..., 1] * sr, -w[..., 0] * sr + w[..., 1] * cr, w[..., 2]

    (ix, iy, iz), (ox, oy, oz) = frame(wi), frame(wo)
    ok = (iz > 0) & (oz > 0)
    hx, hy, hz = ix + ox, iy + oy, iz + oz
    hn = np.sqrt(hx * hx + hy * hy + hz * hz)
    hn = np.where(hn > 0, hn, 1.0)
    hx, hy, hz = hx / hn, hy / hn, hz / hn
    # GGX: D = 1 / (π αt αb (ht²/αt² + hb²/αb² + hn²)²)
    d = 1.0 / (math.pi * a_t * a_b * ((hx / a_t) ** 2 + (hy / a_b) ** 2 + hz**2) ** 2)

    def g1(x, y, z):
        z = np.where(z > 0, z, 1.0)
        return 2.0 * z / (z + np.sqrt((a_t * x) ** 2 + (a_b * y) ** 2 + z * z))

    vis = g1(ix, iy, iz) * g1(ox, oy, oz) / (4.0 * np.where(ok, iz * oz, 1.0))
    voh = np.abs(ox * hx + oy * hy + oz * hz)
    fr = f0 + (f90 - f0) * (1.0 - voh[..., None]) ** 5
    f = (1.0 - fr) * base / math.pi + fr * (d * vis)[..., None]
    return np.where(ok[..., None], f, 0.0)
