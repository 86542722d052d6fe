"""The null bench's figures (``benchmarks/null_captures.py``): what counts as a false name, the gap band, z."""

from __future__ import annotations

import math

import numpy as np

from benchmarks.null_captures import _robust_sd, figures


def _row(material, found, verdict, gap, dof, rho_s, sd_s, true_s, alpha, sd_a, true_a):
    return {
        "material": material,
        "found": found,
        "verdict": verdict,
        "gap_after": str(gap),
        "dof": str(dof),
        "rho_s": str(rho_s),
        "rho_s_sigma": str(sd_s),
        "rho_s_true": str(true_s),
        "alpha": str(alpha),
        "alpha_sigma": str(sd_a),
        "alpha_true": str(true_a),
    }


def test_figures_count_only_names_not_truly_present():
    rows = [
        # the desk is anisotropic (Table 1): anisotropy is present there, gamma is not
        _row("desk", "anisotropy", "found anisotropy; ...", 1.01, 10_000, 0.04, 0.001, 0.039, 0.14, 0.01, 0.1434),
        _row("desk", "gamma", "found gamma; ...", 1.00, 10_000, 0.03, 0.001, 0.039, 0.14, 0.01, 0.1434),
        # the satin is isotropic: any name is false, and its verdict must be "nothing needed"
        _row("satin", "-", "nothing needed: ...", 1.10, 10_000, 0.061, 0.001, 0.06, 0.09, 0.001, 0.09),
        _row("satin", "anisotropy", "found anisotropy; ...", 0.99, 10_000, 0.06, 0.001, 0.06, 0.091, 0.001, 0.09),
    ]
    f = figures(rows)
    assert [r["found"] for r in f["false"]] == ["gamma", "anisotropy"]
    assert len(f["clean"]) == 2 and len(f["clean_ok"]) == 1
    # band 1 ± 2√(2/10⁴) = 1 ± 0.0283: 1.10 is outside, the others inside
    assert [float(r["gap_after"]) for r in f["band"]] == [1.01, 1.00, 0.99]
    np.testing.assert_allclose(f["z"]["rho_s"], [1.0, -9.0, 1.0, 0.0], atol=1e-9)
    np.testing.assert_allclose(f["z"]["alpha"][2:], [0.0, 1.0], atol=1e-9)


def test_robust_sd_reads_a_normal_sample_and_ignores_outliers():
    z = np.random.default_rng(0).standard_normal(4000)
    assert abs(_robust_sd(z) - 1.0) < 0.05
    z[:40] = 50.0  # 1 % wild values move the SD, not the robust SD
    assert abs(_robust_sd(z) - 1.0) < 0.07 and np.std(z) > 4
    assert math.isnan(_robust_sd(np.array([])))
