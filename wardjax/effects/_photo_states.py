"""The models discovery compares on a photograph capture: the paper's model plus the effects found so far.

A :class:`PhotoState` names the radial gains found (``vignetting``,
``flash_falloff``: :mod:`._photo_model`) and the structural ones
(``varying_specular``: a lobe per material cluster, ``normals``: a normal per
problem, ``height_field``: those normals tied to one height field over the
problems' grid, :mod:`wardjax.fit._pixel_height`). Without structural effects a state is fitted by
:func:`~wardjax.effects._photo_model.fit_shared`; with them, its gains are
fitted there and held, the data divided by them, and
:func:`wardjax.fit_pixels` fits the lobes (``lobe="clusters"``) and normals.

Held-out χ² (:func:`held_chi2`): a state fitted on some views predicts
others with its lobes, gains and normals held and ρd profiled on the views
predicted; with clusters predicting other problems, each problem takes the
lobe of lowest ``χ² − 2 ln π_l`` (``π`` the clusters' shares), as the fit
assigns them.
"""

from __future__ import annotations

import dataclasses
from typing import NamedTuple

import numpy as np

from ._photo_model import RADIAL, PhotoData, SharedFit, chi2_held, fit_shared, gains

__all__ = ["NORMALS", "STRUCTURAL", "PhotoState", "StateFit", "fit_state", "held_chi2"]

STRUCTURAL = {
    "varying_specular": "a lobe per material cluster (count chosen by BIC), each problem labelled with one",
    "normals": "a normal per problem where it earns its BIC cost (bumps, tilt)",
    "height_field": "normals tied to one height field: the nearest integrable normal map (Frankot & Chellappa 1988)",
}
NORMALS = ("normals", "height_field")  # one or the other: a normal per problem, free or tied to its neighbours


@dataclasses.dataclass(frozen=True)
class PhotoState:
    """The effects in a model: radial gains and structural effects, in the order found."""

    radial: tuple[str, ...] = ()
    structural: tuple[str, ...] = ()
    bounded: bool = False  # the shared lobe held within what a material has (``_photo_model.BOUNDED``)

    def plus(self, name: str) -> PhotoState:
        if name in RADIAL:
            return dataclasses.replace(self, radial=(*self.radial, name))
        return dataclasses.replace(self, structural=(*self.structural, name))

    @property
    def lobe(self) -> str:
        return "clusters" if "varying_specular" in self.structural else "shared"

    @property
    def normals(self) -> bool:
        return any(n in self.structural for n in NORMALS)

    @property
    def height_field(self) -> bool:
        return "height_field" in self.structural

    @property
    def n_radial(self) -> int:
        return sum(len(RADIAL[n].params) for n in self.radial)


class StateFit(NamedTuple):
    """A state fitted: χ² and dof, the shared-lobe fit (its gains), and :func:`wardjax.fit_pixels`' result."""

    chi2: float
    dof: int
    shared: SharedFit
    pixel: object | None  # wardjax.fit.PixelFit where the state has structure (or ``pixels=True``)

    @property
    def gap(self) -> float:
        return self.chi2 / max(self.dof, 1)


def _pixel_fit(data: PhotoData, g: np.ndarray, keep: np.ndarray, state: PhotoState, held=None):
    """:func:`wardjax.fit_pixels` on the views ``keep``; ``held``: normals ``(P, 3)`` to fit at, not refit; the
    problems' grid ``(rows, cols)`` the height field where ``state`` has one."""
    from ..fit import fit_pixels

    lobe, normals = state.lobe, state.normals
    fit_normals = normals and held is None
    w = data.w * (g * g * keep)[..., None]
    return fit_pixels(
        data.f / g[..., None],
        data.wi,
        data.wo,
        weights=w,
        mask=np.any(w > 0, -1),
        lobe=lobe,
        normals=fit_normals,
        fixed_normals=held if normals else None,
        height_field=data.grid[:2] if fit_normals and state.height_field else None,
        normalization=data.normalization,
    )


def fit_state(
    state: PhotoState,
    data: PhotoData,
    keep: np.ndarray | None = None,
    *,
    start=None,
    pixels: bool = False,
    gains_from: SharedFit | None = None,
    normals_from: StateFit | None = None,
) -> StateFit:
    """Fit ``state`` to the views ``keep (P, V)``; ``pixels``: through :func:`wardjax.fit_pixels` even
    without structure (to compare with a structural candidate on the same footing); ``gains_from``: a fit
    whose radial gains are taken as they are (fitted on a held structure, :mod:`._photo_held`);
    ``normals_from``: a fit whose normals are held (``fixed_normals``), not refitted."""
    keep = np.ones(data.radius2.shape, bool) if keep is None else keep
    shared = fit_shared(data, state.radial, keep, start, state.bounded) if gains_from is None else gains_from
    if not (state.structural or pixels):
        return StateFit(shared.chi2, shared.dof, shared, None)
    held = getattr(getattr(normals_from, "pixel", None), "normals", None)
    res = _pixel_fit(data, gains(data, shared.effects), keep, state, held)
    chi2 = float(res.chi2)
    ev = getattr(getattr(normals_from, "pixel", None), "evidence", {})
    n_held = 2 * int(ev.get("normals", {}).get("n_pixels", 0)) if held is not None else 0  # the held normals
    return StateFit(chi2, max(int(res.dof) - state.n_radial - n_held, 1), shared, res)


def _profiled(f, w, spec, q) -> np.ndarray:
    """``(P,)`` each problem's χ² with ``a = ⟨q, f − spec⟩/⟨q, q⟩`` per channel."""
    sq = np.sum(w * q * q, 1)
    a = np.sum(w * q * (f - spec), 1) / np.where(sq > 0, sq, 1.0)
    return np.sum(w * (f - spec - q * a[:, None]) ** 2, (1, 2))


def held_chi2(fit: StateFit, state: PhotoState, data: PhotoData, test: np.ndarray, train: np.ndarray) -> float:
    """χ² of the views ``test (P, V)`` predicted by ``fit`` (made on the views ``train``)."""
    if fit.pixel is None:
        return chi2_held(data, fit.shared, state.radial, test)
    from ..fit import predict_pixels

    res = fit.pixel
    g = gains(data, fit.shared.effects)
    f = data.f / g[..., None]
    w = data.w * (g * g * test)[..., None]
    zero = np.zeros_like(np.asarray(res.rho_d))  # pyright: ignore[reportAttributeAccessIssue]

    def predicted(labels):
        r0 = dataclasses.replace(res, rho_d=zero, labels=labels)  # pyright: ignore[reportArgumentType]
        spec = np.asarray(predict_pixels(r0, data.wi, data.wo))
        ones = dataclasses.replace(r0, rho_d=np.full_like(zero, np.pi))  # pyright: ignore[reportArgumentType]
        return spec, np.asarray(predict_pixels(ones, data.wi, data.wo)) - spec

    labels = np.asarray(res.labels)  # pyright: ignore[reportAttributeAccessIssue]
    n_lobes = int(np.asarray(res.rho_s).shape[0])  # pyright: ignore[reportAttributeAccessIssue]
    moved = np.any(test, 1) & ~np.any(train, 1)  # problems the fit did not see: the mixture's deviance
    if n_lobes > 1 and moved.any():
        from scipy.special import logsumexp

        seen = np.any(train, 1)
        share = np.bincount(labels[seen], minlength=n_lobes) / max(int(seen.sum()), 1)
        costs = np.stack([_profiled(f, w, *predicted(np.full_like(labels, lb))) for lb in range(n_lobes)], 1)
        log_pi = np.log(np.maximum(share, 1e-300))[None]
        deviance = -2.0 * logsumexp(log_pi - 0.5 * costs, axis=1)
        return float(np.sum(np.where(moved, deviance, costs[np.arange(labels.size), labels])))
    return float(np.sum(_profiled(f, w, *predicted(labels))))
