"""The notebooks for fitting a folder of captures, texture analysis and synthesis, and the smartphone method execute."""

from pathlib import Path

import nbformat
import pytest
from nbclient import NotebookClient

NOTEBOOKS = Path(__file__).parents[1] / "notebooks"


def _run(name: str) -> str:
    nb = nbformat.read(NOTEBOOKS / name, as_version=4)
    NotebookClient(nb, timeout=600, kernel_name="python3", resources={"metadata": {"path": str(NOTEBOOKS)}}).execute()
    outs = [o for c in nb.cells if c.cell_type == "code" for o in c.get("outputs", [])]
    assert not [o for o in outs if o.output_type == "error"]
    assert any("image/png" in o.get("data", {}) for o in outs)
    return "".join(o.get("text", "") for o in outs)


@pytest.mark.slow
def test_fit_folder_notebook_reports_honest_errors():
    text = _run("fit_folder.ipynb")
    assert "('desk', 'ok'), ('marble', 'ok'), ('satin', 'ok')" in text
    rms_z = float(text.split("RMS z = ")[1].split(",")[0])
    assert 0.3 < rms_z < 2.0  # reported σ of the right size against the truth


@pytest.mark.slow
def test_texture_notebook_synthesis_keeps_the_statistics():
    text = _run("texture.ipynb")
    ks = [float(x) for x in text.split("each iteration: ")[1].splitlines()[0].split(" → ")]
    assert ks[-1] <= 0.05 < ks[0]
    assert float(text.split("largest relative difference of the mean: ")[1].split()[0]) < 0.02


@pytest.mark.slow
def test_smartphone_notebook_recovers_alpha_from_three_observers():
    text = _run("smartphone.ipynb")
    # the real photo: the chart-based correction brings ρd within a few ΔE of the published colours
    assert float(text.split("leave-one-out: mean ΔE*ab ")[1].split(",")[0]) < 4.0
    # α drawn by the model for three observers: inside the posterior's 95 % interval
    assert "true α inside the 95 % interval: True" in text
    # the chain: split-R̂ as expected for mixed chains of this length (√(1 + τ/n))
    rhat, expected = text.split("split-R̂(α) = ")[1].split(" (expected ≈ ")
    assert abs(float(rhat) - float(expected.split(")")[0])) < 0.02
    # one observer leaves α wider than three do
    widths = {line[:38].strip(): float(line.split()[-1].rstrip("×")) for line in text.splitlines() if "×" in line[-3:]}
    assert widths["first observer only"] > 1.5 * widths["three observers, chart-corrected ρd"]


@pytest.mark.slow
def test_validation_notebook_radiance_and_jax_agree():
    """notebooks/validation.ipynb: every scene's Radiance render equals the JAX render per pixel (≤ 1e-4, the
    issue's bound is 5 %), and the MTF is within 0.02 of its closed form. Over a minute with Radiance: slow."""
    text = _run("validation.ipynb")
    worst = float(text.split("largest relative difference over all scenes: ")[1].split()[0])
    assert worst <= 1e-4
    assert float(text.split("largest absolute error up to 0.5 cycles/pixel: ")[1].split()[0]) <= 0.02
    for scene in (
        "rig (plastic2)",
        "spheres (6 paints, plastic)",
        "sphere (plastic2)",
        "sphere (metal)",
        "phone, NCS white (plastic)",
        "phone, red low gloss, home screen (cos³)",
    ):
        assert scene in text  # every scene compared
