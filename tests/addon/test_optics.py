"""The optical analysis in Blender (HUD Optics panel, hud.optical_analysis): on a preset the command
line's figures, the mirror's exact surface carried through the export; on a scene built by hand (a
camera, a plane mirror and a lit panel) the closed form's VID; the pictures opened as images."""

import json
import math
import sys
import tempfile
from pathlib import Path

import numpy as np
import pytest

from tests.support.addon import in_blender, needs_bpy
from tests.support.cli import run_cli

pytestmark = [needs_bpy, pytest.mark.slow]


def scenario_optics(out):
    import bpy

    from tests.support.blender import Layout, disable, enable_from_source

    module = enable_from_source(bpy, Path(tempfile.mkdtemp()))
    pkg = f"{module}.hud_addon"
    operators, ui = sys.modules[f"{pkg}.operators"], sys.modules[f"{pkg}.ui"]
    scene = bpy.context.scene
    res = {}

    bpy.ops.hud.add_preset(preset="hud-direct")
    mirror_surfaces = json.loads(bpy.data.objects["mirror"].hud.surfaces)
    scene.hud.optics_folder = str(Path(out) / "preset")
    bpy.ops.hud.optical_analysis()
    labels = []

    class Panel:
        layout = Layout(labels)

    ui.HUD_PT_optics.draw(Panel(), bpy.context)
    result = operators.OPTICS[scene.name]
    res["preset"] = {"summary": result["summary"], "rows": result["rows"], "labels": labels,
                     "surfaces": mirror_surfaces, "target": scene.hud.optics_target,
                     "images": sorted(i.name for i in bpy.data.images if i.name.startswith("optics-"))}

    bpy.ops.wm.read_homefile(use_empty=True)
    scene = bpy.context.scene
    scene.unit_settings.scale_length = 1.0  # metres
    bpy.ops.object.camera_add(location=(0.0, 0.0, 0.0), rotation=(math.pi / 2, 0.0, 0.0))  # looks along +y
    scene.camera = bpy.context.object
    bpy.ops.mesh.primitive_plane_add(size=0.4, location=(0.0, 0.4, 0.0), rotation=(math.pi / 4, 0.0, 0.0))
    mirror = bpy.context.object
    mirror.name, mirror.hud.role = "mirror", "mirror"
    bpy.ops.mesh.primitive_plane_add(size=0.06, location=(0.0, 0.4, 0.6), rotation=(math.pi, 0.0, 0.0))
    panel = bpy.context.object
    panel.name, panel.hud.role, panel.hud.emits, panel.hud.emission_luminance = "panel", "absorber", True, 1000.0
    scene.hud.optics_folder = str(Path(out) / "by-hand")
    scene.hud.optics_eye_grid = (3, 3)
    bpy.ops.hud.optical_analysis()
    result = operators.OPTICS[scene.name]
    res["by_hand"] = {"summary": result["summary"], "rows": result["rows"]}
    # a mistyped requirement in the Target text: refused in the panel's words, nothing written
    scene.hud.optics_target = json.dumps({"requirements": ["design_eye.vid < 1001"]})
    scene.hud.optics_folder = str(Path(out) / "refused")
    try:
        bpy.ops.hud.optical_analysis()
        res["refused"] = None
    except RuntimeError as e:
        res["refused"] = str(e)
    scene.hud.optics_target = ""
    # a windshield made from parameters, beside the rest, exported with its two exact surfaces
    scene.cursor.location = (0.0, 1.5, 0.0)
    bpy.ops.hud.add_windshield(size_mm=(600.0, 400.0), wedge_mrad=0.3, radius_x_mm=4000.0)
    bpy.ops.hud.export_scene(directory=str(Path(out) / "windshield"))
    disable(module)
    return res


@pytest.fixture(scope="module")
def optics_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("optics")
    res, proc = in_blender(scenario_optics, out)
    assert "Traceback" not in proc.stdout + proc.stderr
    return res, out


def test_the_panel_runs_the_analysis_of_a_preset_as_the_command_line_does(optics_run, tmp_path):
    res, out = optics_run
    preset = res["preset"]
    code, err = run_cli("optics", "hud-direct", "--out", str(tmp_path / "cli"))
    assert code == 0, err
    cli = json.loads((tmp_path / "cli" / "optics.json").read_text())
    # the same within what Blender's float32 vertices move the LCD and the windshield (about 1e-4 mm)
    blender, line = preset["summary"]["design_eye"], cli["summary"]["design_eye"]
    assert blender["vid_mm"] == pytest.approx(line["vid_mm"], rel=1e-3)
    assert blender["fov_h_deg"] == pytest.approx(line["fov_h_deg"], rel=1e-4)
    for key in ("static_distortion_mrad", "ghost_separation_centre_arcmin"):
        assert blender[key] == pytest.approx(line[key], abs=0.01)
    assert preset["summary"]["eyebox"]["dipvergence_mrad"] == pytest.approx(
        cli["summary"]["eyebox"]["dipvergence_mrad"], abs=0.01)
    # the mirror's exact ellipsoid went through Blender and back; the target's eyebox with it
    assert [s["type"] for s in preset["surfaces"]] == ["conic"]
    written = json.loads((out / "preset" / "optics.json").read_text())
    assert written["exact_surfaces"] == ["mirror"] and "mesh_comparison" in written
    assert written["target"]["eyebox_mm"] == [120.0, 40.0]
    assert json.loads(preset["target"])["distance_mm"] == 2500.0
    # the panel shows every row, and the three pictures are Blender images
    assert len(preset["labels"]) >= 2 * len(preset["rows"])
    assert preset["images"] == ["optics-distortion.png", "optics-eyebox.png", "optics-vid.png"]
    for name in preset["images"]:
        assert (out / "preset" / name).stat().st_size > 10_000


def test_add_windshield_exports_a_closed_shell_on_its_exact_surfaces(optics_run):
    """Add Windshield (600 x 400 mm, 0.3 mrad wedge, radius 4 m across) at the 3D cursor: the loader finds
    its faces on its inner biconic and its turned outer one, and the glass 0.3 mrad thicker per metre up."""
    from tracer.scene import load_scene

    _, out = optics_run
    glass = load_scene(out / "windshield").object("windshield")
    inner, outer = glass.surfaces
    assert (inner.type, outer.type) == ("biconic", "biconic")
    assert inner.params["radius_x_mm"] == 4000.0 and outer.params["radius_x_mm"] == pytest.approx(4004.76)
    assert len(inner.faces) > 100 and inner.gap_mm.max() < 0.02 and outer.gap_mm.max() < 0.02
    axes = [np.linalg.inv(s.to_local)[:3, 2] for s in (inner, outer)]
    axes = [a / np.linalg.norm(a) for a in axes]
    assert math.acos(min(1.0, float(axes[0] @ axes[1]))) == pytest.approx(0.3e-3, rel=1e-3)
    assert glass.vertices[:, 1].mean() == pytest.approx(1500.0, abs=1.0)  # at the cursor, 1.5 m along y


def test_the_panel_analyses_a_scene_built_by_hand(optics_run):
    """A camera 400 mm from a plane mirror folding the view up onto a panel 600 mm above it: VID 1000 mm."""
    res, out = optics_run
    s = res["by_hand"]["summary"]["design_eye"]
    assert s["vid_mm"] == pytest.approx(1000.0, rel=1e-3)
    assert s["static_distortion_mrad"] < 0.01
    assert res["by_hand"]["summary"]["eyebox"]["dipvergence_mrad"] < 0.01
    assert (out / "by-hand" / "optics.csv").is_file()
    message = res["refused"]
    assert "Optical Analysis" in message and "HUD Optics > Target (requirements)" in message, message
    assert "vid_mm" in message and "scene.json" not in message
    assert not (out / "refused" / "optics.json").exists()
