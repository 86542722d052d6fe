"""calibration/real_brdf_fits.csv (Ward on CUReT and RGL, benchmarks/real_brdf_fits.py) against a rerun."""

import csv

import numpy as np
import pytest

from benchmarks import real_brdf_fits as rbf
from wardjax._data import calibration_path
from wardjax._status import Status
from wardjax.effects import LIBRARY
from wardjax.ward import NORMALIZATIONS


def _csv():
    with open(calibration_path(rbf.CSV_NAME), encoding="utf-8") as fh:
        reader = csv.DictReader(r for r in fh if not r.startswith("#"))
        return list(reader), tuple(reader.fieldnames or ())


def test_csv_covers_every_material_model_and_normalisation():
    rows, cols = _csv()
    assert cols == rbf.COLUMNS
    keys = {(r["material"], r["model"], r["normalization"]) for r in rows}
    curet = {r["material"] for r in rows if r["source"] == "curet"}
    rgl = {r["material"] for r in rows if r["source"] == "rgl"}
    assert len(curet) == 61 and rgl == set(rbf.RGL_MATERIALS)
    assert len(rows) == len(keys) == 64 * len(rbf.MODELS) * len(NORMALIZATIONS)
    names = {s.name.lower() for s in Status}
    for r in rows:
        assert r["status"] in names
        assert float(r["reduced_chi2"]) > 0 and 0 <= float(r["rel_rms"]) < 10
    # discover's additions: per material, named effects of the library (or none)
    known = {e.name for e in LIBRARY}
    adds = {r["material"]: r["discover_adds"] for r in rows}
    assert all(a == "none" or set(a.split(";")) <= known for a in adds.values()), adds
    assert all(r["discover_adds"] == adds[r["material"]] for r in rows)
    # Ward misses CUReT at its measured noise: the typical reduced χ² is well above 1
    chi = np.array([float(r["reduced_chi2"]) for r in rows if r["source"] == "curet"])
    assert np.median(chi) > 5


@pytest.mark.slow
@pytest.mark.parametrize("index", [0, 30, 60])
def test_rerun_of_three_curet_samples_matches_the_csv(index):
    rows, _ = _csv()
    stored = {(r["model"], r["normalization"]): r for r in rows if r["material"] == f"curet_{index + 1:02d}"}
    again = rbf.curet_rows([index], with_discover=index == 30)
    assert len(again) == len(stored) == len(rbf.MODELS) * len(NORMALIZATIONS)
    for r in again:
        s = stored[(r["model"], r["normalization"])]
        assert s["status"] == r["status"]
        if index == 30:  # discover rerun on one sample: same effects, same order
            assert s["discover_adds"] == r["discover_adds"]
        for c in rbf.COLUMNS[5:-1]:
            assert float(s[c]) == pytest.approx(float(r[c]), rel=1e-4, abs=1e-9), (c, r["model"], r["normalization"])
        assert int(s["n_samples"]) == 205
        n_alpha = 1 if r["model"] == "isotropic" else 2
        assert int(s["dof"]) == 205 - 2 - n_alpha  # one grey channel: ρd, ρs, α (or αx, αy)
