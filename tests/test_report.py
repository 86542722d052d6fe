"""wardjax report: a folder of fits as one executed notebook, in a self-contained HTML file."""

import re

import pytest

from wardjax.report import CaptureResult, flag_outliers, write_report
from wardjax.run import main, run_batch
from wardjax.simulate import SensorNoise, simulate_capture
from wardjax.ward import WardParams


@pytest.fixture(scope="module")
def fits(tmp_path_factory):
    root = tmp_path_factory.mktemp("report")
    for name, (rd, rs, a) in {"glossy": (0.5, 0.05, 0.08), "matte": (0.3, 0.03, 0.16)}.items():
        p = WardParams(rho_d=(rd, rd, rd), rho_s=rs, alpha_x=a, alpha_y=a)
        simulate_capture(p, root / "captures" / name, seed=1, image_size=(96, 72), noise=SensorNoise(0.002, 0.0))
    run_batch([root / "captures"], root / "fits")
    return root / "fits"


def test_html_report_has_every_capture_section_and_figure_and_needs_nothing_else(fits, tmp_path):
    out = write_report(fits, tmp_path / "report.html")
    page = out.read_text(encoding="utf-8")
    assert "Batch: 2 captures" in page
    for name in ("glossy", "matte"):
        i = page.index(f'id="capture-{name}"')
        section = page[i : page.find('id="capture-', i + 1) if name == "glossy" else len(page)]
        # errors by model, measured ρd + synthesised tile, scanline plot: three images, all embedded
        assert section.count("data:image/png;base64,") >= 3, name
        assert "Fitted vs measured scanline" in section
    assert not re.search(r'(src|href)="https?://', page)  # opens with no server and no network
    # no cell printed an error or a warning (stderr outputs carry this mime type in the HTML)
    assert not re.search(r'<div[^>]*data-mime-type="application/vnd\.jupyter\.(stderr|error)"', page)


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
