"""The discovery report: steps, evidence, gap per step, plots; JSON, Markdown and HTML.

The same :class:`DiscoveryReport` prints in a terminal (``str``), renders in a
notebook (``_repr_html_`` / ``_repr_markdown_``) and is written to a folder by
:meth:`DiscoveryReport.save` (``report.json``, ``report.md``, PNGs) — what
``wardjax diagnose`` writes.
"""

from __future__ import annotations

import base64
import dataclasses
import io
import json
import math
from pathlib import Path
from typing import NamedTuple

import numpy as np

from .._files import write_bytes_atomic
from ._averaging import model_averaged
from ._structure import _binned_test, covariate_label

__all__ = ["Candidate", "DiscoveryReport", "FitState", "HoldoutRead", "Step", "VariogramRead"]


@dataclasses.dataclass(frozen=True, eq=False)
class FitState:
    """One fitted model: parameter vector, χ², dof, gap, covariance, values ± σ, active effects."""

    u: np.ndarray
    chi2: float
    dof: int
    gap: float
    ok: bool
    cov: np.ndarray
    active: tuple[int, ...]
    values: dict
    sigma: dict
    free: tuple[int, ...]  # indices of u the fit moved (an effect's optional parameters may stay held)


class HoldoutRead(NamedTuple):
    """The two-fold hold-out of one winner (:mod:`wardjax.effects._holdout`): ``gain``, the held-out ``χ²`` it
    removed over both folds, its ``share`` of the in-sample Δχ², and whether it ``passed`` (may be named: the gain
    sufficed, or the read is ``inconclusive``: a fold's refit of the current model alone ``lost`` more held-out
    χ² than the winner's Δχ²)."""

    gain: float
    share: float
    passed: bool
    inconclusive: bool = False
    lost: float = math.nan


class VariogramRead(NamedTuple):
    """A winner and the model before it refitted under the texture's covariance from the variogram.

    ``gap`` and ``gap_p`` (``P(χ²_dof ≥ χ²)``) of the model with the winner,
    the fraction of the excess it ``explained``, ``gap_before``, the
    model without it, and ``delta_chi2``, what the winner lowers χ² by there
    (:mod:`wardjax.effects._recheck`).
    """

    gap: float
    gap_p: float
    explained: float
    gap_before: float
    delta_chi2: float = math.nan

    def names(self, k: int, ln_n: float, design_effect: float, min_explained: float, structure_p: float) -> bool:
        """Whether this reading lets a questioned winner (``k`` parameters) be named.

        Only if the winner pays for its parameters under this covariance too,
        ``Δχ²/D − k ln N > 0`` (``D`` its design effect), *and* it explains at least
        ``min_explained`` of the excess or leaves a gap within the noise
        (``gap_p ≥ structure_p``). A gap within the noise alone is not enough:
        where the model without the winner is within the noise as well, the
        winner "explains" an excess that is not there (an effect that lowers χ²
        by nothing would pass).
        """
        pays = self.delta_chi2 / max(design_effect, 1.0) - k * ln_n > 0
        return bool(pays and (self.explained >= min_explained or self.gap_p >= structure_p))


@dataclasses.dataclass(frozen=True, eq=False)
class Candidate:
    """One candidate extension at one step.

    Attributes
    ----------
    effect, k
        Effect name; parameters counted in the evidence.
    delta_chi2
        Deviance drop against the current model (0 if only unphysical fits).
    delta_bic
        ``Δχ² − k ln N``: positive favours the extension.
    p_value
        Likelihood-ratio p-value (boundary-corrected for one-sided amplitudes).
    explained
        Fraction of the current excess ``χ² − dof`` it removes.
    structure_p
        Binned-residual test against the effect's telling covariate, before fitting.
    physical
        Some start converged on the physical side.
    gap_p_after
        ``P(χ²_dof ≥ χ²)`` of the model with the effect: small when a
        significant gap remains (a partial match if it also explains little).
    design_effect
        ``D ≥ 1`` that divided Δχ² in ΔBIC and the p-value: the texture
        between scanlines and channels (1 without the texture term; see
        :func:`wardjax.effects._texture.design_effect`).
    holdout
        :class:`HoldoutRead`: the winner fitted on half the scanlines
        predicting the other half (:mod:`wardjax.effects._holdout`); read for
        the winner of each step, ``None`` for the others and where the data
        have too few scanlines.
    signature
        ``(covariate, χ², bins, p, left)``: the binned test of the residuals
        against the effect's own telling covariate once it is fitted, and the
        share of that covariate's structure (``χ² − bins``) it ``left``; set
        where the effect was named on a gap that stayed beyond the noise and
        was taken back because its own covariate kept its structure (``None``
        otherwise; ``_Steps.unsigned`` in :mod:`wardjax.effects._discover`).
    variogram
        :class:`VariogramRead`: the model with the effect (and the model
        without it) refitted under the texture's covariance from the
        variogram — the partial-match guard's second opinion, read only
        where the guard would refuse (:mod:`wardjax.effects._recheck`);
        ``None`` otherwise.
    converged
        Its fit converged. ``False`` when Levenberg–Marquardt stopped at its
        step cap: Δχ² and ΔBIC are then lower bounds. ``discover`` continues
        such a fit when it would win or reaches half the winner's ΔBIC.
    """

    effect: str
    k: int
    delta_chi2: float
    delta_bic: float
    p_value: float
    explained: float
    structure_p: float
    physical: bool
    state: FitState | None = None
    gap_p_after: float = math.nan
    design_effect: float = 1.0
    variogram: VariogramRead | None = None
    holdout: HoldoutRead | None = None
    signature: tuple[str, float, int, float, float] | None = None

    @property
    def converged(self) -> bool:
        return self.state is None or bool(self.state.ok)

    def as_dict(self) -> dict:
        v = {} if self.variogram is None else self.variogram._asdict()
        h = {} if self.holdout is None else self.holdout._asdict()
        sig = {} if self.signature is None else dict(zip(("covariate", "chi2", "bins", "p", "left"), self.signature))
        return (
            {f"{k}_variogram": _num(x) for k, x in v.items()}
            | {f"signature_{k}": _num(x) for k, x in sig.items()}
            | {f"holdout_{k}": _num(x) for k, x in h.items()}
            | {
                k: _num(getattr(self, k))
                for k in (
                    "effect",
                    "k",
                    "delta_chi2",
                    "delta_bic",
                    "p_value",
                    "explained",
                    "structure_p",
                    "physical",
                    "gap_p_after",
                    "design_effect",
                    "converged",
                )
            }
        )


@dataclasses.dataclass(frozen=True, eq=False)
class Step:
    """One effect added: its fitted parameters ± σ, the evidence, the gap before → after, plot data."""

    effect: str
    title: str
    side: str
    params: dict
    stderr: dict
    evidence: Candidate
    candidates: list
    gap_before: float
    gap_after: float
    plot: dict | None = None


# what would tell apart two effects one capture could not (``report.ambiguous``)
_SEPARATE = {
    frozenset({"illumination_gradient", "anisotropy"}): "a second capture with the probe turned by 90° would: "
    "anisotropy turns with it, the illumination does not",
    frozenset({"illumination_gradient", "fresnel"}): "a second capture with the lamp higher or lower would: the "
    "Fresnel rise follows the incidence angle, the illumination the image position",
    frozenset({"gamma", "coloured_specular"}): "a grey chart in the frame or a second exposure would: a camera "
    "response bends every level, the diffuse floor too; a coloured specular scales the lobe alone",
    frozenset({"ambient", "encoding"}): "a second exposure would: light from the room scales with the lamp's "
    "light at any exposure, an encoding bends each level by its code, so its share of the darks moves",
    frozenset({"ambient", "glare"}): "a black patch in the frame near the highlight would: light from the room "
    "lifts it as it lifts a black patch far away, the lens's glare lifts it more the nearer it lies to the bright "
    "highlight and standard",
}


def _num(x):
    if isinstance(x, (bool, np.bool_)):
        return bool(x)
    if isinstance(x, (int, np.integer)):
        return int(x)
    if isinstance(x, (float, np.floating)):
        x = float(x)
        return x if math.isfinite(x) else None
    return x


def _texture_paragraph(tex: dict) -> str:
    """What report.md says of the ρd texture the baseline's residuals were read for (``settings["texture"]``)."""
    amp = ", ".join(f"{100 * a:.1f}" for a in tex.get("amplitude", []))
    shown = tex.get("dark_shown")
    if "refused" in tex and shown is not None:
        return (
            f"The residuals off the highlight vary like a ρd texture ({amp} % of the diffuse level per channel), "
            f"but the dark frame, which holds the probe's texture under the room's light, shows "
            f"{100 * shown[0]:.0f} ± {100 * shown[1]:.0f} % of it: that structure is taken for the model's misfit, "
            "not texture, and the noise is taken as white."
        )
    rho = ", ".join(f"{r:.2f}" for r in tex.get("rho", []))
    dark = f" The dark frame shows {100 * shown[0]:.0f} ± {100 * shown[1]:.0f} % of it." if shown is not None else ""
    return (
        f"The probe's ρd texture is carried in the noise as a Gaussian process: {amp} % of the diffuse level per "
        f"channel, correlation {rho} between neighbouring samples.{dark}"
    )


def _fmt(v: float, s: float) -> str:
    if s is None or not np.isfinite(s) or s == 0:
        return f"{v:.4g}"
    return f"{v:.4g} ± {s:.2g}"


def _ambiguity(named: str, other: str, d: float) -> str:
    """How far apart two effects one capture did not tell apart were: ``d`` is ``ΔBIC(named) − ΔBIC(other)``."""
    if d >= 0:
        return f"ΔBIC differs by {d:.1f} only"
    return (
        f"{other}'s ΔBIC is {-d:.1f} higher, each deflated by its own design effect, but {named} lowers χ² "
        "at least as much with no more parameters"
    )


@dataclasses.dataclass(frozen=True, eq=False)
class DiscoveryReport:
    """What :func:`~wardjax.effects.discover` found.

    Attributes
    ----------
    found
        Names of the effects added, in order.
    gap
        Reduced χ² after each step, starting with the baseline.
    steps
        One :class:`Step` per effect added.
    unexplained
        Sentences describing structure left that no library effect explains
        (empty when the residuals are consistent with the noise).
    structure
        Final binned-residual test per covariate.
    not_detectable
        ``(name, reason)`` for effects that cancel by the rig's symmetry.
    not_testable
        ``(name, reason)`` for effects the data cannot test (missing covariates).
    partial
        Effects strongly supported but explaining too little to be named.
    baseline, final
        The fitted baseline and final models (:class:`FitState`).
    discrepancy
        Where a gap beyond the noise remains, the discrepancy term that widens
        the parameters' σ (:mod:`~wardjax.effects._discrepancy`): ``covariate``,
        ``bins``, ``tau``, ``length``, ``sigma`` per parameter and ``readings``
        (the term along each covariate with structure); else ``None``.
    ambiguous
        ``(named, other, ΔBIC difference)`` where an effect with a different
        signature explained the step almost as well (illumination
        non-uniformity against anisotropy): one capture cannot tell them
        apart, and both are named. The difference is negative where the
        named effect lowers χ² at least as much with no more parameters but
        its own design effect deflated it more.
    """

    model: str
    model_kind: str
    n_obs: int
    n_profiled: int
    baseline: FitState
    final: FitState
    found: list
    gap: list
    steps: list
    unexplained: list
    structure: dict
    not_detectable: list
    not_testable: list
    partial: list
    tested: list
    seconds: float
    settings: dict
    ambiguous: list = dataclasses.field(default_factory=list)
    discrepancy: dict | None = None

    # ---------------------------------------------------------------- summaries
    @property
    def explained(self) -> bool:
        """True when no unexplained structure remains."""
        return not self.unexplained

    @property
    def within_noise(self) -> bool:
        """The search stopped because the gap is within what noise alone gives (``settings["stop_rule"]``)."""
        return bool(self.settings.get("stopped_within_noise", False))

    @property
    def averaged(self) -> dict[str, dict[str, float]]:
        """The model's ρs and α averaged over the last step's candidate models by their evidence: ``value``,
        ``sigma`` (with the model choice's spread and the discrepancy term's σ), ``sigma_model`` (the chosen
        model's) and ``sigma_discrepancy`` (0 where the gap is within the noise); see
        :mod:`wardjax.effects._averaging` and :mod:`wardjax.effects._discrepancy`."""
        return model_averaged(self.steps, self.baseline, self.ambiguous, self.discrepancy)

    def _under(self) -> str:
        """Where the variogram's covariance read the final gap: the words that say so, else nothing."""
        v = self.settings.get("variogram_gap")
        return "" if v is None else f" under the texture's covariance from the variogram (gap {v:.3f})"

    def verdict(self) -> str:
        if self.within_noise:
            what = f"found {', '.join(self.found)}" if self.found else "nothing needed"
            if self.ambiguous:
                what += "".join(f" (or {b}: not told apart)" for _, b, _ in self.ambiguous)
            return f"{what}; the gap is within the noise{self._under()}: nothing further needed"
        if self.found and self.explained:
            return f"found {', '.join(self.found)}; the residuals are now consistent with the noise{self._under()}"
        if self.found:
            return f"found {', '.join(self.found)}, but structure remains that no library effect explains"
        if self.explained:
            return "nothing needed: the baseline explains the data to the noise level"
        return "unexplained discrepancy: no library effect explains it"

    def to_dict(self) -> dict:
        """JSON-ready summary (what ``report.json`` holds)."""
        return {
            "model": self.model,
            "n_obs": self.n_obs,
            "found": list(self.found),
            "gap": [_num(g) for g in self.gap],
            "verdict": self.verdict(),
            "baseline": {
                "params": self.baseline.values.get("model", {}),
                "stderr": {k: _num(v) for k, v in self.baseline.sigma.get("model", {}).items()},
                "chi2": _num(self.baseline.chi2),
                "dof": self.baseline.dof,
            },
            "steps": [
                {
                    "effect": s.effect,
                    "title": s.title,
                    "side": s.side,
                    "params": {k: _num(v) for k, v in s.params.items()},
                    "stderr": {k: _num(v) for k, v in s.stderr.items()},
                    "evidence": s.evidence.as_dict(),
                    "gap_before": _num(s.gap_before),
                    "gap_after": _num(s.gap_after),
                    "candidates": [c.as_dict() for c in s.candidates],
                }
                for s in self.steps
            ],
            "final": {
                "params": {
                    k: {n: _num(v) for n, v in d.items()}
                    for k, d in self.final.values.items()
                    if k == "model" or k in self.found
                },
                "chi2": _num(self.final.chi2),
                "dof": self.final.dof,
            },
            "averaged": {k: {n: _num(v) for n, v in d.items()} for k, d in self.averaged.items()},
            "discrepancy": None
            if self.discrepancy is None
            else {k: _num(v) if isinstance(v, float) else v for k, v in self.discrepancy.items()},
            "unexplained": list(self.unexplained),
            "partial": list(self.partial),
            "ambiguous": [{"named": a, "or": b, "delta_bic_difference": _num(d)} for a, b, d in self.ambiguous],
            "not_detectable": [{"effect": n, "reason": w} for n, w in self.not_detectable],
            "not_testable": [{"effect": n, "reason": w} for n, w in self.not_testable],
            "tested": list(self.tested),
            "settings": self.settings,
            "seconds": _num(self.seconds),
        }

    def to_markdown(self, figures: dict[str, str] | None = None) -> str:
        """A readable report; ``figures`` maps ``"gap"`` / effect names to image links."""
        figures = figures or {}
        L = [
            "# Missing-effect discovery\n",
            f"**Model:** {self.model} — {self.n_obs} observations ({self.n_profiled} profiled ρd).\n",
            f"**Verdict:** {self.verdict()}.\n",
        ]
        L.append("## Gap per step\n")
        L.append("| step | model | gap (χ²/dof) |\n|---|---|---|")
        L.append(f"| 0 | baseline | {self.gap[0]:.3f} |")
        for i, s in enumerate(self.steps, 1):
            L.append(f"| {i} | + {s.effect} | {self.gap[i]:.3f} |")
        if "gap" in figures:
            L.append(f"\n![gap per step]({figures['gap']})\n")
        bp = self.baseline.values.get("model", {})
        bs = self.baseline.sigma.get("model", {})
        if self.settings.get("texture"):
            L.append("\n## Noise\n\n" + _texture_paragraph(self.settings["texture"]) + "\n")
        L.append("\n## Baseline\n")
        L.append(", ".join(f"{k} = {_fmt(v, bs.get(k))}" for k, v in bp.items()) + "\n")
        for i, s in enumerate(self.steps, 1):
            ev = s.evidence
            L.append(f"## Step {i}: {s.effect} — {s.title}\n")
            L.append(
                "Parameters: " + ", ".join(f"{k} = {_fmt(v, s.stderr.get(k))}" for k, v in s.params.items()) + "\n"
            )
            L.append(
                f"Evidence: Δχ² = {ev.delta_chi2:.1f}, ΔBIC = {ev.delta_bic:.1f} (k = {ev.k}), "
                f"LR p = {ev.p_value:.2g}, explains {100 * min(ev.explained, 1):.0f} % of the excess; "
                f"gap {s.gap_before:.3f} → {s.gap_after:.3f}.\n"
            )
            if ev.variogram is not None:  # let through by the guard's second opinion: by its gap, or what it explains
                g, p, x = ev.variogram.gap, ev.variogram.gap_p, ev.variogram.explained
                why = (
                    f"under its covariance from the variogram it explains {100 * min(x, 1):.0f} % of the excess "
                    f"(gap {g:.3f}, p = {p:.2g})"
                    if p < self.settings.get("structure_p", 1e-3)
                    else f"not under its covariance from the variogram (gap {g:.3f}, p = {p:.2g}, "
                    f"{100 * min(x, 1):.0f} % of the excess)"
                )
                L.append(
                    "It leaves a significant gap under the texture's covariance about each scanline's mean, but "
                    f"{why}: named.\n"
                )
            L.append("| candidate | k | Δχ² | ΔBIC | LR p | structure p |\n|---|---|---|---|---|---|")
            for c in s.candidates:
                ge = "" if c.converged else "≥ "
                L.append(
                    f"| {c.effect} | {c.k} | {ge}{c.delta_chi2:.1f} | {ge}{c.delta_bic:.1f} | {c.p_value:.2g} | "
                    f"{c.structure_p:.2g} |"
                )
            if not all(c.converged for c in s.candidates):
                L.append(
                    "\n≥: the fit stopped at the Levenberg–Marquardt step cap (`lm_steps`); Δχ² and ΔBIC are "
                    "lower bounds, below half the winner's ΔBIC, so the fit was not continued."
                )
            if s.effect in figures:
                what = covariate_label(s.plot["covariate"]) if s.plot else ""
                L.append(f"\n![residuals against {what}]({figures[s.effect]})\n")
        if self.steps:
            av = self.averaged
            L.append("\n## Parameters with the model choice's uncertainty\n")
            L.append(
                ", ".join(
                    f"{k} = {_fmt(d['value'], d['sigma'])} (chosen model: ± {d['sigma_model']:.2g})"
                    for k, d in av.items()
                )
                + " — averaged over the last step's models by their evidence (weights ∝ exp(ΔBIC/2); the named "
                "model and those not told apart from it alike).\n"
            )
        if self.ambiguous:
            L.append("\n## Not told apart\n")
            L.extend(
                f"- {a} or {b}: {_ambiguity(a, b, d)}; one capture cannot tell them apart "
                f"({_SEPARATE[frozenset({a, b})]})"
                for a, b, d in self.ambiguous
            )
        L.append("\n## Unexplained structure\n")
        L.append(
            "\n".join(f"- {u}" for u in self.unexplained)
            if self.unexplained
            else "None: the residuals are consistent with the noise against every covariate."
        )
        if self.discrepancy is not None:
            d, av = self.discrepancy, self.averaged
            L.append(
                f"\nThe parameters' σ include the discrepancy (a level per bin of {d['covariate']}, "
                f"{d['bins']} bins, SD τ = {d['tau']:.3g} σ of the noise, from the binned χ² above its bins; "
                + (
                    f"correlated between bins over {d['length']:.3g} of their range"
                    if d.get("length")
                    else "independent between bins"
                )
                + f"; of the {len(d.get('readings', {})) or 1} covariates with structure, the one that widens σ most): "
                + ", ".join(
                    f"{k} = {_fmt(v['value'], v['sigma'])} (the discrepancy alone ± {v['sigma_discrepancy']:.2g}, "
                    f"the models' ± {math.sqrt(max(v['sigma'] ** 2 - v['sigma_discrepancy'] ** 2, 0.0)):.2g})"
                    for k, v in av.items()
                )
                + ".\n"
            )
        if self.not_detectable:
            L.append("\n## Not detectable from these data\n")
            L.extend(f"- {n}: {w}" for n, w in self.not_detectable)
        if self.not_testable:
            L.append("\n## Not testable on these data\n")
            L.extend(f"- {n}: {w}" for n, w in self.not_testable)
        L.append(
            f"\n_Criterion: largest ΔBIC, added if ΔBIC > 0, Bonferroni LR p < {self.settings['alpha']}, and "
            f"explaining ≥ {100 * self.settings['min_explained']:.0f} % of the excess or leaving a gap within the "
            f"noise (with a texture: under either of its covariances), and predicting held-out scanlines. "
            f"Time {self.seconds:.1f} s._"
        )
        return "\n".join(L) + "\n"

    def __str__(self) -> str:
        return self.to_markdown()

    # ---------------------------------------------------------------- figures
    def plot_gap(self):
        """The gap after each step (dashed: the noise level, 1): ``gap_figure``."""
        return gap_figure(self.gap, ["baseline"] + [f"+ {s}" for s in self.found])

    def plot_step(self, i: int):
        """Residuals against the telling covariate before and after step ``i`` (0-based)."""
        from matplotlib.figure import Figure

        s = self.steps[i]
        fig = Figure(figsize=(8.0, 3.0), layout="constrained")
        if not s.plot:
            return fig
        axs = fig.subplots(1, 2, sharey=True)
        for ax, key, title in (
            (axs[0], "before", f"before (gap {s.gap_before:.2f})"),
            (axs[1], "after", f"after + {s.effect} (gap {s.gap_after:.2f})"),
        ):
            x, r = np.asarray(s.plot[f"x_{key}"], float), np.asarray(s.plot[f"r_{key}"], float)
            ax.plot(x, r, ".", ms=1.5, alpha=0.25, color="0.5", rasterized=True)
            _, _, p, xc, mean, sem = _binned_test(r, x)
            ax.errorbar(xc, mean, yerr=sem, fmt="o-", ms=3, color="C3", label="binned mean")
            ax.axhline(0, color="k", lw=0.8)
            ax.set_xlabel(covariate_label(s.plot["covariate"]))
            ax.set_title(f"{title}; p = {p:.1e}", fontsize=9)
        lim = np.nanpercentile(np.abs(np.asarray(s.plot["r_before"], float)), 99) if len(s.plot["r_before"]) else 1
        axs[0].set_ylim(-1.1 * lim - 1, 1.1 * lim + 1)
        axs[0].set_ylabel("residual / σ")
        axs[0].legend(frameon=False, fontsize=8)
        return fig

    def figures(self) -> dict:
        """``{"gap": Figure, effect: Figure, …}``."""
        out = {"gap": self.plot_gap()}
        for i, s in enumerate(self.steps):
            if s.plot:
                out[s.effect] = self.plot_step(i)
        return out

    # ---------------------------------------------------------------- notebook
    def _repr_markdown_(self) -> str:
        return self.to_markdown()

    def _repr_html_(self) -> str:
        import html

        figs = {}
        for name, fig in self.figures().items():
            buf = io.BytesIO()
            fig.savefig(buf, format="png", dpi=90)
            figs[name] = "data:image/png;base64," + base64.b64encode(buf.getvalue()).decode()
        md = self.to_markdown(figs)
        body = []
        in_table = False
        for line in md.splitlines():
            if line.startswith("|"):
                cells = [c.strip() for c in line.strip("|").split("|")]
                if set("".join(cells)) <= set("-"):
                    continue
                if not in_table:
                    body.append("<table>")
                    in_table = True
                body.append("<tr>" + "".join(f"<td>{html.escape(c)}</td>" for c in cells) + "</tr>")
                continue
            if in_table:
                body.append("</table>")
                in_table = False
            if line.startswith("!["):
                src = line[line.index("(") + 1 : line.rindex(")")]
                body.append(f'<img src="{src}"/>')
            elif line.startswith("## "):
                body.append(f"<h3>{html.escape(line[3:])}</h3>")
            elif line.startswith("# "):
                body.append(f"<h2>{html.escape(line[2:])}</h2>")
            elif line.startswith("- "):
                body.append(f"<li>{html.escape(line[2:])}</li>")
            elif line.strip():
                body.append(f"<p>{html.escape(line).replace('**', '')}</p>")
        if in_table:
            body.append("</table>")
        return "<div>" + "\n".join(body) + "</div>"

    # ---------------------------------------------------------------- files
    def save(self, out_dir, *, extra: dict | None = None) -> dict[str, Path]:
        """Write ``report.json``, ``report.md`` and the PNGs to ``out_dir`` (atomic writes).

        ``extra`` entries are merged into ``report.json`` (e.g. the capture's name).
        """
        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        paths: dict[str, Path] = {}
        links = {}
        for name, fig in self.figures().items():
            fn = "gap.png" if name == "gap" else f"residuals_{name}.png"
            buf = io.BytesIO()
            fig.savefig(buf, format="png", dpi=110)
            write_bytes_atomic(out / fn, buf.getvalue())
            paths[name] = out / fn
            links[name] = fn
        d = self.to_dict()
        if extra:
            d.update(extra)
        write_bytes_atomic(out / "report.json", (json.dumps(d, indent=2, ensure_ascii=False) + "\n").encode())
        write_bytes_atomic(out / "report.md", self.to_markdown(links).encode())
        paths["json"] = out / "report.json"
        paths["md"] = out / "report.md"
        return paths


def gap_figure(gap, labels, title: str | None = None):
    """The gap after each step as points on an axis zoomed to the values and the noise level (1).

    A bar from 0 would hide 1.003 against 1.001; each point carries its value, and the
    axis switches to log when the values span more than a factor 20.
    """
    from matplotlib.figure import Figure

    fig = Figure(figsize=(4.5, 3.0), layout="constrained")
    ax = fig.add_subplot()
    gap = np.asarray(gap, float)
    x = np.arange(len(gap))
    ax.plot(x, gap, "o-", color="C0", ms=6)
    for xi, g in zip(x, gap):
        ax.annotate(f"{g:.4g}", (xi, g), textcoords="offset points", xytext=(0, 7), ha="center", fontsize=8)
    ax.axhline(1.0, ls="--", color="k", lw=1, label="noise level (1)")
    ax.set_xticks(x, list(labels)[: len(gap)], rotation=20, ha="right")
    ax.set_xlim(-0.5, len(gap) - 0.5)
    ax.set_ylabel("gap: reduced χ² (dimensionless)")
    finite = gap[np.isfinite(gap)]
    if finite.size and finite.max() / max(finite.min(), 1e-9) > 20:
        ax.set_yscale("log")
    elif finite.size:
        lo, hi = min(finite.min(), 1.0), max(finite.max(), 1.0)
        pad = 0.25 * (hi - lo) if hi > lo else 0.001
        ax.set_ylim(lo - pad, hi + pad)
        ax.ticklabel_format(axis="y", useOffset=False)
    if title:
        ax.set_title(title, fontsize=9)
    ax.legend(frameon=False, fontsize=8)
    return fig
