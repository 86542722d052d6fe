"""How the ρd texture of a ``wardjax simulate`` capture is correlated *across* scanlines, and what an edit adds.

Measures, on the baseline fit's residuals (one ρd per scanline, before any
texture term), relative to the mean predicted level:

- the correlation of residuals at the same sample index between scanlines
  ``lag`` apart (scanlines are binned image columns);
- the variance of the profile shared by all scanlines (the mean residual over
  scanlines at each sample index) against the total, and the along-scanline
  lag-1 correlation before and after removing that shared profile.

Independent texture per scanline would read cross-scanline correlation ≈ 0
and a shared-profile variance ≈ total / S. The edits are those of
:mod:`benchmarks.edited_captures` (image files edited, nothing of
:mod:`wardjax.effects` used to make them).

Run ``python -m benchmarks.texture_across_scanlines [--texture wood] [--size 160 120]``.
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import numpy as np

from benchmarks.edited_captures import EDITS, edit_capture, make_capture


def baseline_residuals(folder: Path):
    """``(e, pred, mask)`` of the baseline fit ``discover`` starts from (private helpers: a measurement)."""
    from wardjax.capture import load_capture
    from wardjax.effects import ScanlineModel
    from wardjax.effects import _discover as d
    from wardjax.effects._capture import capture_data
    from wardjax.effects._search import _Search

    cap = load_capture(folder)
    data = capture_data(cap)
    model = ScanlineModel(cap.config.fit.normalization)
    testable, _ = d._split_library(model, data, None)
    search = _Search(model, data, testable, 60, 64)
    cur = search.residual_view(d._fit_baseline(search))
    y, m = np.asarray(data.y), np.asarray(data.mask)
    pred = np.asarray(cur.pred)
    return np.where(m, y - pred, np.nan), pred, m


def summarise(e: np.ndarray, pred: np.ndarray, lags=(1, 2, 3, 4, 8)) -> list[str]:
    out = []
    for c in range(e.shape[-1]):
        ec = e[..., c] / np.nanmean(pred[..., c])
        cors = []
        for lag in lags:
            a, b = ec[:-lag], ec[lag:]
            ok = np.isfinite(a) & np.isfinite(b)
            cors.append(f"{np.corrcoef(a[ok], b[ok])[0, 1]:+.2f}")
        prof = np.nanmean(ec, axis=0)
        dev = ec - prof[None]
        ok = np.isfinite(ec[:, :-1]) & np.isfinite(ec[:, 1:])
        raw1 = np.corrcoef(ec[:, :-1][ok], ec[:, 1:][ok])[0, 1]
        dev1 = np.corrcoef(dev[:, :-1][ok], dev[:, 1:][ok])[0, 1]
        out.append(
            f"  ch{c}: across-scanline corr at lags {lags}: {' '.join(cors)}; "
            f"var total {np.nanvar(ec):.2e}, shared profile {np.nanvar(prof):.2e} "
            f"(independent: {np.nanvar(ec) / ec.shape[0]:.2e}); along lag-1 corr {raw1:.3f} → {dev1:.3f} without it"
        )
    return out


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--texture", default="wood")
    ap.add_argument("--edits", nargs="+", default=["none", "gradient", "offset"])
    ap.add_argument("--size", nargs=2, type=int, default=(160, 120))
    ap.add_argument("--seed", type=int, default=0)
    a = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        base = Path(tmp) / "base"
        make_capture(base, texture=a.texture, size=a.size, seed=a.seed)
        for name in a.edits:
            spec = EDITS[name]
            folder = edit_capture(base, Path(tmp) / name, *(spec or (None,)))
            e, pred, _ = baseline_residuals(folder)
            print(f"{a.texture} {name}: {e.shape[0]} scanlines × {e.shape[1]} samples", flush=True)
            print("\n".join(summarise(e, pred)), flush=True)


if __name__ == "__main__":
    main()
