"""Capture-level z-scores: are the σ that ``wardjax fit`` reports for ρs, αx, αy honest?

Draws ``N`` captures as ``wardjax simulate`` writes them (8-bit sRGB PNG,
the default rig and sensor noise) with parameters drawn from a seeded
generator — ρs 0.02–0.08, αx and αy 0.05–0.25 with αy/αx between 1/1.35
and 1.35, a grey-to-coloured ρd, the textures ``wood``, ``marble``,
``noise`` and ``none`` in turn — fits each with :func:`wardjax.fit_capture`
(what ``wardjax fit`` calls, with its defaults), and prints per capture the
truth, the estimate, the reported σ and ``z = (estimate − truth)/σ``, then
the robust SD of z (``1.4826 · MAD``, about the median) of ρs, αx, αy,
overall and by texture.

An honest σ gives a robust z-SD near 1 (between 0.8 and 1.25 over 40
captures, the sampling spread of the statistic included).

Run ``python -m benchmarks.capture_z [--n 48] [--size 240 180] [--seed 0]
[--out benchmarks/results/capture_z.md]``.

``--texture-alone DRAWS`` checks the texture-field estimator without a fit:
the response of one capture's joint fit (its true parameters, untextured
rig) to ``DRAWS`` textures of each kind drawn on its sample points gives the
Monte-Carlo spread of (ρs, αx, αy); beside it, the root-mean σ the estimator
reads from each texture itself and from what the fit leaves of it (its
residual), into ``benchmarks/results/capture_z_texture_alone.md``.
"""

from __future__ import annotations

import argparse
import dataclasses
import tempfile
import time
from pathlib import Path

import numpy as np

__all__ = ["TEXTURES", "CaptureZ", "draw_params", "fit_one", "robust_sd", "run", "summary", "texture_alone"]

TEXTURES = ("wood", "marble", "noise", "none")
SHARED = ("rho_s", "alpha_x", "alpha_y")


@dataclasses.dataclass(frozen=True)
class CaptureZ:
    """One capture: its seed, texture, and per parameter (ρs, αx, αy) truth, estimate and σ."""

    seed: int
    texture: str
    truth: np.ndarray  # (3,)
    estimate: np.ndarray  # (3,)
    sigma: np.ndarray  # (3,)
    seconds: float
    other_sigma: dict = dataclasses.field(default_factory=dict)  # σ of the other error models (diagnostics)

    @property
    def z(self) -> np.ndarray:
        return (self.estimate - self.truth) / self.sigma


def draw_params(seed: int):
    """The Ward parameters of capture ``seed``: ρs 0.02–0.08, α 0.05–0.25, αy/αx in [1/1.35, 1.35]."""
    import wardjax as wj

    rng = np.random.default_rng([20260, seed])
    ratio = float(np.exp(rng.uniform(-np.log(1.35), np.log(1.35))))  # αy / αx
    lo, hi = max(0.05, 0.05 / ratio), min(0.25, 0.25 / ratio)
    alpha_x = float(np.exp(rng.uniform(np.log(lo), np.log(hi))))
    rho_d = tuple(float(v) for v in rng.uniform(0.25, 0.7, 3))
    return wj.WardParams(rho_d=rho_d, rho_s=float(rng.uniform(0.02, 0.08)), alpha_x=alpha_x, alpha_y=alpha_x * ratio)


def fit_one(seed: int, size: tuple[int, int], root: Path) -> CaptureZ:
    """Simulate capture ``seed`` into ``root`` (texture by ``seed`` modulo 4) and fit it as ``wardjax fit`` does."""
    from wardjax import fit_capture, load_capture
    from wardjax.simulate import simulate_capture

    p = draw_params(seed)
    texture = TEXTURES[seed % len(TEXTURES)]
    folder = root / f"capture_{seed:03d}"
    simulate_capture(p, folder, seed=seed, image_size=size, texture=texture)
    t0 = time.perf_counter()
    out = fit_capture(load_capture(folder))
    seconds = time.perf_counter() - t0
    get = lambda w: np.array([float(getattr(w, k)) for k in SHARED])
    errs = out.diagnostics["errors"]
    other = {k: np.array(errs[k], float) for k in ("texture_field", "scanline_sandwich", "model")}
    return CaptureZ(seed, texture, get(p), get(out.params), get(out.stderr), seconds, other)


def robust_sd(z) -> float:
    """``1.4826 · median |z − median z|``: the SD of a normal sample, insensitive to a few outliers."""
    z = np.asarray(z, float)
    return float(1.4826 * np.median(np.abs(z - np.median(z))))


def run(n: int, size: tuple[int, int], seed: int = 0, progress=None) -> list[CaptureZ]:
    """Fit captures ``seed … seed + n − 1`` in a temporary folder."""
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for s in range(seed, seed + n):
            rows.append(fit_one(s, size, Path(tmp)))
            if progress is not None:
                progress(rows[-1])
    return rows


def summary(rows: list[CaptureZ]) -> dict[str, np.ndarray]:
    """Robust z-SD of (ρs, αx, αy) overall (``"all"``) and by texture."""
    groups = {"all": rows} | {t: [r for r in rows if r.texture == t] for t in TEXTURES}
    return {k: np.array([robust_sd([r.z[i] for r in g]) for i in range(3)]) for k, g in groups.items() if g}


def _row(r: CaptureZ) -> str:
    cells = [f"{r.seed}", r.texture]
    for i in range(3):
        cells += [f"{r.truth[i]:.4f}", f"{r.estimate[i]:.4f}", f"{r.sigma[i]:.2g}", f"{r.z[i]:+.2f}"]
    return "| " + " | ".join(cells + [f"{r.seconds:.1f}"]) + " |"


def report(rows: list[CaptureZ], size: tuple[int, int]) -> str:
    """The Markdown results: provenance, per-capture table, robust z-SD overall and by texture."""
    from .textured_bench import provenance

    z = np.array([r.z for r in rows])
    lines = [
        provenance().rstrip(),
        "",
        f"# Capture-level z: {len(rows)} captures, {size[0]}×{size[1]}, 8-bit sRGB "
        f"(`python -m benchmarks.capture_z --n {len(rows)} --size {size[0]} {size[1]}`)",
        "",
        "| group | n | robust SD z ρs | αx | αy | median z ρs | αx | αy |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for k, sd in summary(rows).items():
        sel = z if k == "all" else np.array([r.z for r in rows if r.texture == k])
        med = np.median(sel, axis=0)
        lines.append(f"| {k} | {len(sel)} | " + " | ".join(f"{v:.2f}" for v in (*sd, *med)) + " |")
    lines += [
        "",
        f"max |z|: {np.max(np.abs(z)):.2f}",
        "",
        "| seed | texture | ρs | est | σ | z | αx | est | σ | z | αy | est | σ | z | fit s |",
        "|" + "---|" * 15,
    ]
    lines += [_row(r) for r in rows]
    return "\n".join(lines) + "\n"


def _fit_grid(seed: int, size: tuple[int, int]):
    """The binned fit grid of capture ``seed`` drawn untextured: ``(params, model, normalization, F, WI, WO, cols,
    points)`` as :func:`wardjax.fit_capture` hands them to the texture-field estimator."""
    from wardjax import load_capture
    from wardjax.run._fit_capture import MIN_SCANLINE_SAMPLES, _bin_bands, prepare_bands
    from wardjax.simulate import simulate_capture

    p = draw_params(seed)
    with tempfile.TemporaryDirectory() as tmp:
        simulate_capture(p, Path(tmp) / "c", seed=seed, image_size=size, texture="none")
        cap = load_capture(Path(tmp) / "c")
        bins = _bin_bands(cap, prepare_bands(cap, band_rows=512), 50_000, 512)[0]
    keep = np.sum(np.all(np.isfinite(bins.f_r), axis=-1), axis=1) >= MIN_SCANLINE_SAMPLES
    fit = cap.config.fit
    return (
        p,
        fit.model,
        fit.normalization,
        bins.f_r[keep],
        bins.wi[keep],
        bins.wo[keep],
        np.flatnonzero(keep),
        (bins.points[keep]),
    )


def texture_alone(seed: int, size: tuple[int, int], draws: int, kinds=TEXTURES[:3]) -> dict[str, np.ndarray]:
    """Per texture kind ``(3, 3)``: Monte-Carlo SD of (ρs, αx, αy) over ``draws`` textures, and the root-mean σ
    :func:`~wardjax.fit.plane_covariance` reads from the texture and from its residual, over that SD."""
    from wardjax.fit._texture_field import _design, plane_covariance
    from wardjax.simulate import plane_texture

    p, model, norm, F, WI, WO, cols, points = _fit_grid(seed, size)
    w, jac, info, _, _ = _design(F, WI, WO, p, model, norm)
    g = np.einsum("pq,qsnc->psnc", np.linalg.pinv(info), jac)
    x, y = (np.nan_to_num(points[..., k]) for k in (0, 1))
    out = {}
    for kind in kinds:
        theta, est = [], []
        for k in range(draws):
            df = w * np.asarray(p.rho_d) * (plane_texture(kind, x, y, seed=1000 + k)[..., None] - 1) / np.pi
            df -= w * df.sum(axis=1, keepdims=True) / np.maximum(w.sum(axis=1, keepdims=True), 1)
            th = np.einsum("psnc,snc->p", g, df)
            resid = df - np.einsum("p,psnc->snc", th, jac)
            theta.append(th)
            est.append([np.diag(plane_covariance(a, w, g, cols, points)) for a in (df, resid)])
        mc = np.sqrt(np.mean(np.square(theta), axis=0))
        out[kind] = np.vstack([mc, np.sqrt(np.mean(est, axis=0)) / mc])
    return out


def _texture_alone_report(res: dict, seed: int, size: tuple[int, int], draws: int) -> str:
    from .textured_bench import provenance

    lines = [
        provenance().rstrip(),
        "",
        f"# The texture-field σ on textures alone: capture {seed}'s response, {draws} textures per kind "
        f"(`python -m benchmarks.capture_z --texture-alone {draws} --seed {seed} --size {size[0]} {size[1]}`)",
        "",
        "| texture | MC SD ρs | αx | αy | σ/SD from the texture ρs | αx | αy | from its residual ρs | αx | αy |",
        "|" + "---|" * 10,
    ]
    for kind, (mc, true, resid) in res.items():
        lines.append(
            f"| {kind} | " + " | ".join([f"{v:.2g}" for v in mc] + [f"{v:.2f}" for v in (*true, *resid)]) + " |"
        )
    return "\n".join(lines) + "\n"


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=48, help="captures (default 48)")
    ap.add_argument("--size", type=int, nargs=2, default=(240, 180), metavar=("W", "H"))
    ap.add_argument("--seed", type=int, default=0, help="first capture's seed")
    ap.add_argument("--out", type=Path, default=None, help="results file (default under benchmarks/results/)")
    ap.add_argument("--texture-alone", type=int, default=0, metavar="DRAWS", help="check the estimator, no fit")
    a = ap.parse_args(argv)
    size = (int(a.size[0]), int(a.size[1]))
    if a.texture_alone:
        text = _texture_alone_report(texture_alone(a.seed, size, a.texture_alone), a.seed, size, a.texture_alone)
        print(text)
        out = a.out or Path("benchmarks/results/capture_z_texture_alone.md")
        out.parent.mkdir(parents=True, exist_ok=True)
        out.write_text(text)
        return
    rows = run(a.n, size, a.seed, progress=lambda r: print(_row(r), flush=True))
    text = report(rows, size)
    print(text)
    out = a.out or Path("benchmarks/results/capture_z.md")
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(text)


if __name__ == "__main__":
    main()
