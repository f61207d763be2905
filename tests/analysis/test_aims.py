"""The aims' coverage (tracer.analysis.aims): an aim that misses light is told before the first ray, for the
methods whose particles follow the aims, and every preset's aims cover the light that reaches the eye."""

import subprocess
import sys

import numpy as np
import pytest

from tests.support.paths import ROOT
from tests.support.scenes import mirror_behind_glass
from tracer.analysis.brightness import brightness_theorem
from tracer.scene import load_scene
from tracer.transport.world import World

pytestmark = pytest.mark.slow


def test_an_aim_that_misses_light_is_told_before_the_first_ray(preset, tmp_path):
    """The glass block's scene: the aims' coverage over the whole image, before any ray (64 pixels, 16
    pupil points each), finds the panel's aim 16 % short, as the report's sections do after the render,
    for the methods whose particles follow the aims (forward, photon); the command line prints it
    before its progress bar. Backward tracing, whose eye paths do not use the emitters' aims, is told
    nothing."""
    from tracer.analysis.aims import AIM_COVERAGE, aim_preflight

    folder = mirror_behind_glass(preset)
    world = World(load_scene(folder))
    for method in ("forward", "photon"):
        said = aim_preflight(world, method)
        assert len(said) == 1 and said[0].startswith("the aim of panel toward pupil_image covers"), said
        assert 80 < float(said[0].split("covers ")[1].split(" %")[0]) < 87 < 100 * AIM_COVERAGE, said
    assert aim_preflight(world, "backward") == []
    out = subprocess.run([sys.executable, "-m", "tracer.cli", "render", str(folder), "--method", "forward", "--rays",
                          "100000", "--workers", "1", "--out", str(tmp_path / "o")],
                         cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stderr
    first = out.stderr.index("warning: before the first ray: the aim of panel toward pupil_image covers")
    assert first < out.stderr.index("forward: "), out.stderr  # before the render's summary line


def test_every_presets_aims_cover_the_light_that_reaches_the_eye(tmp_path):
    """The presets aim their emitters and scatterers at the pupil or its image through the optics; the
    analysis' rays over the pupil leave each inside its aim (99.2 % behind the sunglasses' tilted
    field, 99.8 % for analytic-mirror's 64-gon pupil image, 100 % elsewhere), above the line from which
    the particle methods warn of an aim. Without the screens' photon maps: their light does not move
    where the pupil's rays end, and without them the rays are the more (6 x 6 pupil points, not 3 x 3)."""
    from presets import PRESETS
    from tracer.analysis.aims import AIM_COVERAGE, aim_preflight

    seen = 0
    for name, module in PRESETS.items():
        world = World(load_scene(module.write(tmp_path / name)))
        h, w = world.eye.height, world.eye.width
        coverage = brightness_theorem(world, np.zeros((h, w)), np.zeros((h, w)), photons=0)["aim_coverage"]
        assert all(c["coverage"] >= max(0.99, AIM_COVERAGE) for c in coverage.values()), (name, coverage)
        assert aim_preflight(world, "forward") == aim_preflight(world, "photon") == [], name  # no false alarm
        seen += len(coverage)
    assert seen == len(PRESETS)  # every preset aims one object
