"""Add HUD Preset's builder (hud_addon/build.py, with hud_addon/units.py): a preset built in millimetres in
a collection of its own, replacing the previous one; lengths shown in the scene's unit system.

Each scenario (a ``scenario_*`` function: the scene set up, rendered or exported inside the bpy module)
sits before the tests that assert on its result, and runs in a process of its own through
tests/addon/blender_runner.py (tests.support.addon.in_blender)."""

from __future__ import annotations

import tempfile
from pathlib import Path

import pytest

from tests.support.addon import in_blender, needs_bpy

pytestmark = [needs_bpy, pytest.mark.slow]


def scenario_preset_twice():
    """Add HUD Preset on Blender's startup scene, twice, then once more without replacing."""
    import bpy

    from tests.support.blender import disable, enable_from_source

    module = enable_from_source(bpy, Path(tempfile.mkdtemp()))
    scene = bpy.context.scene
    startup = sorted(o.name for o in scene.objects)
    bpy.ops.hud.add_preset(preset="hud-direct")
    first = sorted(o.name for o in scene.objects)
    bpy.ops.hud.add_preset(preset="hud-direct")
    second = sorted(o.name for o in scene.objects)
    led = next(o for o in scene.objects if o.hud.emits)
    led_area = sum(poly.area for poly in led.data.polygons)  # Blender units squared
    cam = scene.camera.data.hud
    shown_mm = {"pupil": cam.pupil_diameter_mm_shown, "stored": cam.pupil_diameter_mm}
    units = {"scale_length": scene.unit_settings.scale_length, "length_unit": scene.unit_settings.length_unit}
    bpy.ops.hud.add_preset(preset="analytic-mirror", replace=False)
    kept = sorted(c.name for c in scene.collection.children)
    scene.unit_settings.scale_length = 1.0  # a scene in metres shows the same pupil as 0.004 m
    shown_m = cam.pupil_diameter_mm_shown
    cam.pupil_diameter_mm_shown = 0.003  # set in metres, stored in mm
    stored_after = cam.pupil_diameter_mm
    disable(module)
    return {"startup": startup, "first": first, "second": second, "led_area": led_area, "units": units,
            "shown_mm": shown_mm, "collections": kept, "shown_m": shown_m, "stored_after": stored_after}


def test_add_hud_preset_builds_in_millimetres_and_replaces_the_previous_one():
    """On Blender's startup scene the preset replaces the startup cube, camera and point light and is built
    in a collection in millimetres (1 unit = 1 mm: hud-direct's LED dies are 0.2 units wide); pressed
    again it replaces itself (no "Eye.001"); with Replace off it adds beside. Lengths show in the
    scene's unit system and are stored in mm."""
    res, _ = in_blender(scenario_preset_twice)
    assert {"Cube", "Camera", "Light"} <= set(res["startup"])
    assert not {"Cube", "Camera", "Light"} & set(res["first"])  # the preset's Eye is the camera (issue 31)
    assert res["second"] == res["first"] and not any(n.endswith(".001") for n in res["second"])
    assert res["units"]["length_unit"] == "MILLIMETERS" and res["units"]["scale_length"] == pytest.approx(0.001)
    assert res["led_area"] == pytest.approx(0.2 * 0.2, rel=1e-3)  # a 0.2 x 0.2 mm die, in mm^2
    assert res["shown_mm"] == {"pupil": pytest.approx(4.0), "stored": pytest.approx(4.0)}
    assert [c for c in res["collections"] if c.startswith("HUD")] == ["HUD analytic-mirror", "HUD hud-direct"]
    assert res["shown_m"] == pytest.approx(0.004) and res["stored_after"] == pytest.approx(3.0)


def scenario_clear_startup():
    """Blender's startup scene, its cube, camera and light cleared as Add HUD Preset clears them."""
    import sys

    import bpy

    from tests.support.blender import disable, enable_from_source

    module = enable_from_source(bpy, Path(tempfile.mkdtemp()))
    removed = sys.modules[f"{module}.hud_addon.build"].clear_previous(bpy.context.scene)
    disable(module)
    return removed


def test_add_hud_preset_says_it_removed_the_startup_cube_too():
    """A second walk-through: Add HUD Preset removed the startup cube but its message named only the
    startup light and camera."""
    removed, _ = in_blender(scenario_clear_startup)
    assert sorted(removed) == ["the startup camera", "the startup cube", "the startup light"], removed
