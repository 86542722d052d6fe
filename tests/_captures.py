"""Capture folders the bad-input tests and the corpus build and then break."""

from __future__ import annotations

from pathlib import Path

import imageio.v3 as iio
import numpy as np
import tomli_w


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
