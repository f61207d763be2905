"""Forward tracing (tracer/methods/forward.py): its efficiency falls with the pupil and the report warns,
an emitter left without particles is named, and crossed polarisers never splat negative luminance."""

import numpy as np
import pytest

from tests.support.render import render, render_report
from tests.support.scenes import edit_json, panel_in_view
from tests.support.stats import film_dof, t_bound
from tracer.core.errors import SceneError
from tracer.methods import INTEGRATORS, Budget
from tracer.scene import load_scene
from tracer.transport.world import World


@pytest.mark.slow
def test_an_emitter_forward_tracing_leaves_without_particles_is_named(tmp_path):
    """Two 20 mm panels side by side, 1e12 and 1e-6 cd/m^2 (the range the scene format allows): forward
    tracing emits by flux, so the dim one gets 1e-18 of the particles and rendered 0 +- 0, silently (a
    hand-built scene). The warning names it with its share; backward tracing reads it exactly, and no
    preset is warned (their emitters share the flux evenly)."""
    from presets import PRESETS
    from presets._build import SceneBuilder, frame_matrix, rectangle
    from tracer.transport.world import World

    sb = SceneBuilder(tmp_path / "s", "range", "1e12 next to 1e-6 cd/m^2")
    for name, x, lum in (("bright", -10.0, 1e12), ("dim", 10.0, 1e-6)):
        sb.add(name, rectangle(20.0, 20.0)[:2], {"type": "absorber"}, frame_matrix([x, 0, 0], [1, 0, 0], [0, 0, 1]),
               emission={"luminance": lum, "aim": {"target": "eye", "share": 0.9}})
    folder = sb.write(eye={"position": [0, 0, 500.0], "gaze": [0, 0, -1], "up": [0, 1, 0], "pupil_diameter_mm": 4.0,
                           "accommodation_distance_mm": 500.0, "resolution": [4, 2], "fov_deg": [4.5, 2.2]})
    res = INTEGRATORS["forward"](load_scene(folder), 1).render(Budget(rays=300_000))
    said = [w for w in res.warnings if "emits particles in proportion to flux" in w]
    assert len(said) == 1 and f"of its {res.paths:,} particles fewer than 100 came from dim (1e-18 of the flux, " \
        "about 3.93e-13 particles)" in said[0], res.warnings
    assert "bright" not in said[0]
    y, var, back = render(folder, "backward", 300_000)
    dim, err = y[:, 2:], np.sqrt(var[:, 2:])  # the dim panel's pixels, seen directly
    assert np.all(np.abs(dim - 1e-6) < t_bound(dim.size, film_dof(back.film)) * err) and np.all(err < 1e-4 * 1e-6), y
    for name, module in PRESETS.items():
        world = World(load_scene(module.write(tmp_path / name)))
        assert INTEGRATORS["forward"](world, 1).starved_emitters(131072) == [], name


@pytest.mark.slow
def test_forward_with_a_shrinking_pupil(tmp_path):
    """The pupil shrinks toward a pinhole: forward efficiency falls with its area, the report warns,
    and a zero pupil is refused with the field named."""
    effs, warned = [], []
    for pupil in (4.0, 0.4, 0.04):
        report = render_report(panel_in_view(tmp_path / f"pupil{pupil}", 100.0, pupil), "forward", 2_000_000, tmp_path)
        effs.append(report["efficiency"])
        warned.append(bool(report["warnings"]))
    assert effs[0] > effs[1] > effs[2]
    assert effs[1] == pytest.approx(effs[0] / 100, rel=0.5)
    assert not warned[0] and warned[2]
    folder = panel_in_view(tmp_path / "pinhole", 100.0, 1.0)
    edit_json(folder, lambda d: d["eye"].update(pupil_diameter_mm=0.0))
    with pytest.raises(SceneError, match="eye.pupil_diameter_mm"):
        load_scene(folder)


@pytest.mark.parametrize("name", ["hud-direct-s-sunglasses", "hud-direct-film-sunglasses"])
def test_forward_tracing_through_sunglasses_gives_no_negative_luminance(preset, name):
    """Float32 rounding over the windshield's events takes fully s-polarised light a little past a
    degree of 1 (1e-5); the crossed analyser's factor m0 + m1 s1 then went below 0 and forward tracing
    of hud-direct-s-sunglasses splatted negative luminance (-0.01 cd/m^2 at 3 M rays), which ended the
    render in the preview's tone mapping with a traceback. The factor is clamped at 0, as scatter's is."""
    world = World(load_scene(preset(name, resolution=(60, 20))))
    integ = INTEGRATORS["forward"](world, 1, options=dict(world.scene.method_options("forward")))
    film = integ.render(Budget(rays=1_000_000)).film
    rgb = film.rgb()
    assert np.all(np.isfinite(rgb)) and rgb.min() >= 0.0, rgb.min()
    assert rgb.max() > 0


def test_light_paths_that_miss_the_eye_say_what_to_aim_at(tmp_path):
    """Issue 31's walk-through: Show Light Paths found nothing in a scene built by hand ("none of 100,000
    particles reached the eye pupil") and gave no hint. An unaimed emitter is told to aim, and at the
    first optic where mirrors or lenses lie between; analytic-mirror's panel, aimed at the eye though
    its light comes by a mirror, is told the latter. (A panel turned away is named by facing_hint, tested
    with the renders' "no light path found".)"""
    from presets import PRESETS
    from tests.support.scenes import edit_json, panel_in_view

    folder = panel_in_view(tmp_path / "panel", 20.0, 4.0)
    forward = INTEGRATORS["forward"](load_scene(folder), 1)
    hint = forward.no_paths_hint()
    assert "without an aim" in hint and "first optic" in hint, hint
    mirror = PRESETS["analytic-mirror"].write(tmp_path / "mirror")
    edit_json(mirror, lambda d: [o["emission"].update(aim={"target": "eye", "share": 0.9}) for o in d["objects"]
                                 if "emission" in o])
    hint = INTEGRATORS["forward"](load_scene(mirror), 1).no_paths_hint()
    assert "first optic" in hint and "without an aim" not in hint, hint
