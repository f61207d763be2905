"""A sweep's requirements (``--require``, tracer.scans.requirements): their syntax, and how a report is
judged against one."""

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
