"""``hud-trace readouts`` (tracer/cli.py): one row per figure of a render's report; a file that is not a
report gives one line and exit 2."""

import json
import subprocess
import sys

import pytest

from tests.support.cli import assert_one_line_error, run_cli
from tests.support.paths import ROOT


@pytest.mark.slow
def test_readouts_prints_the_reports_figures(tmp_path):
    """hud-trace readouts DIR prints one row per figure of the report (the add-on's HUD Readouts); a file
    that is not a report gives one line and exit 2."""
    from tracer.cli import main
    from tracer.products.report import readouts

    out = tmp_path / "r"
    assert main(["render", "analytic-mirror", "--rays", "300000", "--seed", "2", "--out", str(out), "--quiet"]) == 0
    proc = subprocess.run([sys.executable, "-m", "tracer.cli", "readouts", str(out)], capture_output=True, text=True,
                          cwd=ROOT)
    assert proc.returncode == 0, proc.stderr
    rows = readouts(json.loads((out / "report.json").read_text()))
    lines = proc.stdout.splitlines()
    assert len(lines) == len(rows) and all(line.split()[0] == label.split()[0] and line.endswith(text)
                                           for line, (label, text) in zip(lines, rows, strict=True))
    (tmp_path / "x.json").write_text("{}")
    bad = subprocess.run([sys.executable, "-m", "tracer.cli", "readouts", str(tmp_path / "x.json")],
                         capture_output=True, text=True, cwd=ROOT)
    assert bad.returncode == 2 and len(bad.stderr.strip().splitlines()) == 1 and "not a hud-trace report" in bad.stderr


def test_readouts_of_a_file_that_is_not_a_report_give_one_line(tmp_path):
    """A JSON list gave an AttributeError traceback; a field of the wrong type a garbled message."""
    for name, text in (("list.json", "[]"), ("typed.json", json.dumps({"luminance": "bright", "hud": {}}))):
        (tmp_path / name).write_text(text)
        code, err = run_cli("readouts", tmp_path / name)
        assert_one_line_error(code, err, name, "not a hud-trace report")


def test_readouts_of_a_noisy_render_whose_background_median_is_0(tmp_path):
    """A forward render of few rays leaves most background pixels at 0: the spot's ratio to the median
    is null, and readouts said "not a hud-trace report" (a None formatted as a number)."""
    from tracer.products.report import readouts

    code, err = run_cli("render", "analytic-mirror", "--rays", "200000", "--workers", "1", "--quiet", "--out",
                        tmp_path / "r")
    assert code == 0, err
    report = json.loads((tmp_path / "r" / "report.json").read_text())
    report["hud"] = {"display_pixels": 100, "symbol_pixels_from": "lcd_cells", "symbol_pixels": 10,
                     "background_pixels": 20, "symbol_cd_m2": 761.4, "background_cd_m2": 3.0, "contrast_ratio": 254.8,
                     "spot": {"peak_cd_m2": 8.2, "peak_pixel": [1, 2], "peak_over_median_background": None,
                              "peak_over_symbol": 0.011, "half_peak_diameter_deg": 1.0, "smoothing_px": 29}}
    (tmp_path / "r" / "report.json").write_text(json.dumps(report))
    assert dict(readouts(report))["Spot"] == "8.2 cd/m², the background's median is 0, 1 deg"
    code, err = run_cli("readouts", tmp_path / "r")
    assert code == 0, err
