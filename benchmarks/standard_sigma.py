"""z of the baseline's ρs and α against truth on untouched captures, with and without the standard's lags in σ.

    python -m benchmarks.standard_sigma --material metal --seeds 3 30

Each seed simulates a capture (160 × 120, 8-bit, texture none), reconstructs it as ``diagnose`` does, fits the
baseline and reads σ twice: the fit's own (the per-value noise, the smoothed standard's share included) and with
the standard's shared noise between values (:mod:`wardjax.effects._standard_sigma`). The scanlines are cut to one
set of image columns (the first seed's, three fewer at each side) so that every seed runs the same compiled
program. Prints one line per seed, then the SD and robust SD (IQR / 1.349) of z.
"""

from __future__ import annotations

import argparse
import dataclasses
import tempfile
from pathlib import Path

import numpy as np

MATERIALS = {
    "metal": dict(rho_d=(0.03, 0.03, 0.03), rho_s=0.35, alpha_x=0.08, alpha_y=0.08),
    "satin": dict(rho_d=(0.2, 0.3, 0.5), rho_s=0.06, alpha_x=0.09, alpha_y=0.09),
}


def _columns(data, cols):
    """``data`` cut to the image columns ``cols`` (``None`` where one is missing)."""
    have = list(np.asarray(data.standard[2]))
    if not all(c in have for c in cols):
        return None
    i = np.array([have.index(c) for c in cols])
    cut = {k: np.asarray(getattr(data, k))[i] for k in ("y", "sigma", "mask", "wi", "wo")}
    cens = None if data.censored is None else np.asarray(data.censored)[i]
    cov = {k: np.asarray(v)[i] for k, v in data.cov.items()}
    c = np.asarray(data.standard[0])
    c = c[i] if c.ndim == 3 else c  # per value, or per channel
    return dataclasses.replace(data, **cut, censored=cens, cov=cov, standard=(c, data.standard[1], np.asarray(cols)))


def _robust_sd(z: np.ndarray) -> float:
    q = np.percentile(z, [25, 75])
    return float((q[1] - q[0]) / 1.349)


def main(argv=None) -> None:
    import wardjax as wj
    from wardjax.effects import ScanlineModel
    from wardjax.effects._capture import capture_data
    from wardjax.effects._discover import _baseline, _split_library
    from wardjax.effects._standard_sigma import with_standard

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--material", choices=sorted(MATERIALS), default="metal")
    ap.add_argument("--seeds", nargs=2, type=int, default=[3, 30], help="first and last (exclusive) seed")
    a = ap.parse_args(argv)
    p = wj.WardParams(**MATERIALS[a.material])
    truth = {"rho_s": float(p.rho_s), "alpha": float(p.alpha_x)}
    z: dict[str, list] = {f"{k} {s}": [] for k in truth for s in ("before", "after")}
    cols = model = testable = None
    for seed in range(*a.seeds):
        with tempfile.TemporaryDirectory() as tmp:
            cap = wj.simulate_capture(p, Path(tmp) / "cap", seed=seed, image_size=(160, 120), texture="none")
            data = capture_data(cap, max_samples=6000)
        if data.standard is None:
            raise SystemExit("the capture carries no smoothed standard's noise")
        if cols is None:
            cols = list(np.asarray(data.standard[2])[3:-3])
            model = ScanlineModel(cap.config.fit.normalization)
            testable, _ = _split_library(model, data, None)
        data = _columns(data, cols)
        if data is None:
            print(f"seed {seed}: a column is missing; skipped", flush=True)
            continue
        search, cur, _ = _baseline(model, data, testable, 20, 64, True)
        st, wide = cur.state, with_standard(search, cur.state)
        line = [f"seed {seed}: gap {st.gap:.3f}"]
        for k, t in truth.items():
            v = st.values["model"][k]
            z[f"{k} before"].append((v - t) / st.sigma["model"][k])
            z[f"{k} after"].append((v - t) / wide.sigma["model"][k])
            line.append(f"{k} {v:.5g} ± {st.sigma['model'][k]:.2g} → ± {wide.sigma['model'][k]:.2g}")
        print("; ".join(line), flush=True)
    for k, v in z.items():
        x = np.array(v)
        print(f"z {k}: n {x.size}, mean {x.mean():+.2f}, SD {x.std(ddof=1):.2f}, robust SD {_robust_sd(x):.2f}")


if __name__ == "__main__":
    main()
