"""Profile-likelihood standard errors where the Gauss–Newton curvature is not trusted.

The scanlines here are rendered by this file's own NumPy Ward model and rig (lamp and
camera in the plane x = 0, as in the image-based paper's Fig. 2), not by
:mod:`wardjax.simulate`: the library under test did not make its test data. The
reference profiles are brute force: at each fixed α (or ρs) the remaining parameters
are fitted by NumPy's linear least squares (or SciPy's bounded scalar search).
"""

import numpy as np
import pytest
from scipy.optimize import brentq, minimize_scalar

import wardjax as wj

MAD = 1.4826


def robust_sd(z):
    z = np.asarray(z)
    return MAD * np.median(np.abs(z - np.median(z)))


def ward_iso(rho_d, rho_s, alpha, wi, wo):
    """Ward (1992) isotropic BRDF ``(S, N, 3)``: ρd/π + ρs exp(−tan²δ/α²) / (4πα² √(cos θi cos θo))."""
    h = wi + wo
    tan2 = (h[..., 0] ** 2 + h[..., 1] ** 2) / h[..., 2] ** 2
    a2 = alpha[:, None] ** 2
    spec = rho_s[:, None] * np.exp(-tan2 / a2) / (4 * np.pi * a2 * np.sqrt(wi[..., 2] * wo[..., 2]))
    return rho_d[:, None, :] / np.pi + spec[..., None]


def _directions(lamp, cam, x, y):
    p = np.stack([x, y, np.zeros_like(x)], -1)
    wi = lamp[:, None] - p
    wo = cam[:, None] - p
    return wi / np.linalg.norm(wi, axis=-1, keepdims=True), wo / np.linalg.norm(wo, axis=-1, keepdims=True)


def _tan_half(lamp, cam, x, y):
    wi, wo = _directions(lamp, cam, x, y)
    h = wi + wo
    return h[..., 0] / h[..., 2], h[..., 1] / h[..., 2]


def blind_scanlines(rng, s, alpha_range, *, n=256, span=(1.5, 40.0), offset=2.0):
    """``s`` scanlines of random materials, each in its own rig; 1 % noise plus a floor.

    The scanline covers half-vector slopes of ``±span·α`` (log-uniform: 3 to 85 samples
    per α) at an offset across it that tilts the half vector by up to ``±offset·α``.
    """
    alpha = rng.uniform(*alpha_range, s)
    rho_s = rng.uniform(0.01, 0.1, s)
    rho_d = rng.uniform(0.05, 0.8, (s, 3))
    tl, tc = np.deg2rad(rng.uniform(20, 60, s)), np.deg2rad(rng.uniform(20, 60, s))
    dl, dc = rng.uniform(400, 900, s), rng.uniform(400, 900, s)
    lamp = np.stack([np.zeros(s), dl * np.sin(tl), dl * np.cos(tl)], -1)
    cam = np.stack([np.zeros(s), -dc * np.sin(tc), dc * np.cos(tc)], -1)
    ym = ((lamp[:, 1] * cam[:, 2] + cam[:, 1] * lamp[:, 2]) / (lamp[:, 2] + cam[:, 2]))[:, None]
    zero, eps = np.zeros((s, 1)), 1e-3
    dy = (_tan_half(lamp, cam, zero, ym + eps)[1] - _tan_half(lamp, cam, zero, ym - eps)[1])[:, 0] / (2 * eps)
    dx = (_tan_half(lamp, cam, zero + eps, ym)[0] - _tan_half(lamp, cam, zero - eps, ym)[0])[:, 0] / (2 * eps)
    half = np.exp(rng.uniform(*np.log(span), s)) * alpha / np.abs(dy)
    x0 = rng.uniform(-offset, offset, s) * alpha / np.abs(dx)
    y = ym + np.linspace(-1.0, 1.0, n)[None, :] * half[:, None]
    wi, wo = _directions(lamp, cam, np.broadcast_to(x0[:, None], y.shape), y)
    f = ward_iso(rho_d, rho_s, alpha, wi, wo)
    sigma = np.sqrt((0.01 * f) ** 2 + 0.002**2)
    return (rho_d, rho_s, alpha), f + sigma * rng.standard_normal(f.shape), wi, wo, sigma


def _chi2_fixed(f, wi, wo, w, alpha, rho_s=None):
    """χ² minimised over ρd (and ρs unless given) at fixed α: linear least squares."""
    b = ward_iso(np.zeros((1, 3)), np.ones(1), np.array([alpha]), wi[None], wo[None])[0, :, 0]
    sw = np.sqrt(w)
    total = 0.0
    if rho_s is not None:
        for c in range(3):
            r = f[:, c] - rho_s * b
            mean = np.sum(w[:, c] * r) / np.sum(w[:, c])
            total += np.sum(w[:, c] * (r - mean) ** 2)
        return total
    design = np.zeros((f.shape[0] * 3, 4))
    for c in range(3):
        design[c::3, c] = 1.0
        design[c::3, 3] = b
    design *= sw.reshape(-1)[:, None]
    coef, *_ = np.linalg.lstsq(design, (sw * f).reshape(-1), rcond=None)
    return float(np.sum(((sw * f).reshape(-1) - design @ coef) ** 2))


def _interval_half_width(fun, x_hat, chi_min, scale, step):
    """Half-width of ``{x : fun(x) − chi_min ≤ scale}`` (one crossing each side of ``x_hat``)."""
    g = lambda x: fun(x) - chi_min - scale
    lo = x_hat - step
    while g(lo) < 0:
        lo -= step
    hi = x_hat + step
    while g(hi) < 0:
        hi += step
    return 0.5 * (brentq(g, x_hat, hi) - brentq(g, lo, x_hat))


@pytest.fixture(scope="module")
def narrow_tail():
    """Narrow lobes seen from scanlines in the lobe's tail (2–3 α off the highlight): skewed likelihoods."""
    rng = np.random.default_rng(41)
    truth, f, wi, wo, sigma = blind_scanlines(rng, 48, (0.01, 0.05), span=(2.0, 4.0), offset=3.0)
    return truth, f, wi, wo, sigma


def test_profile_errors_match_brute_force_profiles(narrow_tail):
    _, f, wi, wo, sigma = narrow_tail
    res = wj.fit_scanlines(f, wi, wo, weights=1 / sigma**2, errors="profile")
    # where the ρs interval stays clear of its bound at 0 (the reference does not cut there)
    rows = np.flatnonzero(res.ok & (res.stderr.rho_s < 0.3 * res.params.rho_s))[:6]
    assert rows.size == 6
    assert np.all(res.errors[rows] == "profile")
    for i in rows:
        w = 1 / sigma[i] ** 2
        a_hat, s_hat = float(res.params.alpha_x[i]), float(res.params.rho_s[i])
        scale = float(res.reduced_chi2[i])
        chi_a = lambda a: _chi2_fixed(f[i], wi[i], wo[i], w, a)
        chi_min = chi_a(a_hat)
        ref_a = _interval_half_width(chi_a, a_hat, chi_min, scale, 0.3 * float(res.stderr.alpha_x[i]))

        def chi_s(s):
            opt = minimize_scalar(
                lambda la: _chi2_fixed(f[i], wi[i], wo[i], w, np.exp(la), s),
                bounds=(np.log(a_hat) - 0.5, np.log(a_hat) + 0.5),
                method="bounded",
                options={"xatol": 1e-9},
            )
            return opt.fun

        ref_s = _interval_half_width(chi_s, s_hat, chi_min, scale, 0.3 * float(res.stderr.rho_s[i]))
        assert res.stderr.alpha_x[i] == pytest.approx(ref_a, rel=0.03), i
        assert res.stderr.rho_s[i] == pytest.approx(ref_s, rel=0.03), i


@pytest.mark.slow
def test_profile_equals_gauss_newton_where_chi2_is_quadratic():
    rng = np.random.default_rng(42)
    _, f, wi, wo, sigma = blind_scanlines(rng, 64, (0.03, 0.3), span=(3.0, 3.5), offset=1.0)
    gn = wj.fit_scanlines(f, wi, wo, weights=1 / sigma**2, errors="gauss_newton")
    prof = wj.fit_scanlines(f, wi, wo, weights=1 / sigma**2, errors="profile")
    auto = wj.fit_scanlines(f, wi, wo, weights=1 / sigma**2)
    assert np.all(gn.errors == "gauss_newton") and np.all(prof.errors[prof.ok] == "profile")
    ok = gn.ok & prof.ok
    np.testing.assert_allclose(prof.stderr.alpha_x[ok], gn.stderr.alpha_x[ok], rtol=0.05)
    np.testing.assert_allclose(prof.stderr.rho_s[ok], gn.stderr.rho_s[ok], rtol=0.05)
    # the same optimum whichever errors are asked for, and the covariance agrees with stderr
    np.testing.assert_array_equal(prof.params.alpha_x, gn.params.alpha_x)
    np.testing.assert_allclose(np.sqrt(prof.covariance[:, 4, 4]), prof.stderr.alpha_x)
    # where the curvature check passes, "auto" reports Gauss–Newton's errors
    keep = auto.errors == "gauss_newton"
    assert keep.mean() > 0.8
    np.testing.assert_array_equal(auto.stderr.alpha_x[keep], gn.stderr.alpha_x[keep])


@pytest.mark.slow
def test_errors_choice_is_checked():
    rng = np.random.default_rng(43)
    _, f, wi, wo, sigma = blind_scanlines(rng, 2, (0.05, 0.1))
    with pytest.raises(ValueError, match="errors"):
        wj.fit_scanlines(f, wi, wo, weights=1 / sigma**2, errors="bootstrap")
    aniso = wj.fit_scanlines(f, wi, wo, "anisotropic", weights=1 / sigma**2, errors="profile")
    assert np.all(aniso.errors == "gauss_newton")  # profiles are for isotropic fits


@pytest.mark.slow
@pytest.mark.parametrize("alpha_range", [(0.01, 0.05), (0.03, 0.3)])
def test_blind_errors_are_honest_on_narrow_and_broad_lobes(alpha_range):
    """Many seeds of blind scanlines: robust SD of (fit − truth)/σ in [0.85, 1.2] for α and ρs."""
    za, zs, used = [], [], []
    for seed in range(8):
        rng = np.random.default_rng(1000 + seed)
        (_, rho_s, alpha), f, wi, wo, sigma = blind_scanlines(rng, 500, alpha_range)
        res = wj.fit_scanlines(f, wi, wo, weights=1 / sigma**2)
        ok = res.ok
        assert ok.mean() > 0.9  # broad lobes over ±40 α reach grazing angles: some at_bound
        za.append(((res.params.alpha_x - alpha) / res.stderr.alpha_x)[ok])
        zs.append(((res.params.rho_s - rho_s) / res.stderr.rho_s)[ok])
        used.append(res.errors[ok] == "profile")
    sd_a, sd_s = robust_sd(np.concatenate(za)), robust_sd(np.concatenate(zs))
    frac = np.mean(np.concatenate(used))
    print(f"\nα {alpha_range}: robust SD of z: α {sd_a:.3f}, ρs {sd_s:.3f}; profiled {frac:.3f}")
    assert 0.85 <= sd_a <= 1.2
    assert 0.85 <= sd_s <= 1.2


def test_profiles_in_the_search_program_equal_the_separate_pass(narrow_tail):
    """The rows failing the curvature check are profiled inside the search program, up to a share of
    each chunk; the rest (and ``errors="profile"``) in a separate pass. Both give the same σ."""
    from wardjax.fit import _data, _profile, _scanline

    _, f, wi, wo, sigma = narrow_tail
    w = 1 / sigma**2  # the programs the tests above compiled (unweighted fits share the code path)
    auto = wj.fit_scanlines(f, wi, wo, weights=w)
    apart = wj.fit_scanlines(f, wi, wo, weights=w, errors="profile")  # every converged row, in the separate pass
    rows = auto.errors == "profile"
    assert rows.sum() >= 4
    np.testing.assert_allclose(auto.stderr.alpha_x[rows], apart.stderr.alpha_x[rows], rtol=1e-9)
    np.testing.assert_allclose(auto.stderr.rho_s[rows], apart.stderr.rho_s[rows], rtol=1e-9)
    np.testing.assert_allclose(auto.covariance[rows], apart.covariance[rows], rtol=1e-9, atol=1e-300)
    # the search program itself profiled as many as its lanes hold (48 rows: a 64-row chunk, 4 lanes)
    data = _data.validate(f, wi, wo, None, w)
    sol = _scanline._solve(
        data,
        iso=True,
        normalization="ward1992",
        solver="fast",
        dtype=np.dtype(np.float64),
        chunk=1024,
    )
    done = np.sum(sol.nonlinear == _profile.PROFILED)
    assert done == min(rows.sum(), _scanline._profile_lanes(64, 256))
    assert done + np.sum(sol.nonlinear == _profile.PENDING) >= rows.sum()


def _check_reference(f, wi, wo, w, sol_row):
    """The curvature check's verdict by brute force (NumPy least squares at fixed α, and ρs):
    ``(fails, margin)``, ``margin`` the smallest distance of a relative miss from the tolerance."""
    a_hat, s_hat = float(sol_row["alpha"]), float(sol_row["rho_s"])
    cov, chi_min, scale = sol_row["cov_gn"], float(sol_row["chi2"]), float(sol_row["scale"])
    sd_t, sd_s = np.sqrt(cov[4, 4]) / a_hat, np.sqrt(cov[3, 3])
    r = np.clip(cov[3, 4] / np.sqrt(cov[3, 3] * cov[4, 4]), -0.999, 0.999)
    kappa = np.tanh(2 * sd_t)
    misses = []
    # the two points, symmetric in 1/α²: 1/α'² = (1 ∓ κ)/α̂², θ' = θ̂ ± σ_θ + ½ log cosh 2σ_θ
    for sign, delta in ((1.0, -0.5 * np.log1p(-kappa)), (-1.0, 0.5 * np.log1p(kappa))):
        a = a_hat * np.exp(sign * delta)
        z = delta / sd_t
        rise = (_chi2_fixed(f, wi, wo, w, a) - chi_min) / scale
        misses.append(abs(rise - z * z) / (z * z))
        s_new = max(s_hat + sign * np.sign(r) * z * sd_s, 0.0)
        rise = (_chi2_fixed(f, wi, wo, w, a, s_new) - chi_min) / scale
        pred = 2 * z * z / (1 + abs(r))
        misses.append(abs(rise - pred) / pred)
    misses = np.array(misses)
    return bool(np.any(misses > 0.2)), float(np.min(np.abs(misses - 0.2)))


def test_curvature_check_matches_brute_force_chi2(narrow_tail):
    """The search program's curvature check (χ² at its two points from the search's own exponential)
    gives the verdict that brute-force χ² at those points gives, on narrow lobes seen in the tail and on
    broad ones: a few hundred rows, both verdicts present."""
    from wardjax.fit import _data, _scanline

    rng = np.random.default_rng(7)
    sets = [narrow_tail[1:]]
    sets += [blind_scanlines(rng, 64, rng_range, span=(1.5, 8.0))[1:] for rng_range in ((0.03, 0.3), (0.01, 0.05))]
    sets += [blind_scanlines(rng, 64, (0.03, 0.3), span=(1.5, 8.0))[1:]]
    agree = fails = passes = 0
    for f, wi, wo, sigma in sets:
        w = 1 / sigma**2
        data = _data.validate(f, wi, wo, None, w)
        sol = _scanline._solve(
            data, iso=True, normalization="ward1992", solver="fast", dtype=np.dtype(np.float64), chunk=1024
        )
        for i in np.flatnonzero(sol.status == wj.Status.CONVERGED):
            row = dict(alpha=sol.alpha[i, 0], rho_s=sol.rho_s[i], cov_gn=sol.cov_gn[i], chi2=sol.chi2[i])
            row["scale"] = sol.chi2[i] / sol.dof[i]
            ref, margin = _check_reference(f[i], wi[i], wo[i], w[i], row)
            if margin < 0.02:  # on the tolerance's edge: rounding may decide either way
                continue
            agree += ref == (sol.nonlinear[i] != 0)
            fails += ref
            passes += not ref
    assert fails >= 10 and passes >= 50
    assert agree == fails + passes
