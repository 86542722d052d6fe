"""Sharding over several JAX devices: the scanline batch and the texture synthesis give the same results.

The test suite never needs an accelerator: XLA's CPU backend is split into two
devices (``--xla_force_host_platform_device_count=2``), which must be set
before JAX starts, so the comparison runs in a subprocess. On those two
devices it fits 300 simulated scanlines (an odd count: the last call is padded
to whole rows per device) and synthesises a 3-channel texture (the channels
are padded to 4, two per device), each once sharded over both devices and
once on the first alone; 37 of the fits are also run with profile-likelihood
errors for every row (the profiles are split over the devices too). The partitioned program rounds differently from the
one-device program (XLA fuses it differently), and the fixed-iteration LM
carries that into the last digits: the fits agree to 1e-7 relative, five orders
of magnitude below their standard errors. The texture's first pyramid is
identical; afterwards the collapse rounds differently in the last bits, and at
this small size (6,144 pixels) a value crossing a histogram bin edge moves the
matched values of its bin by 1/n in probability: pixels agree to 1e-2 (mean
difference < 1e-3) and the per-iteration KS distances to 5e-3.
"""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap

import pytest

SCRIPT = textwrap.dedent(
    """
    import jax, numpy as np
    import wardjax as wj
    from wardjax.simulate import procedural_texture, x_offset_for_slope

    both = jax.devices()
    assert len(both) == 2 and both[0].platform == "cpu", both
    rng = np.random.default_rng(5)
    s = 300
    a = rng.uniform(0.03, 0.3, s)
    truth = wj.WardParams(rho_d=rng.uniform(0.05, 0.8, (s, 3)), rho_s=rng.uniform(0.01, 0.1, s), alpha_x=a, alpha_y=a)
    rig = wj.ScanlineRig.random(s, rng)
    data = wj.simulate_scanlines(
        truth, x_offsets=x_offset_for_slope(rig, rng.uniform(-1.5, 1.5, s) * a), rig=rig, seed=rng
    )
    fits = [
        wj.fit_scanlines(data.f_r, data.wi, data.wo, weights=1 / data.sigma**2, chunk_size=64, devices=d)
        for d in (both, both[:1])
    ]
    assert np.all(fits[0].ok), np.unique(fits[0].status_names, return_counts=True)
    for name in ("rho_d", "rho_s", "alpha_x"):
        x, y = getattr(fits[0].params, name), getattr(fits[1].params, name)
        np.testing.assert_allclose(x, y, rtol=1e-7, err_msg=name)
    np.testing.assert_allclose(fits[0].stderr.alpha_x, fits[1].stderr.alpha_x, rtol=1e-6)
    np.testing.assert_array_equal(fits[0].status, fits[1].status)
    # Profile-likelihood errors (every converged row profiled) are split over the devices the same way.
    prof = [
        wj.fit_scanlines(data.f_r[:37], data.wi[:37], data.wo[:37], weights=1 / data.sigma[:37] ** 2,
                         chunk_size=64, devices=d, errors="profile")
        for d in (both, both[:1])
    ]
    assert (prof[0].errors == "profile").sum() > 30, prof[0].errors
    np.testing.assert_array_equal(prof[0].errors, prof[1].errors)
    for name in ("rho_s", "alpha_x"):
        np.testing.assert_allclose(getattr(prof[0].stderr, name), getattr(prof[1].stderr, name), rtol=1e-6)
    # The fits are right, not only equal: α recovered to a few per cent.
    assert np.median(np.abs(fits[0].params.alpha_x / a - 1)) < 0.02

    src = procedural_texture("marble", (64, 64), seed=2, rho_s=0.04)
    model = wj.analyze_texture(src, height=2, n_quantiles=33, rho_s=0.04)
    tex = [wj.synthesize_texture(model, (64, 96), seed=3, iterations=2, devices=d) for d in (both, both[:1])]
    np.testing.assert_allclose(tex[0].image, tex[1].image, rtol=0, atol=1e-2)
    np.testing.assert_allclose(tex[0].band_distance, tex[1].band_distance, rtol=0, atol=5e-3)
    assert np.abs(tex[0].image - tex[1].image).mean() < 1e-3
    print("sharded == unsharded")
    """
)


@pytest.mark.slow
def test_sharded_equals_unsharded_on_two_cpu_devices(tmp_path):
    env = dict(os.environ)
    env["XLA_FLAGS"] = (env.get("XLA_FLAGS", "") + " --xla_force_host_platform_device_count=2").strip()
    env["JAX_PLATFORMS"] = "cpu"
    r = subprocess.run([sys.executable, "-c", SCRIPT], env=env, capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stdout + r.stderr
    assert "sharded == unsharded" in r.stdout
