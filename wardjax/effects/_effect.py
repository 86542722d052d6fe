"""What an effect is: a named, documented extension of a forward model.

An :class:`Effect` carries

- its extra parameters (:class:`Param`): a starting value, the value at which
  the effect is *absent* (the model reduces exactly to the one without it),
  the side of the absent value that is physical (one-sided amplitudes), a
  scale for the optimiser, and extra starting points for parameters that are
  not identified while the effect is absent (a second lobe's width when its
  amplitude is zero — the Davies problem);
- how it changes the prediction: hook methods that the model calls (see
  :mod:`wardjax.effects._models`); the defaults leave the prediction alone;
- the residual signature it predicts: the *telling covariate* against which
  the residuals of a model without the effect show structure (half-vector
  azimuth for anisotropy, predicted intensity for a γ mismatch, …);
- which data it needs (``requires``) and whether it cancels out of the
  reconstruction ratio ``v / v_std`` by the rig's symmetry, in which case it
  cannot be found from reconstructed BRDFs and is reported as such.
"""

from __future__ import annotations

import math
from typing import NamedTuple

__all__ = ["Effect", "Param"]


class Param(NamedTuple):
    """One parameter of a model or an effect.

    Attributes
    ----------
    name
        Short name (unique within its effect).
    init
        Starting value in natural units.
    absent
        Value at which the effect vanishes (linear parameters only; ``nan`` for
        parameters that are merely nuisance, e.g. a lobe width).
    kind
        ``"linear"``: natural value ``= scale · u``; ``"log"``: ``= scale · exp(u)``,
        where ``u`` is the coordinate the optimiser moves.
    scale
        Typical size, so that the optimiser works with ``u`` of order one.
    sign
        ``+1``: only values ``≥ absent`` are physical (an amplitude), ``−1``:
        only ``≤ absent``; ``0``: either side.
    starts
        Extra starting values (natural units) for a multi-start fit.
    unit, doc
        For the report.
    prior_sd
        If > 0, a weak Gaussian prior of this SD (in ``u``) around the starting
        value: it keeps a parameter that the data cannot pin down (a lobe
        width while its amplitude is near zero) from wandering, so the
        optimiser converges; its deviance is not counted in the gap.
    optional
        A refinement of the effect that must earn its own place: discovery
        also tries the effect with this parameter held at ``absent`` (one
        parameter fewer in ``k``) and keeps whichever form has the larger
        ΔBIC; once the reduced form is added it stays reduced. Where the
        probe's texture is carried, only the reduced form is tried: the one
        such parameter, the illumination field's tilt, moves the diffuse level
        along every scanline in proportion to the column, which texture
        coherent over many columns also does (marble's veins: Δχ² 20–29 on
        untouched captures), and neither the design effect nor the scanline
        levels (:mod:`~wardjax.effects._levels`) price that.
    """

    name: str
    init: float
    absent: float = 0.0
    kind: str = "linear"
    scale: float = 1.0
    sign: int = 0
    starts: tuple[float, ...] = ()
    unit: str = ""
    doc: str = ""
    prior_sd: float = 0.0
    optional: bool = False

    def to_u(self, value: float) -> float:
        if self.kind == "log":
            return math.log(value / self.scale)
        return value / self.scale


class Effect:
    """Base class of the effect library; subclasses override the hooks they need.

    Class attributes
    ----------------
    name
        Identifier used in reports (``rep.found``).
    title
        One line for humans.
    model
        The model kind it extends: ``"scanline"`` (BRDF samples along scanlines,
        reconstructed or measured) or ``"threshold"`` (PPB → lobe SD lines).
    side
        ``"measurement"``, ``"material"`` or ``"threshold"``.
    params
        Its :class:`Param` tuple (may be empty: a data-fixed effect such as
        the saturation level still counts one parameter in the evidence).
    n_data_params
        Parameters estimated from the data outside the fit (counted in the
        evidence penalty).
    covariate
        The telling covariate of its residual signature.
    requires
        Covariates (or data properties) without which it cannot be tested.
    cancels_by_symmetry
        ``True`` when it divides out of ``v / v_std`` for reconstructed data.
    nests
        ``(name, params)``: with ``params`` at their absent values it is the effect ``name`` (veiling glare with no
        share of the frame is a veil: the ambient offset). Discovery then names it over that effect only where
        ``params`` pay for themselves on their own; ``None`` (the default) for an effect that nests none.
    physics
        The forward change in words and maths, with the source.
    """

    name: str = ""
    title: str = ""
    model: str = "scanline"
    side: str = "material"
    params: tuple[Param, ...] = ()
    n_data_params: int = 0
    covariate: str = ""
    requires: tuple[str, ...] = ()
    cancels_by_symmetry: bool = False
    nests: tuple[str, tuple[str, ...]] | None = None
    physics: str = ""

    # -------------------------------------------------------------- bookkeeping
    @property
    def k(self) -> int:
        """Parameters counted by the evidence: fitted plus data-fixed."""
        return len(self.params) + self.n_data_params

    def applicable(self, data) -> str | None:
        """``None`` when the effect can be tested on ``data``, else the reason why not."""
        if self.cancels_by_symmetry and getattr(data, "kind", "") == "ratio":
            return "cancels out of v/v_std by the rig's symmetry: not detectable from reconstructed BRDFs"
        have = set(getattr(data, "available", ()))
        missing = [r for r in self.requires if r not in have]
        if missing:
            return f"the data carry no {', '.join(missing)}"
        return None

    def starts(self) -> list[tuple[float, ...]]:
        """Starting points (natural units): the product of each parameter's init and starts."""
        out: list[tuple[float, ...]] = [()]
        for p in self.params:
            vals = (p.init,) + tuple(v for v in p.starts if v != p.init)
            out = [o + (v,) for o in out for v in vals]
        return out

    def physical(self, values: dict[str, float]) -> bool:
        """Whether fitted values lie on the physical side of the absent value."""
        for p in self.params:
            if p.sign and p.sign * (values[p.name] - p.absent) < 0:
                return False
        return True

    def __repr__(self) -> str:
        return f"<Effect {self.name}: {self.title}>"

    def __hash__(self) -> int:
        return hash((type(self), self.name))

    def __eq__(self, other) -> bool:
        return type(self) is type(other) and self.name == other.name
