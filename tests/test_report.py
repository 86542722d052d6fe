"""wardjax report: a folder of fits as one executed notebook, in a self-contained HTML file."""

import html
import json
import re
import shutil
from pathlib import Path

import imageio.v3 as iio
import numpy as np
import pytest
import tifffile

from wardjax.report import CaptureResult, flag_outliers, write_report
from wardjax.report._collect import split_rhat
from wardjax.run import main, run_batch
from wardjax.simulate import SensorNoise, simulate_capture
from wardjax.ward import WardParams

EXAMPLE = Path(__file__).parents[1] / "examples" / "smartphone" / "colorchecker-red"

SCANLINE = ("glossy", "matte")
# Every capture's section: its figures under these headings, each one embedded PNG.
SCANLINE_FIGURES = (
    "1σ by error model",
    "Fitted vs measured scanline",
    "Residuals over the image",
    "ρd texture and a synthesised tile",
)
SMARTPHONE_FIGURES = ("α posterior: 68 and 95 % intervals", "α posterior: corner plot", "α posterior: chains")


def _smartphone_capture(folder):
    """A smartphone capture: a noisy near-white photo and three observers (Table 1b: NCS white, gloss 50)."""
    folder.mkdir(parents=True)
    rng = np.random.default_rng(0)
    iio.imwrite(folder / "photo.png", np.clip(rng.normal(237, 3, (96, 128, 3)), 0, 255).astype(np.uint8))
    (folder / "capture.toml").write_text(
        'method = "smartphone"\n[photo]\nfile = "photo.png"\nregion = [20, 80, 30, 100]\n'
        "[thresholds]\nppb = [10, 11, 12]\n"
    )


@pytest.fixture(scope="module")
def fits(tmp_path_factory):
    root = tmp_path_factory.mktemp("report")
    for name, (rd, rs, a) in zip(SCANLINE, [(0.5, 0.05, 0.08), (0.3, 0.03, 0.16)]):
        p = WardParams(rho_d=(rd, rd, rd), rho_s=rs, alpha_x=a, alpha_y=a)
        simulate_capture(p, root / "captures" / name, seed=1, image_size=(96, 72), noise=SensorNoise(0.002, 0.0))
    _smartphone_capture(root / "captures" / "phone")
    shutil.copytree(EXAMPLE, root / "captures" / "phone-chart")  # a real photo with its colour chart
    run_batch([root / "captures"], root / "fits")
    return root / "fits"


@pytest.fixture(scope="module")
def report_page(fits, tmp_path_factory):
    """The HTML report of the fits, with a stand-in for what ``wardjax diagnose`` writes beside one of them.

    ``report.json`` holds the gap after each step; the real diagnose run is in a slow test below.
    """
    (fits / "matte" / "diagnose").mkdir(exist_ok=True)
    (fits / "matte" / "diagnose" / "report.json").write_text('{"found": ["anisotropy"], "gap": [3.9, 1.02]}')
    return write_report(fits, tmp_path_factory.mktemp("page") / "report.html").read_text(encoding="utf-8")


def _sections(page: str) -> dict[str, str]:
    """Each capture's section of the HTML report, from its heading to the next capture's."""
    starts = [(m.start(), m.group(1)) for m in re.finditer(r'id="capture-([^"]+)"', page)]
    ends = [s for s, _ in starts[1:]] + [len(page)]
    return {name: page[s:e] for (s, name), e in zip(starts, ends)}


def _figures_under(section: str) -> dict[str, int]:
    """Embedded PNGs under each ``<h3>`` heading of a section."""
    parts = re.split(r"<h3[^>]*>(.*?)</h3>", section, flags=re.S)
    out = {}
    for i in range(1, len(parts) - 1, 2):
        heading = html.unescape(re.sub(r"<a[^>]*>.*?</a>|<[^>]+>", "", parts[i])).strip()
        out[heading] = parts[i + 1].count("data:image/png;base64,")
    return out


def test_html_report_has_every_capture_section_and_figure_and_needs_nothing_else(report_page):
    page = report_page
    assert "Batch: 4 captures" in page
    sections = _sections(page)
    assert sorted(sections) == ["glossy", "matte", "phone", "phone-chart"]
    for name in SCANLINE:
        figs = _figures_under(sections[name])
        assert all(figs.get(h) == 1 for h in SCANLINE_FIGURES), (name, figs)
        assert "Parameters ± 1σ by error model (dimensionless)" in figs  # texture field, sandwich, model
        assert "texture field (reported)" in sections[name] and "scanline sandwich" in sections[name]
        assert not any(h.startswith("α posterior") for h in figs)
    assert _figures_under(sections["matte"]).get("Missing-effect gap") == 1
    assert "Missing-effect gap" not in sections["glossy"]  # diagnose did not run there
    figs = _figures_under(sections["phone"])
    assert all(figs.get(h) == 1 for h in SMARTPHONE_FIGURES), figs
    for label in ("acceptance fraction", "autocorrelation time", "effective samples", "split-R̂"):
        assert label in html.unescape(sections["phone"]), label
    assert "Residuals over the image" not in figs and "Fitted vs measured scanline" not in figs
    assert not re.search(r'(src|href)="https?://', page)  # opens with no server and no network
    # no cell printed an error or a warning (stderr outputs carry this mime type in the HTML)
    assert not re.search(r'<div[^>]*data-mime-type="application/vnd\.jupyter\.(stderr|error)"', page)


def _text(fragment: str) -> str:
    """The visible text of an HTML fragment, entities decoded, whitespace collapsed."""
    return " ".join(html.unescape(re.sub(r"<[^>]+>", " ", fragment)).split())


def test_every_number_is_labelled_alpha_is_an_interval_and_correlations_are_shown(report_page, fits):
    page = report_page
    batch = _text(page[page.index("Batch:") : page.index('id="capture-')])
    # the fit-quality column names what it is: unweighted fits give an RMS residual in sr⁻¹, not a "χ²/dof"
    assert "fit quality" in batch and "χ²/dof" not in batch and "sr⁻¹" in batch and "unit weights" in batch
    assert "dimensionless" in batch and "median [68 % interval]" in batch
    sections = {k: _text(v) for k, v in _sections(page).items()}
    for name in SCANLINE:
        sec = sections[name]
        doc = json.loads((fits / name / "params.json").read_text())
        cov = np.asarray(doc["fit"]["covariance"]["matrix"])
        r = cov[0, 1] / np.sqrt(cov[0, 0] * cov[1, 1])
        assert "Correlations of the shared parameters" in sec and f"ρs–α {r:+.2f}" in sec, name
        assert re.search(r"α = [0-9.]+ \(dimensionless[^)]*\); 68 % \[[0-9.]+, [0-9.]+\], 95 % \[", sec), name
        assert "Which σ to believe" in sec and "(reported)" in sec
        assert "ρd (R, G, B; linear, sRGB primaries, white E; dimensionless)" in sec
        rms = doc["fit"]["diagnostics"]["residuals"]["rms"]
        assert f"fit quality, RMS residual, unit weights (no noise σ given, so no χ²): RMS {rms:.2g} sr⁻¹" in sec
    for name in ("phone", "phone-chart"):
        sec = sections[name]
        assert re.search(r"posterior median\); 68 % \[[0-9.]+, [0-9.]+\], 95 % \[[0-9.]+, [0-9.]+\]", sec)
        assert "no symmetric ± is quoted" in sec and "ρs–α: none" in sec
    assert "the camera's colour error" in sections["phone"]  # no chart: said, not hidden
    assert re.search(r"held out of its own fit, mean [0-9.]+, RMS [0-9.]+", sections["phone-chart"])
    assert "log_f" not in page


def test_gap_figure_shows_a_difference_of_0_002():
    """``gap.png`` and the report's gap chart: 1.003 against 1.001 apart on the axis, not two bars from 0."""
    from wardjax.effects import gap_figure

    ax = gap_figure([1.003, 1.001], ["baseline", "+ anisotropy"]).axes[0]
    lo, hi = ax.get_ylim()
    assert lo > 0.99 and hi < 1.01  # the 0.002 step spans a visible share of the axis
    assert (1.003 - 1.001) / (hi - lo) > 0.2
    assert "dimensionless" in ax.get_ylabel()


def test_residuals_file_holds_the_fit_over_the_image(fits):
    """residuals.npz: measured f_r where the probe is, the joint fit beside it; RMS as params.json says."""
    doc = json.loads((fits / "glossy" / "params.json").read_text())
    with np.load(fits / "glossy" / "residuals.npz") as z:
        f_r, model, b, origin = z["f_r"], z["model"], int(z["binning"]), z["origin"]
    assert b == doc["fit"]["diagnostics"]["binning"]
    fitted = np.isfinite(model)
    assert fitted.sum() > 100 and np.array_equal(fitted, np.isfinite(f_r))
    rms = np.sqrt(np.mean((f_r - model)[fitted] ** 2))
    assert rms == pytest.approx(doc["fit"]["diagnostics"]["residuals"]["rms"], rel=1e-4)  # float32 storage
    # the bins lie over the probe: the fitted ρd texture (full resolution) is finite there
    rho = tifffile.imread(fits / "glossy" / "rho_d.tif")
    rows, cols = np.nonzero(fitted.all(axis=-1))
    centre = np.isfinite(rho[origin[0] + b * rows + b // 2, origin[1] + b * cols + b // 2]).all(axis=-1)
    assert centre.mean() > 0.95


def test_split_rhat_against_its_expected_value():
    """Mixed AR(1) chains read √(1 + τ/n) (τ = (1 + φ)/(1 − φ)); walkers stuck apart read far above 1."""
    rng = np.random.default_rng(0)
    phi, steps, walkers = 0.8, 4000, 64
    x = np.empty((steps, walkers))
    x[0] = rng.standard_normal(walkers)
    for t in range(1, steps):
        x[t] = phi * x[t - 1] + np.sqrt(1 - phi**2) * rng.standard_normal(walkers)
    tau = (1 + phi) / (1 - phi)
    assert split_rhat(x) == pytest.approx(np.sqrt(1 + tau / (steps // 2)), abs=2e-3)
    stuck = x + np.where(np.arange(walkers) < walkers // 2, 0.0, 1.0)  # half the walkers 1 σ away
    assert split_rhat(stuck) > 1.1


@pytest.mark.slow
def test_report_shows_the_gap_chart_of_a_real_diagnose_run(fits, tmp_path):
    folder = tmp_path / "fits"
    shutil.copytree(fits, folder, ignore=shutil.ignore_patterns("diagnose"))
    with pytest.raises(SystemExit) as e:
        main(["diagnose", str(fits.parent / "captures" / "glossy"), "--out", str(folder / "glossy" / "diagnose")])
    assert e.value.code == 0
    rep = json.loads((folder / "glossy" / "diagnose" / "report.json").read_text())
    page = write_report(folder, tmp_path / "report.html").read_text(encoding="utf-8")
    sections = _sections(page)
    assert _figures_under(sections["glossy"]).get("Missing-effect gap") == 1
    assert "Missing-effect gap" not in sections["matte"]
    assert len(rep["gap"]) >= 1


@pytest.mark.slow
def test_ipynb_report_through_the_cli(fits, tmp_path):
    out = tmp_path / "report.ipynb"
    with pytest.raises(SystemExit) as e:
        main(["report", str(fits), "-o", str(out)])
    assert e.value.code == 0
    import nbformat

    nb = nbformat.read(out, as_version=4)
    assert all(c.get("execution_count") for c in nb.cells if c.cell_type == "code")


def test_report_refuses_a_folder_without_fits_and_an_unknown_suffix(tmp_path, capsys):
    with pytest.raises(SystemExit) as e:
        main(["report", str(tmp_path), "-o", str(tmp_path / "r.html")])
    assert e.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "no finished capture" in err[0]
    with pytest.raises(ValueError, match="expected .html or .ipynb"):
        write_report(tmp_path, tmp_path / "r.pdf")
    assert not (tmp_path / "r.html").exists()


def _result(name, alpha):
    doc = {
        "params": {"rho_d": [0.5, 0.5, 0.5], "rho_s": 0.04, "alpha_x": alpha, "alpha_y": alpha},
        "stderr": {"rho_d": [0.001] * 3, "rho_s": 0.001, "alpha_x": 0.001, "alpha_y": 0.001},
    }
    return CaptureResult(name, None, doc)


def test_outliers_are_robust_z_beyond_3_5_from_the_batch_median():
    alphas = [0.100, 0.101, 0.099, 0.102, 0.098, 0.140]  # MAD-σ ≈ 0.0022: the last is ~18 σ out
    flags = flag_outliers([_result(f"c{i}", a) for i, a in enumerate(alphas)])
    assert flags["c5"] == {"alpha_x", "alpha_y"}
    assert all(not flags[f"c{i}"] for i in range(5))
    # three captures: too few to call one an outlier
    assert not any(flag_outliers([_result(f"c{i}", a) for i, a in enumerate([0.1, 0.1, 0.5])]).values())
