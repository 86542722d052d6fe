"""The physical grating-threshold model: CSFs fitted on ModelFest only, Table 1b predicted out of sample.

Run with ``-s`` to see every Table 1 cell's prediction and error.
"""

import colour
import numpy as np
import pytest
from scipy import stats

from wardjax.capture import load_display, load_viewing
from wardjax.smartphone import (
    CSF_METHODS,
    CSFFit,
    csf_sensitivity,
    fit_csf_gratings,
    fit_csf_modelfest,
    load_csf_gratings,
    load_modelfest,
    load_table1,
    lobe_sd_from_threshold,
    ppb_to_cpd,
    screen_view_factor,
    threshold_ppb,
)
from wardjax.smartphone._threshold_model import _screen_frame


def test_modelfest_data_shipped():
    mf = load_modelfest()
    assert mf["sensitivity"].shape == (14,) and np.all(mf["luminance"] == 30.0)
    assert mf["frequency"].min() == pytest.approx(1.12) and mf["frequency"].max() == pytest.approx(30.0)


def test_barten_fits_modelfest_within_0p2_log10():
    barten = fit_csf_modelfest("Barten 1999")
    mannos = fit_csf_modelfest("Mannos 1974")
    print(f"\nModelFest RMS log10 S: Barten {barten.rms_log10:.3f} {barten.constants}, Mannos {mannos.rms_log10:.3f}")
    assert barten.rms_log10 <= 0.2
    # Mannos–Sakrison has no field-size term: ModelFest's small Gabors are beyond it
    assert mannos.rms_log10 > barten.rms_log10
    mf = load_modelfest()
    res = np.log10(csf_sensitivity(mf["frequency"], 30.0, barten.constants[2] * mf["sigma"], barten)) - np.log10(
        mf["sensitivity"]
    )
    assert np.sqrt(np.mean(res**2)) == pytest.approx(barten.rms_log10, rel=1e-9)


def test_barten_matches_colour_at_its_reference_conditions():
    """With k = 3, σ from σ0 = 0.5′ and Barten's pupil, our call is colour-science's Barten CSF."""
    fit = CSFFit("Barten 1999", (3.0, 0.5, 1.0), float("nan"))
    f = np.array([0.5, 2.0, 8.0, 30.0])
    lum, x0 = 20.0, 60.0
    d = colour.contrast.pupil_diameter_Barten1999(lum, x0)
    e = colour.contrast.retinal_illuminance_Barten1999(lum, d, True)
    sigma = np.hypot(0.5 / 60, 0.08 / 60 * d)
    ref = colour.contrast.contrast_sensitivity_function_Barten1999(u=f, sigma=sigma, k=3.0, X_0=x0, E=e)
    np.testing.assert_allclose(csf_sensitivity(f, lum, x0, fit), ref, rtol=1e-12)
    # luminance matters: sensitivity at 30 cpd rises from 1 to 100 cd/m² (the 20 cd/m² default is not used)
    s = csf_sensitivity(30.0, np.array([1.0, 100.0]), x0, fit)
    assert s[1] > 3 * s[0]


def test_screen_view_factor_matches_monte_carlo():
    """Independent check: the fraction of cosine-distributed rays from P that hit the screen."""
    corner, e1, e2, normal, _ = _screen_frame(load_display("iphone5s"), load_viewing("paper"))
    rng = np.random.default_rng(0)
    n = 400_000
    u1, u2 = rng.random(n), rng.random(n)
    r, phi = np.sqrt(u1), 2 * np.pi * u2
    dirs = np.stack([r * np.cos(phi), r * np.sin(phi), np.sqrt(1 - u1)], -1)
    denom = dirs @ normal
    t = (corner @ normal) / np.where(denom != 0, denom, np.nan)
    hit = t[:, None] * dirs - corner
    a = hit @ e1 / (e1 @ e1)
    b = hit @ e2 / (e2 @ e2)
    frac = np.nanmean(np.where((t > 0) & (a >= 0) & (a <= 1) & (b >= 0) & (b <= 1), 1.0, 0.0))
    f = screen_view_factor()
    print(f"\nscreen view factor from the viewed point: {f:.4f} (Monte Carlo {frac:.4f})")
    assert f == pytest.approx(frac, abs=4 * np.sqrt(frac * (1 - frac) / n) + 1e-3)


def test_threshold_limits_and_monotonicity():
    disp = load_display("iphone5s")
    # a mirror (no blur) on black: the finest grating the eye resolves at this luminance
    assert threshold_ppb(0.0, 0.0) >= disp.ppb_min
    sd = np.array([0.1, 0.3, 1.0, 3.0, 10.0])
    p = threshold_ppb(sd, 0.2)
    assert np.all(np.diff(p) > 0)  # a wider lobe needs coarser bars
    # a brighter diffuse floor lowers the contrast: coarser bars at threshold
    assert np.all(np.diff(threshold_ppb(1.0, np.array([0.0, 0.3, 0.9]))) > 0)
    # closed form for the blur-limited regime: where the CSF changes slowly the threshold
    # frequency scales as 1/σ, so PPB ∝ σ
    big = threshold_ppb(np.array([2.5, 5.0, 10.0]), 0.0)
    np.testing.assert_allclose(big[1:] / big[:-1], 2.0, rtol=0.1)
    assert threshold_ppb(1e4, 0.5) == disp.ppb_max
    assert ppb_to_cpd(threshold_ppb(0.0, 0.0)) < 60


def test_barten_fitted_on_gratings_lands_on_bartens_own_constants():
    """Rovamo et al.'s gratings of 0.003–980 deg² (castleCSF) fix Barten's constants near his published ones."""
    g = load_csf_gratings()
    assert g["sensitivity"].shape == (46,) and np.all(g["luminance"] == 50.0)
    fit = fit_csf_gratings("Barten 1999")
    k, sigma0, a = fit.constants
    print(f"\nRovamo 1993 gratings: Barten RMS log10 S {fit.rms_log10:.3f}, k {k:.2f}, σ0 {sigma0:.2f}′, a {a:.2f}")
    assert fit.rms_log10 <= 0.2
    # Barten (1999): k = 3, σ0 = 0.5 arcmin, X_0 the field's angular size (a = 1); ModelFest's small
    # Gabors pull the same three constants far from these (k ≈ 14, a ≈ 8)
    assert 2.0 <= k <= 4.0 and 0.2 <= sigma0 <= 0.8 and 0.7 <= a <= 1.4
    assert fit_csf_modelfest("Barten 1999").constants[0] > 3 * k
    with pytest.raises(ValueError, match="calibration"):
        threshold_ppb(1.0, 0.5, calibration="castle")


@pytest.mark.parametrize("calibration", ["gratings", "modelfest"])
@pytest.mark.parametrize("method", CSF_METHODS)
def test_table1b_predicted_out_of_sample(method, calibration):
    """Every Table 1b threshold from Table 1a's lobe SD and the NCS ρd, with no Table 1 data in the fit.

    Measured, median |ln(PPB_pred/PPB)| over the 24 cells: CSF constants from Rovamo et
    al.'s gratings 0.155 (Barten; signed +0.04) and 0.157 (Mannos–Sakrison); from ModelFest
    0.274 and 0.365, a uniform positive bias (+0.27: the ModelFest constants, fitted to small
    Gabor patches, underestimate the sensitivity to a grating filling the reflected screen by
    0.5 log10 on Rovamo's data). The cells left worst with the grating constants: gloss 95 on
    black (the observers saw 1 PPB, 54 cpd, where the model's eye resolves ~2 PPB; the paper
    notes the 1 PPB grating's contrast is below nominal, and the scale stops at 1 PPB) and
    gloss 6 on white and light grey (lobe SDs of 222° and 156° the paper distrusts; the
    prediction is the scale's end, 120 PPB). The lightness order at gloss 95 (contrast gloss)
    is reproduced.
    """
    t = load_table1()
    pred = threshold_ppb(t["lobe_sd_deg"], t["rho_d"][:, None], csf=method, calibration=calibration)
    err = np.log(pred / t["ppb"])
    print(f"\n{method}, constants from {calibration}: Table 1b threshold PPB, measured → predicted (ln error)")
    print("NCS    " + "".join(f"{g:>18d}" for g in (95, 75, 50, 30, 12, 6)))
    for i, ncs in enumerate(("0500", "2500", "5000", "9000")):
        print(f"{ncs}   " + "".join(f"{t['ppb'][i, j]:6.1f} →{pred[i, j]:6.1f} ({err[i, j]:+.2f})" for j in range(6)))
    med = float(np.median(np.abs(err)))
    print(f"median |ln(pred/obs)| = {med:.3f}, median signed {np.median(err):+.3f}")
    rho = stats.spearmanr(pred.ravel(), t["ppb"].ravel()).statistic
    assert rho > 0.9  # the ordering of the 24 surfaces is right
    if calibration == "gratings":
        assert med <= 0.25
        assert abs(np.median(err)) < 0.15  # no uniform bias left
    else:
        assert med <= (0.3 if method == "Barten 1999" else 0.4)
        assert np.median(err) > 0.2  # the ModelFest constants' bias
    if method == "Barten 1999":
        assert np.all(np.diff(pred[:, 0]) < 0)  # contrast gloss: darker surfaces show finer bars


def test_inverse_round_trip_and_table1a_from_thresholds():
    """The model inverted: lobe SD from a threshold. Round trip, then Table 1a from Table 1b."""
    t = load_table1()
    sd_true = np.array([0.3, 1.0, 2.8, 5.0])
    rho = np.array([0.85, 0.49, 0.25, 0.01])
    back = lobe_sd_from_threshold(threshold_ppb(sd_true, rho), rho)
    np.testing.assert_allclose(back, sd_true, rtol=1e-6)
    cols = slice(1, 4)  # gloss 75–30: thresholds of 5–18 PPB, inside the display's range
    sd_est = lobe_sd_from_threshold(t["ppb"][:, cols], t["rho_d"][:, None])
    err = np.log(sd_est / t["lobe_sd_deg"][:, cols])
    print(f"\nTable 1a lobe SD from Table 1b thresholds (gloss 75–30), ln error:\n{np.round(err, 2)}")
    assert np.median(np.abs(err)) < 0.2  # measured 0.13 with grating constants (0.21, all negative, with ModelFest's)
    with pytest.raises(ValueError, match="ppb"):
        lobe_sd_from_threshold(0.0, 0.5)
