"""Orchestration on top of the stages: a capture fitted end to end, batches of folders, the demo, the CLI.

Names are imported on first use (PEP 562), so that the ``wardjax`` command starts
without importing JAX; each subcommand imports what it needs.
"""

import importlib as _importlib
from typing import TYPE_CHECKING

if TYPE_CHECKING:  # the API as the type checker and the reader see it
    from ._batch import BatchItem as BatchItem
    from ._batch import find_captures as find_captures
    from ._batch import run_batch as run_batch
    from ._batch import scanline_note as scanline_note
    from ._cli import main as main
    from ._demo import run_capture_demo as run_capture_demo
    from ._fit_capture import CaptureFit as CaptureFit
    from ._fit_capture import fit_capture as fit_capture
    from ._smartphone import fit_smartphone_capture as fit_smartphone_capture

# Each public name → the module defining it, imported on first use (PEP 562).
_API = {
    "BatchItem": "._batch",
    "find_captures": "._batch",
    "run_batch": "._batch",
    "scanline_note": "._batch",
    "main": "._cli",
    "run_capture_demo": "._demo",
    "CaptureFit": "._fit_capture",
    "fit_capture": "._fit_capture",
    "fit_smartphone_capture": "._smartphone",
}
__all__ = [
    "BatchItem",
    "find_captures",
    "run_batch",
    "scanline_note",
    "main",
    "run_capture_demo",
    "CaptureFit",
    "fit_capture",
    "fit_smartphone_capture",
]


def __getattr__(name: str):
    """Import the module behind ``name`` on first use and keep the value in the namespace."""
    try:
        module = _API[name]
    except KeyError:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}") from None
    obj = _importlib.import_module(module, __name__)
    value = obj if module == f".{name}" else getattr(obj, name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_API))
