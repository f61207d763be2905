"""Errors told in the panels' words (hud_addon/messages.py): options and object references named as the
panels show them, not as scene.json keys or command-line flags.

Each scenario (a ``scenario_*`` function: the scene set up, rendered or exported inside the bpy module)
sits before the tests that assert on its result, and runs in a process of its own through
tests/addon/blender_runner.py (tests.support.addon.in_blender)."""

from __future__ import annotations

import tempfile
from pathlib import Path

import pytest

from tests.support.addon import in_blender, needs_bpy

pytestmark = [needs_bpy, pytest.mark.slow]


def scenario_option_messages(out):
    """Exports and an Eyebox Sweep that fail on render settings, object references, the lens and a mesh:
    what each says."""
    import bpy

    from tests.support.blender import disable, enable_from_source

    module = enable_from_source(bpy, Path(tempfile.mkdtemp()))
    bpy.ops.hud.add_preset(preset="analytic-mirror")
    s = bpy.context.scene
    messages = {}

    def attempt(case, op=lambda folder: bpy.ops.hud.export_scene(directory=str(folder))):
        try:
            op(Path(out) / case.replace(" ", "_"))
            messages[case] = None
        except RuntimeError as e:
            messages[case] = str(e)

    s.hud.backward_exit_pupil_use, s.hud.backward_exit_pupil_by = True, "object"
    attempt("exit pupil unset")
    s.hud.backward_exit_pupil_object = s.camera
    attempt("exit pupil at the camera")
    s.hud.backward_exit_pupil_use = False
    bpy.ops.mesh.primitive_plane_add(size=5, location=(0, 50, 0))
    window = bpy.context.object
    window.name = "window"  # no HUD Optical Role
    panel = s.objects["panel"]
    panel.hud.emission_aim, panel.hud.emission_aim_object = "OBJECT", window
    attempt("aim at an object without a role")
    panel.hud.emission_aim = "NONE"
    s.hud.photon_alpha = 0.0
    attempt("photon radius reduction 0")
    s.hud.photon_alpha = 0.5
    s.camera.data.lens = 0.5
    attempt("lens too wide")
    s.camera.data.lens = 50.0
    s.hud.eyebox_folder = str(Path(out) / "eyebox")
    attempt("eyebox without an LCD", lambda folder: bpy.ops.hud.eyebox_sweep())
    mesh = bpy.data.meshes.new("quad")
    mesh.from_pydata([(-5, 60, -5), (5, 60, -5), (5, 60, 5), (-5, 60, 5)], [], [(0, 1, 2, 3)])
    lcd = bpy.data.objects.new("lcd", mesh)
    s.collection.objects.link(lcd)
    lcd.hud.role = "lcd"
    slide = bpy.data.images.new("slide", 8, 8)
    slide.pixels.foreach_set([1.0] * 256)
    slide.pack()
    lcd.hud.image = slide
    attempt("LCD without a UV map")
    disable(module)
    return messages


def test_option_and_reference_errors_are_told_in_the_panels_words(tmp_path):
    """They named a bare "Object", scene.json keys (alpha, "eye", an OBJ's vt lines), no object where the
    object exists but is not exported, the field angle without its value, and command-line flags."""
    res, _ = in_blender(scenario_option_messages, tmp_path)
    expect = {"exit pupil unset": ["Backward options > Exit pupil > Object", "choose an object"],
              "exit pupil at the camera": ["Exit pupil > Object", "is the camera"],
              "aim at an object without a role": ["'panel'", "'window' is an object the render does not see",
                                                  "HUD Optical Role"],
              "photon radius reduction 0": ["Photon options > Radius reduction", "must be > 0"],
              "lens too wide": ["Lens and Sensor", "got 17"],
              "eyebox without an LCD": ["Eyebox Sweep", "set Display field to Given"],
              "LCD without a UV map": ["'lcd'", "add a UV map"]}
    for case, words in expect.items():
        message = res[case] or ""
        assert all(w in message for w in words), (case, message)
        assert "--field" not in message and "vt lines" not in message and '"eye"' not in message, (case, message)
