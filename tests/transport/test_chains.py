"""The specular chains of the analysis (tracer.transport.chains): the lights' quadrature is coarse only
where a light is small for its distance to the nearest scattering surface."""

import numpy as np
import pytest

from tests.support.scenes import condenser_scene, edit_json
from tracer.analysis.brightness import brightness_theorem
from tracer.scene import load_scene
from tracer.transport.world import World


@pytest.mark.slow
def test_the_quadrature_is_coarse_only_where_the_light_is_small_for_its_distance(hud_with_sky, monkeypatch):
    """The LEDs' quadrature level follows their size over their distance to the nearest scattering
    surface (relative error ~ (h/d)^2 < 1e-4): hud-direct's 0.2 mm dies need one point each instead of
    16 (the analysis ran 5 s, now under 1 s), and the predictions agree with 16 points to 1e-4."""
    from tracer.transport import chains as analysis

    world = World(load_scene(hud_with_sky))
    levels = analysis.quadrature_levels(world)
    assert levels.shape == (world.lights.tris.area.shape[0],) and np.all(levels == 1)
    pts, _, weights, _, _, _ = world.lights.quadrature(levels)
    assert weights.sum() == pytest.approx(world.lights.tris.area.sum(), rel=1e-12)
    zeros = np.zeros((world.eye.height, world.eye.width))
    adaptive = brightness_theorem(world, zeros, zeros, environment=False)
    monkeypatch.setattr(analysis, "quadrature_levels", lambda w, level=4: np.full(w.lights.tris.area.shape[0], 4))
    fine = brightness_theorem(World(load_scene(hud_with_sky)), zeros, zeros, environment=False)
    for key in ("symbol", "background"):
        assert adaptive[key]["predicted_cd_m2"] == pytest.approx(fine[key]["predicted_cd_m2"], rel=1e-4)


def test_a_large_light_close_to_a_screen_keeps_the_fine_quadrature(tmp_path):
    """The screen lit directly by a 6 mm LED 60 mm away (cells of 3 mm would be 5 % of the distance):
    level 4, the finest (tests/analysis/test_brightness.py's test_without_the_glass_the_same_screen_is_compared
    checks that prediction against the render)."""
    from tracer.transport import chains as analysis

    folder = condenser_scene(tmp_path / "s")
    edit_json(folder, lambda d: d.update(objects=[o for o in d["objects"] if o["name"] != "glass"]))
    assert np.all(analysis.quadrature_levels(World(load_scene(folder))) == 4)
