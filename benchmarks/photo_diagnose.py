"""``wardjax diagnose`` on photographs: the licensed real flash photos and multiview renders with a hidden effect.

Prints, per capture, what discovery names and the gap (χ²/dof) from the
paper's model to the last effect added::

    python -m benchmarks.photo_diagnose            # the real photos and the renders
    python -m benchmarks.photo_diagnose --renders  # the renders only
    python -m benchmarks.photo_diagnose --capture matfusion_pink  # one real photo

The renders are wardjax's forward model of nine flash photos of a flat
one-material sample (``wardjax.render.flash_views``, no bumps), written in
the rectified layout with sensor noise and imported; a radial gain the
layout does not describe multiplies each photo before the noise: none (the
null), the lens's vignetting ``1 − 0.3 r²`` or the lamp's falloff
``cos³ ψ``. With the flash 10 mm from the lens the two are one effect to
the data; with the lamp 150 mm away they are told apart.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np

REAL = Path(__file__).resolve().parents[1] / "tests" / "data" / "flash"
NOISE_READ, NOISE_GAIN = 0.002, 1e-4  # wardjax.simulate.FlashNoise's defaults, written into the capture


def radial_gain(scene, kind: str | None) -> np.ndarray | None:
    """``(K, H, W)`` the gain of ``kind`` on each photo of ``scene``, from its geometry (cameras look at the centre).

    ``"vignetting"``: ``1 − 0.3 r²``, ``r`` the tangent of the angle off the camera's axis over its largest value;
    ``"flash_falloff"``: ``cos³ ψ``, ``ψ`` the angle off the lamp's axis (parallel to the camera's).
    """
    if kind is None:
        return None
    pts = scene.points()[None]  # (1, H, W, 3)
    cam = scene.camera_pos[:, None, None]
    axis = -cam / np.linalg.norm(cam, axis=-1, keepdims=True)
    if kind == "vignetting":
        ray = pts - cam
        along = np.sum(ray * axis, -1)
        tan2 = np.sum(ray * ray, -1) / along**2 - 1.0
        return 1.0 - 0.3 * tan2 / tan2.max()
    to_point = pts - scene.light_pos[:, None, None]
    return (np.sum(to_point * axis, -1) / np.linalg.norm(to_point, axis=-1)) ** 3


def multiview_render(folder: Path, kind: str | None = None, *, offset: float = 10.0, seed: int = 0, size: int = 32):
    """Write and import a one-material multiview render with the gain ``kind``; returns the capture folder."""
    import wardjax as wj
    from wardjax.render import flash_views
    from wardjax.simulate import FlashNoise, simulate_flash_views

    scene = flash_views(
        (size, size),
        rho_d=((0.4, 0.3, 0.2), (0.4, 0.3, 0.2)),
        rho_s=(0.08, 0.08),
        alpha=(0.12, 0.12),
        bump_amplitude=0.0,
        flash_offset=offset,
    )
    noise = FlashNoise(NOISE_READ, NOISE_GAIN)
    simulate_flash_views(scene, folder / "src", noise=noise, seed=seed, gain=radial_gain(scene, kind))
    wj.import_capture(folder / "src", folder / "cap")
    with open(folder / "cap" / "capture.toml", "a") as fh:  # the noise the photos were drawn with
        fh.write(f"\n[noise]\nread = {NOISE_READ}\nshot = {NOISE_GAIN}\n")
    return folder / "cap"


def diagnose(folder: Path):
    """The discovery report of the capture in ``folder``."""
    import wardjax as wj
    from wardjax.run import diagnose_photo_capture

    return diagnose_photo_capture(wj.load_capture(folder), progress=lambda _: None)


def _short(rep) -> str:
    """The verdict in a few words: within the noise, or unexplained and where the residual lives."""
    if rep.within_noise:
        text = "within the noise"
    else:
        band = max(rep.where["bands"], key=lambda b: b["chi2_share"] / max(b["obs_share"], 1e-12))
        text = (
            f"unexplained: the {band['band']} holds {100 * band['chi2_share']:.0f} % of χ² on "
            f"{100 * band['obs_share']:.0f} % of the views"
        )
    if rep.unphysical and rep.unphysical[0]["step"] == 0:
        text += "; baseline lobe not physical"
    return text + "".join(f"; {n} not identifiable" for n in rep.not_identifiable)


def _row(label: str, rep, seconds: float) -> str:
    named = ", ".join(rep.found) or "nothing"
    named += "".join(f" (or {b})" for _, b, _ in rep.not_told_apart)
    gaps = " → ".join(f"{g:.4g}" for g in rep.gap)
    return f"| {label} | {named} | {gaps} | {_short(rep)} | {seconds:.0f} |"


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--renders", action="store_true", help="the multiview renders only")
    ap.add_argument("--capture", help="only the real photo of this name (a folder of tests/data/flash)")
    args = ap.parse_args(argv)
    print("| capture | named | gap per step | verdict | s |\n|---|---|---|---|---|")
    if not args.renders:
        for cap in sorted(p for p in REAL.iterdir() if (p / "capture.toml").is_file()):
            if args.capture and cap.name != args.capture:
                continue
            t = time.perf_counter()
            rep = diagnose(cap)
            print(_row(cap.name, rep, time.perf_counter() - t), flush=True)
    if args.capture:
        return
    with tempfile.TemporaryDirectory() as tmp:
        for offset in (10.0, 150.0):
            for kind in (None, "vignetting", "flash_falloff"):
                label = f"multiview, lamp {offset:.0f} mm from the lens, {kind or 'null'}"
                folder = multiview_render(Path(tmp) / f"{offset:.0f}_{kind}", kind, offset=offset)
                t = time.perf_counter()
                rep = diagnose(folder)
                print(_row(label, rep, time.perf_counter() - t), flush=True)


if __name__ == "__main__":
    main()
