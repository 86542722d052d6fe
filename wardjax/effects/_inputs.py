"""What ``discover`` checks before it starts (the model's interface, the data's kind, the level) and what it tests."""

from __future__ import annotations

from ._library import library

__all__: list[str] = []

# not an effect of the library: what one capture's ratio cannot tell from the material, said in every report
ROOM_LIGHT = (
    "light from the room that the lamp-off frame does not remove, reflected by the probe, cancels from the "
    "diffuse ratio (the standard sees it too) and leaves a scale on the specular lobe that ρs absorbs: not "
    "identifiable from one capture (a second capture with the room dark, or a lamp-off frame taken with the "
    "room as lit, separates it)"
)


def _check_inputs(model, data, alpha: float) -> None:
    """Reject a model without the interface ``discover`` uses, data of another kind, or a level outside (0, 1).

    Checked up front so that a mismatch fails with a clear message instead of
    deep inside a traced solve.
    """
    api = ("kind", "data_kinds", "library_kind", "supports", "base_params", "residuals", "predict", "covariates")
    for attr in api + ("n_profiled",):
        if not hasattr(model, attr):
            raise TypeError(f"model must provide {attr!r} (a ScanlineModel or ThresholdModel), got {type(model)!r}")
    if getattr(data, "kind", None) not in model.data_kinds:
        raise TypeError(f"data of kind {getattr(data, 'kind', type(data))!r} do not suit a {model.kind} model")
    if not 0 < alpha < 1:
        raise ValueError(f"alpha must be in (0, 1), got {alpha}")


def _split_library(model, data, effects):
    """The candidate effects that ``data`` can test, and ``(name, why, cancels_by_symmetry)`` of the others.

    Effects of another model kind are dropped silently; those the data cannot
    test are kept aside so that the report can say why they were not tried.
    """
    lib = library(model.library_kind) if effects is None else tuple(effects)
    supports = model.supports  # a model may take another kind's effects (the screen model: scanline ones)
    testable, skipped = [], []
    for e in lib:
        if not supports(e):
            continue
        why = e.applicable(data)
        if why is None:
            testable.append(e)
        else:
            skipped.append((e.name, why, e.cancels_by_symmetry))
    if model.library_kind == "scanline" and getattr(data, "kind", None) == "ratio":
        skipped.append(("room_light", ROOM_LIGHT, True))
    return tuple(testable), skipped
