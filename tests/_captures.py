"""Test inputs built in one place: capture folders the bad-input tests and the corpus build and then break,
and random scanline problems through the highlight."""

from __future__ import annotations

from pathlib import Path

import imageio.v3 as iio
import numpy as np
import tomli_w

import wardjax as wj
from wardjax.simulate import x_offset_for_slope


def phone_capture(folder: Path, photo: np.ndarray | None = None, **edits) -> Path:
    """A smartphone capture in ``folder``: a near-white photo (Table 1b's NCS white, code 237), three observers.

    ``edits`` are ``section__field=value``; a value of ``None`` removes the field (e.g. ``thresholds__ppb=None``
    beside ``thresholds__ppb_mean``).
    """
    folder.mkdir(parents=True, exist_ok=True)
    iio.imwrite(folder / "photo.png", np.full((96, 128, 3), 237, np.uint8) if photo is None else photo)
    cfg: dict = {
        "method": "smartphone",
        "photo": {"file": "photo.png", "region": [20, 80, 30, 100]},
        "thresholds": {"ppb": [10, 11, 12]},
    }
    for key, value in edits.items():
        section, _, field = key.partition("__")
        cfg.setdefault(section, {})[field] = value
        if value is None:
            cfg[section].pop(field)
    (folder / "capture.toml").write_text(tomli_w.dumps(cfg))
    return folder


def isotropic_set(rng, s, alpha_range=(0.03, 0.3), *, n_samples=None):
    """``s`` random isotropic problems in the papers' rig: ``(truth, data)``.

    ρd 0.05–0.8 (RGB), ρs 0.01–0.1, α in ``alpha_range``; each scanline passes through the highlight, its
    half vector tilting by up to ±1.5 α at its centre; :func:`wardjax.simulate_scanlines`' samples
    (``n_samples``: its default) and 1 % noise.
    """
    truth = wj.WardParams(
        rho_d=rng.uniform(0.05, 0.8, (s, 3)),
        rho_s=rng.uniform(0.01, 0.1, s),
        alpha_x=(a := rng.uniform(*alpha_range, s)),
        alpha_y=a,
    )
    rig = wj.ScanlineRig.random(s, rng)
    x0 = x_offset_for_slope(rig, rng.uniform(-1.5, 1.5, s) * a)
    kw = {} if n_samples is None else {"n_samples": n_samples}
    return truth, wj.simulate_scanlines(truth, x_offsets=x0, rig=rig, seed=rng, **kw)
