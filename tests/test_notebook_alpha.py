"""Execute notebooks/alpha_uncertainty.ipynb (NCS and paint posteriors, corner plot, lobe SDs)."""

import time
from pathlib import Path

import nbformat
import pytest
from nbclient import NotebookClient

NOTEBOOK = Path(__file__).parents[1] / "notebooks" / "alpha_uncertainty.ipynb"


@pytest.mark.slow
def test_alpha_uncertainty_notebook_runs():
    nb = nbformat.read(NOTEBOOK, as_version=4)
    t0 = time.perf_counter()
    NotebookClient(
        nb, timeout=300, kernel_name="python3", resources={"metadata": {"path": str(NOTEBOOK.parent)}}
    ).execute()
    elapsed = time.perf_counter() - t0
    text = "".join(o.get("text", "") for c in nb.cells if c.cell_type == "code" for o in c.get("outputs", []))
    errors = [o for c in nb.cells if c.cell_type == "code" for o in c.get("outputs", []) if o.output_type == "error"]
    assert not errors
    assert "Table 1c inside the 95% interval" in text and "reconstructed threshold" in text
    images = sum(
        "image/png" in o.get("data", {}) for c in nb.cells if c.cell_type == "code" for o in c.get("outputs", [])
    )
    assert images >= 2  # the NCS figure and the corner plot
    print(f"\nnotebook executed in {elapsed:.1f} s")
    if elapsed > 60:
        pytest.fail(f"notebook took {elapsed:.0f} s; keep it under 60 s for the default suite")
