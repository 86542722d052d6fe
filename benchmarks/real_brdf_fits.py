"""Ward fits to real measured BRDFs: all 61 CUReT samples and three RGL materials.

``python -m benchmarks.real_brdf_fits`` writes ``calibration/real_brdf_fits.csv``: one row
per material × model (isotropic, anisotropic) × normalisation (the three of
:data:`wardjax.ward.NORMALIZATIONS`), with the parameters ± σ, the fit's status, the
reduced χ², the relative RMS error ``‖f_Ward − f‖₂ / ‖f‖₂`` over the samples fitted
(dominated by the specular peak) and the median absolute relative residual
``median |f_Ward − f| / max(|f|, floor)`` (the typical sample).

CUReT (``calibration/curet/``)
    Each sample's 205 measured direction pairs, grey (RGB averaged). The noise is the
    per-sample relative scatter between nearest-neighbour direction pairs
    (:func:`wardjax.effects._real.curet_noise`), so the weights are ``1/(rel · f)²``. The
    grey values are fitted as three identical channels (the fitter takes RGB); the χ² and
    dof reported are those of one channel (χ²/3; 205 minus the parameters ρd, ρs and one
    or two α), and σ of ρs and α are scaled by √3 so the copies add no information.

RGL (``shared/data/rgl/*.bsdf``, not shipped: this script only)
    Evaluated through Mitsuba 3's ``measured`` BSDF (``pip install mitsuba``, BSD-3) in
    ``scalar_rgb``; Mitsuba's ``eval`` returns ``f_r · cos θo``, divided out here. Sampled
    where a camera rig sees the surface: CUReT's 205 direction pairs plus, for the lobe,
    the plane of incidence at θi = 15°, 30°, 45°, 60° with θo from the mirror direction
    −20° to +20° in 1° steps (kept between 0.5° and 85°) and the same scans turned 10°
    out of plane.
    The tabulated data carry no noise figure; the weights assume 5 % relative error above
    0.01 sr⁻¹ (``σ = 0.05 · max(f, 0.01)``), so the reduced χ² reads as (relative
    residual / 5 %)². A few interpolated values at grazing pairs are ≤ 0 (kept: their
    error is the floor's).

``discover_adds`` (per material, the same on all its rows)
    The effects :func:`wardjax.effects.discover` adds, in order and ``;``-joined (``none``
    when it adds nothing), starting from its isotropic Ward 1992 baseline
    (:class:`~wardjax.effects.ScanlineModel`) on the same samples and noise: CUReT through
    :func:`wardjax.effects._real.curet_data` (σ = rel · f), RGL with the 5 % error above.
"""

from __future__ import annotations

import io
import sys
from pathlib import Path

import numpy as np

import wardjax as wj
from wardjax._data import calibration_path
from wardjax._files import write_bytes_atomic
from wardjax.effects import ScanlineModel, discover, scanline_data
from wardjax.effects._real import curet_data, curet_noise, load_curet
from wardjax.ward import NORMALIZATIONS

RGL_DIR = Path(__file__).resolve().parents[2] / "shared" / "data" / "rgl"
RGL_MATERIALS = ("paper_white_rgb", "satin_rosaline_rgb", "vch_golden_yellow_rgb")
RGL_REL_SIGMA = 0.05
RGL_FLOOR = 0.01  # sr⁻¹: below it the error stays at 5 % of this (dark channels, grazing pairs)
MODELS = ("isotropic", "anisotropic")
CSV_NAME = "real_brdf_fits.csv"
COLUMNS = (
    "source",
    "material",
    "model",
    "normalization",
    "status",
    "rho_d_r",
    "rho_d_g",
    "rho_d_b",
    "rho_s",
    "sigma_rho_s",
    "alpha_x",
    "sigma_alpha_x",
    "alpha_y",
    "sigma_alpha_y",
    "n_samples",
    "dof",
    "reduced_chi2",
    "rel_rms",
    "median_abs_rel_resid",
    "discover_adds",
)


def _rows(source, names, f, wi, wo, weights, *, grey: bool, floor: float = 1e-4) -> list[dict]:
    """Fit every model and normalisation to a batch of materials: one row each."""
    out = []
    n = f.shape[1]
    for model in MODELS:
        n_par = (1 if grey else 3) + 1 + (1 if model == "isotropic" else 2)
        for norm in NORMALIZATIONS:
            fit = wj.fit_scanlines(f, wi, wo, model, weights=weights, normalization=norm)
            p = fit.params
            pred = np.asarray(
                wj.ward_brdf(
                    wj.WardParams.from_estimate(
                        rho_d=p.rho_d[:, None, :],
                        rho_s=p.rho_s[:, None],
                        alpha_x=p.alpha_x[:, None],
                        alpha_y=p.alpha_y[:, None],
                    ),
                    wi,
                    wo,
                    normalization=norm,
                )
            )
            scale = np.sqrt(3.0) if grey else 1.0  # identical channels carry one channel's information
            chi2 = fit.chi2 / 3.0 if grey else fit.chi2
            dof = n - n_par if grey else fit.dof
            rel_rms = np.sqrt(np.sum((pred - f) ** 2, axis=(1, 2)) / np.sum(f**2, axis=(1, 2)))
            med_rel = np.median(np.abs(pred - f) / np.maximum(np.abs(f), floor), axis=(1, 2))
            for k, name in enumerate(names):
                out.append(
                    {
                        "source": source,
                        "material": name,
                        "model": model,
                        "normalization": norm,
                        "status": str(fit.status_names[k]),
                        "rho_d_r": p.rho_d[k, 0],
                        "rho_d_g": p.rho_d[k, 1],
                        "rho_d_b": p.rho_d[k, 2],
                        "rho_s": p.rho_s[k],
                        "sigma_rho_s": scale * fit.stderr.rho_s[k],
                        "alpha_x": p.alpha_x[k],
                        "sigma_alpha_x": scale * fit.stderr.alpha_x[k],
                        "alpha_y": p.alpha_y[k],
                        "sigma_alpha_y": scale * fit.stderr.alpha_y[k],
                        "n_samples": n,
                        "dof": int(np.asarray(dof if grey else dof[k])),
                        "reduced_chi2": float(chi2[k]) / max(int(np.asarray(dof if grey else dof[k])), 1),
                        "rel_rms": rel_rms[k],
                        "median_abs_rel_resid": med_rel[k],
                    }
                )
    return out


def _adds(data) -> str:
    """What :func:`discover` adds to isotropic Ward on ``data``: names ``;``-joined, or ``none``."""
    rep = discover(ScanlineModel(), data, keep_plot_data=False)
    return ";".join(rep.found) or "none"


def _with_adds(rows: list[dict], adds: dict[str, str] | None) -> list[dict]:
    for r in rows:
        r["discover_adds"] = "" if adds is None else adds[r["material"]]
    return rows


def curet_rows(indices=None, *, with_discover: bool = True) -> list[dict]:
    """Rows for the CUReT samples at ``indices`` (0-based; default all 61).

    ``with_discover=False`` leaves ``discover_adds`` empty (faster).
    """
    ids, brdf, wi, wo = load_curet()
    idx = np.arange(len(ids)) if indices is None else np.asarray(indices)
    f = np.repeat(brdf[idx, :, None], 3, axis=-1)
    rel = np.array([curet_noise(brdf[i], wi, wo) for i in idx])
    weights = 1.0 / (rel[:, None, None] * np.maximum(f, 1e-4)) ** 2
    shape = (len(idx), *wi.shape)
    names = [f"curet_{int(ids[i]):02d}" for i in idx]
    rows = _rows("curet", names, f, np.broadcast_to(wi, shape), np.broadcast_to(wo, shape), weights, grey=True)
    adds = {n: _adds(curet_data(int(i))[0]) for n, i in zip(names, idx, strict=True)} if with_discover else None
    return _with_adds(rows, adds)


def rgl_directions() -> tuple[np.ndarray, np.ndarray]:
    """(wi, wo), each (N, 3): CUReT's 205 pairs, then the in-plane and 10° out-of-plane scans."""
    _, _, wi_c, wo_c = load_curet()

    def unit(theta, phi):
        return np.stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)], -1)

    wi_l, wo_l = [], []
    for ti in (15.0, 30.0, 45.0, 60.0):
        for dphi in (0.0, 10.0):
            for d in np.arange(-20.0, 20.5, 1.0):
                to = ti + d
                if not 0.5 <= to <= 85.0:
                    continue
                wi_l.append(unit(np.radians(ti), 0.0))
                wo_l.append(unit(np.radians(to), np.radians(180.0 + dphi)))
    return np.concatenate([wi_c, np.array(wi_l)]), np.concatenate([wo_c, np.array(wo_l)])


def rgl_eval(path: Path, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
    """RGB ``f_r`` (sr⁻¹) of an RGL ``.bsdf`` file at direction pairs, via Mitsuba 3."""
    import mitsuba as mi

    mi.set_variant("scalar_rgb")
    bsdf = mi.load_dict({"type": "measured", "filename": str(path)})
    ctx = mi.BSDFContext()
    si = mi.SurfaceInteraction3f()
    si.sh_frame = mi.Frame3f(mi.Vector3f(0.0, 0.0, 1.0))
    out = np.empty((len(wi), 3))
    for k, (a, b) in enumerate(zip(wi, wo, strict=True)):
        si.wi = mi.Vector3f(*map(float, a))
        v = bsdf.eval(ctx, si, mi.Vector3f(*map(float, b)))
        out[k] = np.array([v[0], v[1], v[2]]) / b[2]
    return out


def rgl_rows(folder: Path = RGL_DIR) -> list[dict]:
    """Rows for the three RGL materials (needs Mitsuba 3 and the ``.bsdf`` files)."""
    wi, wo = rgl_directions()
    f = np.stack([rgl_eval(folder / f"{m}.bsdf", wi, wo) for m in RGL_MATERIALS])
    weights = 1.0 / (RGL_REL_SIGMA * np.maximum(f, RGL_FLOOR)) ** 2
    shape = (len(RGL_MATERIALS), *wi.shape)
    adds = {
        m: _adds(
            scanline_data(
                f[k][None], wi[None], wo[None], (RGL_REL_SIGMA * np.maximum(f[k], RGL_FLOOR))[None], kind="brdf"
            )
        )
        for k, m in enumerate(RGL_MATERIALS)
    }
    rows = _rows(
        "rgl",
        list(RGL_MATERIALS),
        f,
        np.broadcast_to(wi, shape),
        np.broadcast_to(wo, shape),
        weights,
        grey=False,
        floor=RGL_FLOOR,
    )
    return _with_adds(rows, adds)


def to_csv(rows: list[dict]) -> bytes:
    buf = io.StringIO()
    buf.write("# Ward fits to real measured BRDFs; written by benchmarks/real_brdf_fits.py (see its docstring)\n")
    buf.write(",".join(COLUMNS) + "\n")
    for r in rows:
        vals = [r[c] if isinstance(r[c], str) else f"{float(r[c]):.6g}" for c in COLUMNS]
        buf.write(",".join(vals) + "\n")
    return buf.getvalue().encode()


def main() -> None:
    rows = curet_rows()
    if RGL_DIR.is_dir():
        rows += rgl_rows()
    else:
        print(f"{RGL_DIR}: not found, RGL materials skipped", file=sys.stderr)
    path = calibration_path("curet").parent / CSV_NAME  # beside the data it was fitted to
    write_bytes_atomic(path, to_csv(rows))
    for src in ("curet", "rgl"):
        sub = [r for r in rows if r["source"] == src]
        if not sub:
            continue
        for model in MODELS:
            for norm in NORMALIZATIONS:
                s = [r for r in sub if r["model"] == model and r["normalization"] == norm]
                names, counts = np.unique([r["status"] for r in s], return_counts=True)
                print(
                    f"{src:5s} {model:11s} {norm:19s} n={len(s):2d}"
                    f" median reduced χ² {np.median([r['reduced_chi2'] for r in s]):8.2f}"
                    f" median rel RMS {np.median([r['rel_rms'] for r in s]):.3f}  "
                    + ", ".join(f"{a} {b}" for a, b in zip(names, counts, strict=True))
                )
    per_material = {r["material"]: r["discover_adds"] for r in rows}
    names, counts = np.unique(list(per_material.values()), return_counts=True)
    print("discover adds: " + ", ".join(f"{a} {b}" for a, b in zip(names, counts, strict=True)))
    print(f"wrote {path} ({len(rows)} rows)")


if __name__ == "__main__":
    main()
