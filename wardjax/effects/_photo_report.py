"""The report of :func:`~wardjax.effects.discover_photo`: what was named, the gap per step, the lobes and their labels.

:meth:`PhotoDiscoveryReport.save` writes ``report.json``, ``report.md``,
``gap.png`` (the gap per step), ``labels.png`` (each pixel coloured by the
lobe it carries), ``labels.npy`` (the same as integers) and ``residual.png``
(each block's χ² per observation), each file
atomically — what ``wardjax diagnose`` writes for a photograph capture.
"""

from __future__ import annotations

import dataclasses
import io
import json
import math
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from .._files import write_bytes_atomic
from ._photo_checks import where_text
from ._report import Candidate, _fmt, _num, gap_figure

if TYPE_CHECKING:
    from ._photo_states import StateFit

__all__ = ["PhotoDiscoveryReport", "PhotoStep", "lobes_table"]

# lobe colours of labels.png (matplotlib's tab10, as 8-bit sRGB)
_PALETTE = np.array(
    [[31, 119, 180], [255, 127, 14], [44, 160, 44], [214, 39, 40], [148, 103, 189], [140, 86, 75], [227, 119, 194]],
    np.uint8,
)
_NOTHING = "nothing needed: the gap is within the noise"
_UNEXPLAINED = "unexplained: the gap stays {gap:.3g}× the noise and no library effect explains the rest"


@dataclasses.dataclass(frozen=True, eq=False)
class PhotoStep:
    """One effect added: its parameters ± σ, the evidence, every candidate of the step, the gap before → after."""

    effect: str
    title: str
    params: dict
    stderr: dict
    evidence: Candidate
    candidates: list
    gap_before: float
    gap_after: float


def lobes_table(fit: StateFit) -> list[dict]:
    """Each lobe of a fitted state: ρs, α with σ, and the problems that carry it."""
    res = fit.pixel
    if res is None:
        sh = fit.shared
        return [{"label": 0, "rho_s": sh.rho_s, "alpha": sh.alpha, "alpha_sigma": sh.alpha_sigma, "problems": None}]
    labels = np.asarray(res.labels)  # pyright: ignore[reportAttributeAccessIssue]
    st = res.stderr  # pyright: ignore[reportAttributeAccessIssue]
    rho_s, alpha = np.asarray(res.rho_s), np.asarray(res.alpha_x)  # pyright: ignore[reportAttributeAccessIssue]
    counts = np.bincount(labels, minlength=rho_s.shape[0])
    return [
        {
            "label": i,
            "rho_s": float(rho_s[i]),
            "rho_s_sigma": float(np.asarray(st.rho_s)[i]),
            "alpha": float(alpha[i]),
            "alpha_sigma": float(np.asarray(st.alpha_x)[i]),
            "problems": int(counts[i]),
        }
        for i in range(rho_s.shape[0])
    ]


def _where_dict(where: dict) -> dict:
    out = {k: v for k, v in where.items() if k != "chi2_map"}
    return out | {"map": "residual.png"}


def _refused_dict(r: dict) -> dict:
    return {
        k: ({n: _num(x) for n, x in v.items()} if isinstance(v, dict) else _num(v) if isinstance(v, float) else v)
        for k, v in r.items()
    }


def _pm(v, s) -> str:
    """``v ± s`` as the scanline report writes it (:func:`._report._fmt`); "–" for no value."""
    return "–" if v is None else _fmt(float(v), math.nan if s is None else float(s))


@dataclasses.dataclass(frozen=True, eq=False)
class PhotoDiscoveryReport:
    """What :func:`~wardjax.effects.discover_photo` found.

    Attributes
    ----------
    found
        Names of the effects added, in order.
    gap
        ``χ²/dof`` after each step, starting with the baseline (the paper's model).
    steps
        One ``PhotoStep`` per effect added.
    partial
        Candidates with evidence that did not predict the held-out half (not named).
    ambiguous
        ``(named, other, ΔBIC difference)``: another radial effect explained the step
        nearly as well (with the lamp at the lens the two cannot be told apart).
    lobes
        The final model's lobes: ρs, α ± σ and how many problems carry each.
    labels
        ``(P,)`` the lobe each problem carries (row-major over ``grid``).
    grid
        ``(rows, columns, block)`` of the problems in the image.
    within_noise
        The final gap is within what the noise gives (``χ² − dof ≤ 2 √(2 dof)``).
    n_photos
        Photos each problem is seen in.
    not_identifiable
        Candidates not tried, each with why the data cannot identify it.
    unphysical
        ``{step, why, gap, gap_bounded}``: the model a step started from had a lobe no material has; that
        step tried the radial effects first, with the shared lobe held within ``α ≤ 1``, ``ρs ≤ 1``
        (``gap_bounded`` its gap so held; ``None`` where the lobes were per cluster and could not be held).
    where
        Where the final residual lives (:func:`wardjax.effects._photo_checks.residual_where`).
    refused
        ``{step, effect, why, gap_before, gap_after, delta_bic_held, params, stderr}``: radial effects that
        passed their evidence and hold-out on the held structure but were not added, because the structure
        refitted with them did not lower the gap.
    """

    name: str
    n_obs: int
    grid: tuple[int, int, int]
    found: list
    gap: list
    steps: list
    partial: list
    ambiguous: list
    baseline: dict
    final_chi2: float
    final_dof: int
    within_noise: bool
    lobes: list
    labels: np.ndarray
    lamp_offset: float
    settings: dict
    seconds: float
    n_photos: int = 1
    not_identifiable: dict = dataclasses.field(default_factory=dict)
    unphysical: list = dataclasses.field(default_factory=list)
    where: dict | None = None
    refused: list = dataclasses.field(default_factory=list)

    @property
    def not_told_apart(self) -> list:
        """The entries of ``ambiguous`` whose other effect was not named itself in a later step."""
        return [a for a in self.ambiguous if a[1] not in self.found]

    def verdict(self) -> str:
        named = ", ".join(self.found)
        named += "".join(f" (or {b}: not told apart)" for _, b, _ in self.not_told_apart)
        if self.within_noise:
            text = f"found {named}; the gap is within the noise" if self.found else _NOTHING
        else:
            text = _UNEXPLAINED.format(gap=self.gap[-1])
            text = f"found {named}, but {text}" if self.found else text
            if self.where is not None:
                text += f" ({where_text(self.where, self.n_photos)})"
        notes = [
            f"the paper's model has a lobe no material has ({u['why']}): radial effects tried first, on a lobe held "
            f"within α ≤ 1, ρs ≤ 1"
            for u in self.unphysical[:1]
            if u["step"] == 0
        ]
        notes += [f"{n} not tried ({why})" for n, why in self.not_identifiable.items()]
        return "; ".join([text, *notes])

    def label_image(self) -> np.ndarray:
        """``(rows · block, columns · block)`` the lobe each pixel carries."""
        rows, cols, b = self.grid
        lab = np.asarray(self.labels).reshape(rows, cols)
        return np.repeat(np.repeat(lab, b, 0), b, 1)

    def to_dict(self) -> dict:
        """JSON-ready summary (what ``report.json`` holds)."""

        def step(s: PhotoStep) -> dict:
            return {
                "effect": s.effect,
                "title": s.title,
                "params": {k: _num(v) for k, v in s.params.items()},
                "stderr": {k: _num(v) for k, v in s.stderr.items()},
                "evidence": s.evidence.as_dict(),
                "gap_before": _num(s.gap_before),
                "gap_after": _num(s.gap_after),
                "candidates": [c.as_dict() for c in s.candidates],
            }

        return {
            "capture": self.name,
            "kind": "photo",
            "n_obs": self.n_obs,
            "found": list(self.found),
            "gap": [_num(g) for g in self.gap],
            "verdict": self.verdict(),
            "baseline": {k: _num(v) for k, v in self.baseline.items()},
            "steps": [step(s) for s in self.steps],
            "not_predicting": [c.as_dict() for c in self.partial],
            "ambiguous": [{"named": a, "or": b, "delta_bic_difference": _num(d)} for a, b, d in self.ambiguous],
            "final": {"chi2": _num(self.final_chi2), "dof": self.final_dof, "within_noise": self.within_noise},
            "lobes": [{k: _num(v) for k, v in lb.items()} for lb in self.lobes],
            "labels": {"file": "labels.npy", "image": "labels.png", "grid": list(self.grid)},
            "lamp_offset": _num(self.lamp_offset),
            "n_photos": self.n_photos,
            "not_identifiable": dict(self.not_identifiable),
            "unphysical": [{k: _num(v) if isinstance(v, float) else v for k, v in u.items()} for u in self.unphysical],
            "residual": None if self.where is None else _where_dict(self.where),
            "refused": [_refused_dict(r) for r in self.refused],
            "settings": self.settings,
            "seconds": _num(self.seconds),
        }

    def to_markdown(self) -> str:
        rows, cols, b = self.grid
        L = [
            f"# Missing-effect discovery: {self.name}\n",
            f"**Model:** the paper's — ρd per block of {b}×{b} pixels ({rows}×{cols} blocks), one lobe shared by "
            f"the sample — on {self.n_obs} observations.\n",
            f"**Verdict:** {self.verdict()}.\n",
            "## Gap per step\n",
            "| step | model | gap (χ²/dof) |\n|---|---|---|",
            f"| 0 | baseline | {self.gap[0]:.4g} |",
        ]
        L += [f"| {i} | + {s.effect} | {self.gap[i]:.4g} |" for i, s in enumerate(self.steps, 1)]
        L.append("\n![gap per step](gap.png)\n")
        bl = self.baseline
        L.append(f"Baseline lobe: ρs = {bl['rho_s']:.4g}, α = {bl['alpha']:.4g}.\n")
        for i, s in enumerate(self.steps, 1):
            ev = s.evidence
            L.append(f"## Step {i}: {s.effect} — {s.title}\n")
            L.append("Parameters: " + ", ".join(f"{k} = {_pm(v, s.stderr.get(k))}" for k, v in s.params.items()) + "\n")
            ho = ev.holdout
            held = "" if ho is None else f"; held-out gain {ho.gain:.1f} ({100 * ho.share:.0f} % of its Δχ²)"
            L.append(
                f"Evidence: Δχ² = {ev.delta_chi2:.1f}, ΔBIC = {ev.delta_bic:.1f} (k = {ev.k}), LR p = "
                f"{ev.p_value:.2g}{held}; gap {s.gap_before:.4g} → {s.gap_after:.4g}.\n"
            )
            L.append("| candidate | k | Δχ² | ΔBIC | LR p |\n|---|---|---|---|---|")
            L += [
                f"| {c.effect} | {c.k} | {c.delta_chi2:.1f} | {c.delta_bic:.1f} | {c.p_value:.2g} |"
                for c in s.candidates
            ]
            L.append("")
        if self.not_told_apart:
            L.append("## Not told apart\n")
            why = (
                "the lamp is at the lens: lens and lamp see every point at nearly the same angle"
                if self.lamp_offset < 0.05
                else "their ΔBIC are close"
            )
            L += [f"- {a} or {o} (ΔBIC differs by {d:.1f}): {why}." for a, o, d in self.not_told_apart]
            L.append("")
        if self.partial:
            L.append("## Supported, but not predicting the held-out half (not named)\n")
            L += [
                f"- {c.effect}: ΔBIC = {c.delta_bic:.1f}, held-out gain "
                f"{c.holdout.gain:.1f} ({100 * c.holdout.share:.0f} % of its Δχ²)"
                for c in self.partial
                if c.holdout is not None
            ]
            L.append("")
        if self.refused:
            L.append("## Refused: no lower gap once the structure is refitted (not named)\n")
            for r in self.refused:
                params = ", ".join(f"{k} = {_pm(v, r['stderr'].get(k))}" for k, v in r["params"].items())
                L.append(
                    f"- step {r['step']}: {r['effect']} ({params}; ΔBIC {r['delta_bic_held']:.1f} on the held "
                    f"structure): gap {r['gap_before']:.4g} → {r['gap_after']:.4g} refitted; {r['why']}."
                )
            L.append("")
        if self.unphysical:
            L.append("## A lobe no material has\n")
            for u in self.unphysical:
                held = (
                    "" if u["gap_bounded"] is None else f"; held within α ≤ 1, ρs ≤ 1 its gap is {u['gap_bounded']:.4g}"
                )
                L.append(
                    f"- before step {u['step'] + 1}: {u['why']} (gap {u['gap']:.4g}{held}); the radial effects "
                    "were tried first."
                )
            L.append("")
        if self.not_identifiable:
            L.append("## Not identifiable from these data (not tried)\n")
            L += [f"- {n}: {w}." for n, w in self.not_identifiable.items()]
            L.append("")
        if self.where is not None:
            L.append("## Where the residual lives\n")
            L.append(f"{where_text(self.where, self.n_photos)}.\n")
            L.append("| region (radius over the largest) | share of χ² | share of observations |\n|---|---|---|")
            L += [
                f"| {b['band']} | {100 * b['chi2_share']:.0f} % | {100 * b['obs_share']:.0f} % |"
                for b in self.where["bands"]
            ]
            L.append("\n![χ² per observation of each block](residual.png)\n")
        L.append("## Lobes and the pixels that carry them\n")
        L.append("| label | ρs | α | blocks |\n|---|---|---|---|")
        for lb in self.lobes:
            n = lb["problems"]
            rho_s, alpha = _pm(lb["rho_s"], lb.get("rho_s_sigma")), _pm(lb["alpha"], lb.get("alpha_sigma"))
            L.append(f"| {lb['label']} | {rho_s} | {alpha} | {'all' if n is None else n} |")
        L.append("\n![lobe per pixel](labels.png)\n")
        L.append(
            f"_Criterion: largest ΔBIC, added if ΔBIC > 0, Bonferroni LR p < {self.settings['alpha']}, and "
            f"predicting the held-out half (gain ≥ {100 * self.settings['holdout_share']:.0f} % of its Δχ²); "
            f"stop once the gap is within the noise. Time {self.seconds:.1f} s._"
        )
        return "\n".join(L) + "\n"

    def __str__(self) -> str:
        return self.to_markdown()

    def save(self, out_dir, *, extra: dict | None = None) -> dict[str, Path]:
        """Write ``report.json``, ``report.md`` and the figures and label map of the module docstring (atomic)."""
        from .._files import write_image

        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        fig = gap_figure(self.gap, ["baseline"] + [f"+ {s}" for s in self.found], title=self.name or None)
        write_bytes_atomic(out / "gap.png", _png(fig))
        lab = self.label_image()
        write_image(out / "labels.png", _PALETTE[lab % len(_PALETTE)])
        buf = io.BytesIO()
        np.save(buf, lab.astype(np.int16))
        write_bytes_atomic(out / "labels.npy", buf.getvalue())
        if self.where is not None:
            write_bytes_atomic(out / "residual.png", _png(residual_figure(self.where["chi2_map"], self.grid[2])))
        d = self.to_dict() | (extra or {})
        write_bytes_atomic(out / "report.json", (json.dumps(d, indent=2, ensure_ascii=False) + "\n").encode())
        write_bytes_atomic(out / "report.md", self.to_markdown().encode())
        names = ("report.json", "report.md", "gap.png", "labels.png", "labels.npy")
        return {n: out / n for n in (*names, *(("residual.png",) if self.where is not None else ()))}


def _png(fig) -> bytes:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110)
    return buf.getvalue()


def residual_figure(chi2_map: np.ndarray, block: int):
    """Each block's χ² per observation (1 = the noise), on a log colour scale, axes in pixels."""
    from matplotlib.colors import LogNorm
    from matplotlib.figure import Figure

    rows, cols = chi2_map.shape
    fig = Figure(figsize=(4.8, 4.0 * rows / max(cols, 1) + 0.6), layout="constrained")
    ax = fig.add_subplot()
    v = np.clip(chi2_map, 1e-2, None)
    im = ax.imshow(
        v,
        norm=LogNorm(vmin=min(1.0, float(v.min())), vmax=max(10.0, float(v.max()))),
        extent=(0, cols * block, rows * block, 0),
        cmap="magma",
        interpolation="nearest",
    )
    ax.set_xlabel("x (pixels fitted)")
    ax.set_ylabel("y (pixels fitted)")
    ax.set_title("residual per block", fontsize=9)
    fig.colorbar(im, ax=ax).set_label("χ² per observation (1 = the noise)")
    return fig
