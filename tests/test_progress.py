"""Progress and quiet: each stage of a long command on stderr, no third-party warning, the scanline step limit."""

import io
import re

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from click.testing import CliRunner
from rich.console import Console

import wardjax as wj
from wardjax.run import main
from wardjax.run._progress import Stages, stage

# A finished stage's line: mark, name, (seconds[, of which compiling seconds])
LINE = re.compile(r"^✓ (?P<name>.+) \((?P<s>[0-9.]+) s(?:, of which compiling (?P<c>[0-9.]+) s)?\)$")


def _console(terminal: bool) -> tuple[Console, io.StringIO]:
    buf = io.StringIO()
    return Console(file=buf, force_terminal=terminal, width=200, emoji=False), buf


def _lines(text: str) -> list[re.Match]:
    text = re.sub(r"\x1b\[[0-9;?]*[A-Za-z]", "", text)  # a terminal's colours and cursor moves
    return [m for ln in re.split(r"[\r\n]", text) if (m := LINE.match(ln.strip()))]


def test_each_stage_is_one_line_with_its_time_and_what_compiling_took():
    console, buf = _console(terminal=False)
    with Stages(True, console) as stages:
        stages.advance("compile a new kernel")
        jax.jit(lambda x: jnp.cumsum(jnp.sin(x) ** 3))(jnp.arange(17.0)).block_until_ready()  # a shape not seen yet
        stage("no compile")  # the module-level hook reaches the open Stages
        sum(range(1000))
    lines = _lines(buf.getvalue())
    assert [m["name"] for m in lines] == ["compile a new kernel", "no compile"]
    first = lines[0]
    assert first["c"] is not None and 0 < float(first["c"]) <= float(first["s"]) + 0.05
    assert lines[1]["c"] is None


def test_off_when_stderr_is_not_a_terminal_on_when_it_is_or_forced():
    for terminal, enabled, shown in (
        (False, None, False),
        (True, None, True),
        (False, True, True),
        (True, False, False),
    ):
        console, buf = _console(terminal)
        with Stages(enabled, console) as stages:
            stages.advance("a stage")
        assert bool(_lines(buf.getvalue())) == shown, (terminal, enabled)
    stage("outside any command")  # no Stages open: nothing to tell, no error


def test_a_failed_stage_is_marked_and_the_error_still_propagates():
    console, buf = _console(terminal=False)
    with pytest.raises(ValueError, match="boom"), Stages(True, console) as stages:
        stages.advance("doomed")
        raise ValueError("boom")
    assert buf.getvalue().strip().startswith("✗ doomed (")


@pytest.fixture(scope="module")
def capture(tmp_path_factory):
    root = tmp_path_factory.mktemp("progress")
    p = wj.WardParams(rho_d=(0.5, 0.4, 0.3), rho_s=0.05, alpha_x=0.12, alpha_y=0.12)
    wj.simulate_capture(p, root / "caps" / "plain", seed=0, image_size=(96, 72), texture="none")
    return root


def _stage_names(stderr: str) -> list[str]:
    return [m["name"] for m in _lines(stderr)]


@pytest.mark.slow
def test_diagnose_shows_every_stage(capture):
    r = CliRunner().invoke(
        main, ["diagnose", str(capture / "caps" / "plain"), "--out", str(capture / "diag"), "--progress"]
    )
    assert r.exit_code == 0, r.output
    names = _stage_names(r.stderr)
    for expected in ("loading the capture", "reconstructing", "baseline fit", "step 1: testing", "writing report"):
        assert sum(n.startswith(expected) for n in names) == 1, (expected, names)
    assert "✓" not in r.stdout  # progress goes to stderr only
    quiet = CliRunner().invoke(main, ["diagnose", str(capture / "caps" / "plain"), "--out", str(capture / "diag2")])
    assert quiet.exit_code == 0 and not _stage_names(quiet.stderr)  # not a terminal: off


def test_fit_shows_the_stages_within_a_capture_and_takes_a_step_limit(capture):
    out = capture / "fits"
    r = CliRunner().invoke(main, ["fit", str(capture / "caps"), "--out", str(out), "--progress", "--max-steps", "12"])
    assert r.exit_code == 0, r.output
    names = _stage_names(r.stderr)
    for expected in ("reconstructing", "fitting", "joint", "ρd texture", "writing params.json"):
        assert any(n.startswith(f"plain: {expected}") for n in names), (expected, names)
    bad = CliRunner().invoke(main, ["fit", str(capture / "caps"), "--out", str(out), "--max-steps", "0"])
    assert bad.exit_code == 2 and "--max-steps" in bad.stderr and len(bad.stderr.strip().splitlines()) == 1


@pytest.mark.slow
def test_more_steps_certify_more_scanlines_and_move_nothing_that_converged():
    truth = wj.WardParams(rho_d=(0.6, 0.5, 0.4), rho_s=0.04, alpha_x=0.12, alpha_y=0.12)
    d = wj.simulate_scanlines(truth, x_offsets=np.linspace(-40, 40, 48), seed=3)
    fits = {n: wj.fit_scanlines(d.f_r, d.wi, d.wo, weights=1 / d.sigma**2, max_steps=n) for n in (1, 4, 16)}
    stopped = {n: int(np.sum(f.status == wj.Status.MAX_STEPS)) for n, f in fits.items()}
    assert stopped[1] > stopped[4] >= stopped[16], stopped
    both = (fits[4].status == wj.Status.CONVERGED) & (fits[16].status == wj.Status.CONVERGED)
    assert both.any()
    # a scanline certified at 4 steps is at its minimum: 12 more steps move α by far less than its σ
    da = np.abs(fits[16].params.alpha_x[both] - fits[4].params.alpha_x[both])
    assert np.all(da < 0.01 * fits[4].stderr.alpha_x[both])
    default = wj.fit_scanlines(d.f_r, d.wi, d.wo, weights=1 / d.sigma**2)
    np.testing.assert_array_equal(default.status, fits[4].status)  # the default is 4 steps
    with pytest.raises(ValueError, match="max_steps must be a positive integer"):
        wj.fit_scanlines(d.f_r, d.wi, d.wo, max_steps=0)


def test_the_report_kernel_starts_without_a_warning():
    # ipykernel warns on every start over unencrypted TCP; the report's kernel talks over IPC sockets
    import subprocess
    import sys

    from wardjax.report._render import _kernel_manager_class

    kw = _kernel_manager_class()
    if not kw:
        pytest.skip("no IPC transport on this platform")
    km = kw["kernel_manager_class"]()
    assert km.transport == "ipc"
    code = (
        "import asyncio\n"
        "from wardjax.report._render import _kernel_manager_class\n"
        "async def go():\n"
        "    km = _kernel_manager_class()['kernel_manager_class']()\n"
        "    await km.start_kernel()\n"
        "    kc = km.client(); kc.start_channels(); await kc.wait_for_ready(timeout=60)\n"
        "    kc.stop_channels(); await km.shutdown_kernel(now=False)\n"
        "asyncio.run(go())\n"
    )
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert res.returncode == 0, res.stderr
    assert "WARNING" not in res.stderr and "Warning" not in res.stderr, res.stderr


@pytest.mark.slow
def test_diagnose_on_a_320_by_240_capture_shows_every_stage(tmp_path):
    p = wj.WardParams(rho_d=(0.5, 0.4, 0.3), rho_s=0.05, alpha_x=0.12, alpha_y=0.15)
    wj.simulate_capture(p, tmp_path / "cap", seed=0, image_size=(320, 240))  # wood texture, as wardjax simulate
    r = CliRunner().invoke(main, ["diagnose", str(tmp_path / "cap"), "--out", str(tmp_path / "rep"), "--progress"])
    assert r.exit_code == 0, r.output
    names = _stage_names(r.stderr)
    for expected in ("loading the capture", "reconstructing", "baseline fit", "step 1: testing", "writing report"):
        assert any(n.startswith(expected) for n in names), (expected, names)


@pytest.mark.slow
def test_report_prints_its_stages_and_no_third_party_warning(capture, tmp_path):
    import subprocess
    import sys

    fits = tmp_path / "fits"
    CliRunner().invoke(main, ["fit", str(capture / "caps"), "--out", str(fits), "--quiet"])
    res = subprocess.run(
        [sys.executable, "-m", "wardjax.run._cli", "report", str(fits), "-o", str(tmp_path / "r.html"), "--progress"],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert res.returncode == 0, res.stderr
    other = [ln for ln in res.stderr.splitlines() if ln.strip() and not LINE.match(ln.strip())]
    assert not other, other  # nothing on stderr but the stages
    assert len(_stage_names(res.stderr)) == 4
