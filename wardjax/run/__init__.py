"""Orchestration on top of the stages: a capture fitted end to end, batches of folders, the demo, the CLI.

Names are imported on first use (PEP 562), so that the ``wardjax`` command starts
without importing JAX; each subcommand imports what it needs.
"""

import importlib as _importlib
from typing import TYPE_CHECKING

if TYPE_CHECKING:  # the API as the type checker and the reader see it
    from ._batch import BatchItem as BatchItem
    from ._batch import find_captures as find_captures
    from ._batch import fit_one as fit_one
    from ._batch import run_batch as run_batch
    from ._batch import scanline_note as scanline_note
    from ._cli import main as main
    from ._demo import run_capture_demo as run_capture_demo
    from ._distributed import CompileCounter as CompileCounter
    from ._distributed import JaxWorker as JaxWorker
    from ._distributed import cluster_compiles as cluster_compiles
    from ._distributed import open_scheduler as open_scheduler
    from ._fit_capture import CaptureFit as CaptureFit
    from ._fit_capture import fit_capture as fit_capture
    from ._fit_photo import HeldOut as HeldOut
    from ._fit_photo import PhotoFit as PhotoFit
    from ._fit_photo import fit_photo_capture as fit_photo_capture
    from ._fit_photo import write_photo_outputs as write_photo_outputs
    from ._smartphone import fit_smartphone_capture as fit_smartphone_capture
    from ._progress import Stages as Stages
    from ._diagnose_photo import diagnose_photo_capture as diagnose_photo_capture
    from ._diagnose_photo import photo_data as photo_data

# Each public name → the module defining it, imported on first use (PEP 562).
_API = {
    "BatchItem": "._batch",
    "find_captures": "._batch",
    "fit_one": "._batch",
    "run_batch": "._batch",
    "scanline_note": "._batch",
    "main": "._cli",
    "run_capture_demo": "._demo",
    "CompileCounter": "._distributed",
    "JaxWorker": "._distributed",
    "cluster_compiles": "._distributed",
    "open_scheduler": "._distributed",
    "CaptureFit": "._fit_capture",
    "fit_capture": "._fit_capture",
    "HeldOut": "._fit_photo",
    "PhotoFit": "._fit_photo",
    "fit_photo_capture": "._fit_photo",
    "write_photo_outputs": "._fit_photo",
    "fit_smartphone_capture": "._smartphone",
    "Stages": "._progress",
    "diagnose_photo_capture": "._diagnose_photo",
    "photo_data": "._diagnose_photo",
}
__all__ = [
    "BatchItem",
    "find_captures",
    "fit_one",
    "run_batch",
    "scanline_note",
    "main",
    "run_capture_demo",
    "CompileCounter",
    "JaxWorker",
    "cluster_compiles",
    "open_scheduler",
    "CaptureFit",
    "fit_capture",
    "HeldOut",
    "PhotoFit",
    "fit_photo_capture",
    "write_photo_outputs",
    "fit_smartphone_capture",
    "Stages",
    "diagnose_photo_capture",
    "photo_data",
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
