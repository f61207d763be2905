"""A sweep's requirements (``--require``, tracer.scans.requirements): their syntax, and how a report is
judged against one."""

import re

import pytest

from tracer import cli
from tracer.scans.fields import MAX_RUNS, SweepArgumentError
from tracer.scans.requirements import parse_requirement


def test_requirement_syntax():
    q = parse_requirement("hud.spot.peak_over_median_background<=1.2")
    assert (q.key, q.op, q.value) == ("hud.spot.peak_over_median_background", "<=", 1.2)
    report = {"hud": {"spot": {"peak_over_median_background": 1.3}}}
    assert q.judge(report) == {"requirement": q.text, "value": 1.3, "met": False,
                               "why": "hud.spot.peak_over_median_background is 1.3"}
    assert q.judge({"hud": None})["why"] == "hud is not a block"
    assert parse_requirement("rays > 1").judge({"rays": 1})["met"] is False
    assert parse_requirement("rays >= 1").judge({"rays": 1})["met"] is True
    with pytest.raises(SweepArgumentError):
        parse_requirement("x => 1")
    assert str(MAX_RUNS) in cli.build_parser()._subparsers._group_actions[0].choices["sweep"].format_help()


@pytest.mark.parametrize("text, words", [
    ("hud.symbol >= 10", "did you mean 'symbol_cd_m2'"),
    ("hud.spot.peak_cdm2 >= 10", "did you mean 'peak_cd_m2'"),
    ("optics.design_eye.ghost_seperation_arcmin < 1", "did you mean 'ghost_separation_arcmin'"),
])
def test_keys_below_a_section_are_checked_before_the_runs(text, words):
    """A mistyped HUD figure rendered every run, then exited 3 with "no run meets" (only the section was
    checked)."""
    with pytest.raises(SweepArgumentError, match=words):
        parse_requirement(text)
    parse_requirement("hud.spot.contrast_against_environment >= 1")  # a key of the hybrid's spot


def test_the_hud_keys_are_every_key_the_figures_give(tmp_path):
    """HUD_KEYS and SPOT_KEYS hold every key hud_figures writes: with an environment on lcd_cells masks
    (hud-direct) and on the luminance threshold (hud-screen)."""
    import numpy as np

    from presets import PRESETS
    from tracer.analysis.hud import HUD_KEYS, SPOT_KEYS, hud_figures
    from tracer.scene import load_scene
    from tracer.transport.world import World

    rng = np.random.default_rng(1)
    keys, spot = set(), set()
    for name in ("hud-direct", "hud-screen"):
        world = World(load_scene(PRESETS[name].write(tmp_path / name)))
        shape = (world.eye.height, world.eye.width)
        y = np.full(shape, 10.0)
        y[:, shape[1] // 3:shape[1] // 2] = 1000.0  # a band of symbols on a black level
        y *= 1 + 0.1 * rng.random(shape)
        fig = hud_figures(world, y, environment=np.full(shape, 100.0))
        assert fig is not None and "spot" in fig, name
        keys |= set(fig)
        spot |= set(fig["spot"])
    assert keys <= set(HUD_KEYS) and spot <= set(SPOT_KEYS)
    assert {"symbol_threshold_cd_m2", "environment_behind_symbols_cd_m2"} <= keys
    assert "contrast_against_environment" in spot


@pytest.mark.parametrize("text, words", [
    # the walk-through's case: every run rendered, each failed for want of the figure, exit 3
    ("brightness_theorem.ghost.ratio >= 0.1", "did you mean 'ratio_to_symbol'"),
    ("brightness_theorem.symbol.rendered_over_predicte > 0.9", "did you mean 'rendered_over_predicted'"),
    ("luminance.maen > 1", "did you mean 'mean'"),
    ("noise.median_relative_error < 0.1", "did you mean 'median_relative_standard_error_lit_pixels'"),
    ("optics.target.distanse_mm > 1", "did you mean 'distance_mm'"),
    ("components.conection.share > 0.5", "did you mean 'connection'"),
    ("method_details.channels.hdu.mean_cd_m2 > 1", "did you mean 'hud'"),
    ("polarisation.stokes > 0", "did you mean 'stokes_vectors'"),
    ("image.widht > 1", "did you mean 'width'"),
])
def test_keys_below_every_section_are_checked_before_the_runs(text, words):
    """Only keys under hud (and optics' metrics) were checked below the section: a mistyped key under
    brightness_theorem, luminance, noise, optics... rendered every run, then failed each. Every key is
    now checked against the report's structure (tracer.scans.requirements.REPORT_KEYS)."""
    with pytest.raises(SweepArgumentError, match=words):
        parse_requirement(text)


@pytest.mark.parametrize("text", [
    "brightness_theorem.ghost.ratio_to_symbol >= 0.1",  # only where a second chain crosses the LCD
    "brightness_theorem.image.rendered_over_predicted > 0.9",  # only where no chain crosses an LCD
    "brightness_theorem.aim_coverage.scatterer.coverage > 0.98",  # an object's name
    "brightness_theorem.photon_map.radius_mm < 1",  # only where a screen is lit through optics
    "brightness_theorem.paths[0].predicted_mean_cd_m2 > 1",
    "hud.spot.contrast_against_environment <= 1.2",  # only with an environment channel
    "hud.spot.peak_pixel[1] < 10",
    "method_details.channels.environment.mean_cd_m2 > 1",  # hybrid only
    "method_details.channels.scene.pilots[0].relative_variance_medians.lit < 1",  # auto only
    "method_details.photon.final_radius_mm < 1",  # photon only
    "method_details.emitted_flux_lm > 1",  # forward only
    "components.photon.share > 0.5",
    "stage_seconds.shade < 10",
    "image.pixel_mrad[0] < 1",
    "optics.target.fov_deg[0] > 5",
    "optics.eyebox.dipvergence_mrad < 1",
    "analysis_seconds < 10",
])
def test_keys_that_some_scene_or_method_gives_are_accepted(text):
    """A key present only for some scenes or methods is accepted: the run whose report lacks it fails."""
    parse_requirement(text)


@pytest.mark.parametrize("text, words", [
    ("luminance >= 1", "luminance is a block of figures, not a number"),
    ("image.pixel_mrad < 1", "give an element's index (image.pixel_mrad[0])"),
    ("rays.total > 1", "rays is a value, not a block"),
    ("luminance[0] > 1", "luminance is not a list"),
])
def test_keys_that_lead_to_no_number_are_refused(text, words):
    """A key ending at a block or a list can never be met: refused before the runs, too."""
    with pytest.raises(SweepArgumentError, match=re.escape(words)):
        parse_requirement(text)


def _addressable(report: dict) -> list[str]:
    """Every number of ``report`` that a requirement can read: its numeric leaves whose dotted path
    leads to them (keys with dots or spaces, a hybrid's "hud.connection" component, a chain's text, are
    not reachable by a path)."""
    from tracer.core.jsonpath import lookup, parse_field
    from tracer.scans.requirements import numeric_leaves

    out = []
    for key in numeric_leaves(report, ""):
        try:
            steps = parse_field(key, globs=False)
        except ValueError:
            continue
        if lookup(report, steps)[1] is None:
            out.append(key)
    return out


@pytest.mark.slow
def test_every_number_of_every_methods_report_is_a_key_the_check_accepts(tmp_path):
    """REPORT_KEYS is written from the code that builds the report, not read off a report: every number
    that the reports of every method (analytic-mirror), of an LCD seen through optics (hud-direct: its
    sections, ghost and aims), of a screen lit through a lens (hud-screen: the photon map) and of a
    hybrid render against a sky (its channels and pilots) hold is a key it accepts, and its top level is
    REPORT_SECTIONS."""
    from presets import PRESETS
    from tests.support.scenes import edit_json
    from tracer.core.jsonpath import parse_field
    from tracer.methods import INTEGRATORS, Budget
    from tracer.products.render import render_folder
    from tracer.products.report import REPORT_SECTIONS
    from tracer.scans.requirements import REPORT_KEYS, check_report_key

    assert set(REPORT_KEYS) == set(REPORT_SECTIONS)
    sky = lambda d: d.update(environment={"type": "uniform", "luminance": 2000.0})  # noqa: E731
    cases = [("analytic-mirror", m, 40_000, {}, None) for m in sorted(INTEGRATORS)]
    cases += [("hud-direct", "backward", 100_000, {"resolution": (96, 48)}, None),
              ("hud-screen", "photon", 100_000, {"resolution": (96, 48)}, None),
              ("hud-direct", "hybrid", 100_000, {"resolution": (96, 48)}, sky)]
    keys = set()
    for i, (name, method, rays, kw, edit) in enumerate(cases):
        folder = PRESETS[name].write(tmp_path / str(i), **kw)
        if edit is not None:
            edit_json(folder, edit)
        report, _ = render_folder(folder, method, Budget(rays=rays), 1, tmp_path / f"out{i}")
        keys |= set(_addressable(report))
    for key in sorted(keys):
        check_report_key(f"--require {key}", parse_field(key, globs=False))
    assert {"brightness_theorem.ghost.ratio_to_symbol", "brightness_theorem.photon_map.radius_mm",
            "hud.spot.contrast_against_environment", "method_details.channels.environment.mean_cd_m2"} <= keys
