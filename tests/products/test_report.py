"""The report (tracer/products/report.py): the HUD Readouts rows state the report's figures, and every
method's report has the sections sweep keys are checked against."""

import json

import pytest

from tracer.methods import INTEGRATORS, Budget
from tracer.products.render import render_folder
from tracer.products.report import REPORT_SECTIONS


@pytest.mark.slow
def test_readouts_give_the_reports_figures(preset, tmp_path):
    """The HUD Readouts panel's rows (tracer.products.report.readouts) state the report's own numbers."""
    from tracer.methods import Budget
    from tracer.products.render import render_scene
    from tracer.products.report import readouts
    from tracer.scene import load_scene

    report, _ = render_scene(load_scene(preset("hud-direct")), "backward", Budget(rays=2_000_000), 3, tmp_path / "o")
    rows = dict(readouts(report))
    hud, ghost = report["hud"], report["brightness_theorem"]["ghost"]
    assert rows["Symbols"] == f"{hud['symbol_cd_m2']:,.4g} cd/m²"
    assert rows["Contrast (Ls + Lb) / Lb"].startswith(f"{hud['contrast_ratio']:,.4g}")
    assert rows["Ghost"].startswith(f"{ghost['ratio_to_symbol']:.3g} of the symbols, {ghost['offset_mrad']:.3g} mrad")
    assert f"{report['rays']:,}" in rows["Rays"] and "Spot" in rows
    # A stopped render has no analysis: the rows it cannot fill are left out.
    partial = dict(report, hud=None, brightness_theorem=None, partial=True)
    rows = dict(readouts(partial))
    assert "Symbols" not in rows and "Ghost" not in rows and rows["Rays"].endswith("stopped early")


@pytest.mark.parametrize("method", sorted(INTEGRATORS))
def test_every_method_reports_the_sections_that_sweep_keys_are_checked_against(tmp_path, preset, method):
    """REPORT_SECTIONS is what --y and --require keys are refused against before any ray: every
    method's report.json has exactly those top-level keys, in that order."""
    report, _ = render_folder(preset("analytic-mirror"), method, Budget(rays=40_000), 1, tmp_path / "out")
    assert tuple(report) == REPORT_SECTIONS
    assert tuple(json.loads((tmp_path / "out" / "report.json").read_text())) == REPORT_SECTIONS
