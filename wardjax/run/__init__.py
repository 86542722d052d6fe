"""Orchestration on top of the stages: a capture fitted end to end, batches of folders, the demo, the CLI."""

from ._batch import BatchItem as BatchItem
from ._batch import find_captures as find_captures
from ._batch import run_batch as run_batch
from ._cli import main as main
from ._demo import run_capture_demo as run_capture_demo
from ._fit_capture import CaptureFit as CaptureFit
from ._fit_capture import fit_capture as fit_capture
from ._smartphone import fit_smartphone_capture as fit_smartphone_capture

__all__ = [
    "BatchItem",
    "find_captures",
    "run_batch",
    "main",
    "run_capture_demo",
    "CaptureFit",
    "fit_capture",
    "fit_smartphone_capture",
]
