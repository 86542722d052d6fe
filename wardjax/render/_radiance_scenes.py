"""Radiance scenes (b) and (c) (:mod:`._scenes`): scene text and renders through rtrace.

**(b)** The material on a ``sphere``; every environment cell a ``source`` (a
distant source of cone angle ``a_k``, ``ω_k = 2π(1 − cos a_k/2)``) with its own
grey ``light``. **(c)** The material on a polygon (the sample, ``z = 0``); every
screen cell a ``light`` polygon, counter-clockwise seen from its front (the
side facing the sample), under a ``brightfunc`` ``cos^m θe`` when the emission
is directional. Rendered with :data:`SCENE_SETTINGS`: those of the rig
(:data:`wardjax.render.RTRACE_SETTINGS`: ``-ab 0``, no source subdivision,
jitter or culling, ``-st 0``) and ``-dv-`` (light sources look black to camera
rays: the background and the screen itself are not drawn, as in the JAX
renderer).

Why discrete sources and ``-ab 0``: Radiance's direct calculation of each
source is deterministic (its centre, its solid angle, the source-size widening
of the lobe), so Radiance and the JAX renderer evaluate the *same* sum and can
be compared per pixel; ``-ab 1`` (the environment as a ``glow`` sampled by
ambient rays) or specular sampling of a ``glow`` screen would add Monte-Carlo
noise of several per cent per pixel. The cost is discretisation: the sum
approximates the integral over the environment (the screen) only as well as
the cells are small against the lobe, which the JAX renderer can check by
refining the cells.
"""

from __future__ import annotations

import math
import tempfile
from pathlib import Path

import numpy as np

from .._files import write_bytes_atomic
from ..export import radiance_rgb
from ..geometry import Camera
from ._radiance import RTRACE_SETTINGS, _f, _material_name, _polygon, _radiance_paths, _run, from_radiance_rgb
from ._scenes import DistantSources, PhoneScene, camera_rays

__all__ = [
    "SCENE_SETTINGS",
    "phone_radiance_scene",
    "radiance_render_phone",
    "radiance_render_sphere",
    "sphere_radiance_scene",
]

SCENE_SETTINGS = RTRACE_SETTINGS + ("-dv-",)


def _grey(value: float) -> str:
    r, g, b = radiance_rgb(np.full(3, float(value)))
    return f"{_f(r)} {_f(g)} {_f(b)}"


def sphere_radiance_scene(material: str, sources: DistantSources, *, centre=(0.0, 0.0, 0.0), radius=1.0) -> str:
    """Scene (b) as Radiance text: ``material`` (a ``void`` definition) on a sphere, the environment as sources."""
    out = []
    for k, (d, om, L) in enumerate(zip(sources.direction, sources.solid_angle, sources.radiance)):
        angle = math.degrees(2 * math.acos(1 - float(om) / (2 * math.pi)))
        out.append(f"void light env{k}_mat\n0\n0\n3 {_grey(L)}\n")
        out.append(f"env{k}_mat source env{k}\n0\n0\n4 {' '.join(_f(c) for c in d)} {_f(angle)}\n")
    out.append(material if material.endswith("\n") else material + "\n")
    c = " ".join(_f(v) for v in centre)
    out.append(f"{_material_name(material)} sphere ball\n0\n0\n4 {c} {_f(radius)}\n")
    return "".join(out)


def phone_radiance_scene(material: str, scene: PhoneScene) -> tuple[str, dict[str, bytes]]:
    """Scene (c) as Radiance text, and the function files it reads (``screen.cal`` for directional emission)."""
    src = scene.sources
    out = []
    files: dict[str, bytes] = {}
    modifier = "void"
    if src.exponent:
        files["screen.cal"] = b"cs = -(Dx*Nx + Dy*Ny + Dz*Nz);\nemit = if(cs, cs^A1, 0);\n"
        out.append(f"void brightfunc screen_emit\n2 emit screen.cal\n0\n1 {_f(src.exponent)}\n")
        modifier = "screen_emit"
    values, index = np.unique(src.radiance, return_inverse=True)
    for j, L in enumerate(values):
        out.append(f"{modifier} light screen{j}_mat\n0\n0\n3 {_grey(L)}\n")
    for k, (c, hu, hv) in enumerate(zip(src.centre, src.half_u, src.half_v)):
        corners = (c - hu - hv, c + hu - hv, c + hu + hv, c - hu + hv)
        pts = "  ".join(" ".join(_f(v) for v in q) for q in corners)
        out.append(f"screen{index[k]}_mat polygon cell{k}\n0\n0\n12 {pts}\n")
    out.append(material if material.endswith("\n") else material + "\n")
    out.append(_polygon(_material_name(material), "sample", scene.sample_box))
    return "".join(out), files


def _render(scene: str, files: dict[str, bytes], camera: Camera, processes: int) -> np.ndarray:
    bindir, libdir = _radiance_paths()
    d, o = camera_rays(camera)
    rays = np.concatenate([np.broadcast_to(o, d.shape), d], -1).astype(np.float32)
    with tempfile.TemporaryDirectory(prefix="wardjax-radiance-") as tmp:
        tmp = Path(tmp)
        for name, data in files.items():
            write_bytes_atomic(tmp / name, data)
        write_bytes_atomic(tmp / "scene.rad", scene.encode())
        write_bytes_atomic(tmp / "scene.oct", _run([str(bindir / "oconv"), "-f", "scene.rad"], tmp, libdir))
        cmd = [str(bindir / "rtrace"), "-h", "-fff", "-n", str(int(processes)), *SCENE_SETTINGS, "scene.oct"]
        out = _run(cmd, tmp, libdir, rays.tobytes())
    values = np.frombuffer(out, np.float32).reshape(d.shape[:-1] + (3,))
    return from_radiance_rgb(values.astype(np.float64))


def radiance_render_sphere(
    material: str,
    sources: DistantSources,
    camera: Camera,
    *,
    centre=(0.0, 0.0, 0.0),
    radius: float = 1.0,
    processes: int = 1,
) -> np.ndarray:
    """Render scene (b) with Radiance: ``(H, W, 3)`` radiance in wardjax's linear RGB, one ray per pixel centre.

    ``material`` is a ``void`` Radiance definition (:func:`wardjax.export.radiance_material`, ``radiance_metal``).
    """
    return _render(sphere_radiance_scene(material, sources, centre=centre, radius=radius), {}, camera, processes)


def radiance_render_phone(material: str, scene: PhoneScene, *, processes: int = 1) -> np.ndarray:
    """Render scene (c) with Radiance: ``(H, W, 3)`` radiance (W sr⁻¹ m⁻²) in wardjax's linear RGB."""
    text, files = phone_radiance_scene(material, scene)
    return _render(text, files, scene.camera, processes)
