"""Operators: add a preset, export the scene folder, show sampled light paths."""

from __future__ import annotations

import tempfile
from pathlib import Path

import bpy
import numpy as np
from bpy.props import EnumProperty, IntProperty, StringProperty

from ..presets import PRESETS
from ..tracer.integrators import INTEGRATORS
from ..tracer.scene import load_scene
from .build import build_scene
from .export import M_TO_MM, export_scene


def _preset_items(self, context):
    return [(name, name, mod.SUMMARY) for name, mod in PRESETS.items()]


class HUD_OT_add_preset(bpy.types.Operator):
    """Build one of the tracer's presets in the current scene (from the tracer's own preset code)"""

    bl_idname = "hud.add_preset"
    bl_label = "Add HUD Preset"
    bl_options = {"REGISTER", "UNDO"}

    preset: EnumProperty(name="Preset", items=_preset_items)

    def execute(self, context):
        with tempfile.TemporaryDirectory(prefix="hud-preset-") as tmp:
            folder = PRESETS[self.preset].write(Path(tmp) / self.preset)
            objects = build_scene(folder, context)
        context.scene.render.engine = "HUD_TRACER"
        self.report({"INFO"}, f"{self.preset}: {len(objects)} objects")
        return {"FINISHED"}


class HUD_OT_export_scene(bpy.types.Operator):
    """Write the tracer's scene folder (scene.json, meshes, textures) for this scene"""

    bl_idname = "hud.export_scene"
    bl_label = "Export HUD Scene"

    directory: StringProperty(subtype="DIR_PATH")

    def invoke(self, context, event):
        context.window_manager.fileselect_add(self)
        return {"RUNNING_MODAL"}

    def execute(self, context):
        if not self.directory:
            self.report({"ERROR"}, "choose a folder")
            return {"CANCELLED"}
        try:
            # The tracer's own validation runs on the staged folder: one that would not render never
            # replaces an earlier export.
            folder = export_scene(context.evaluated_depsgraph_get(), Path(bpy.path.abspath(self.directory)),
                                  check=load_scene)
        except Exception as e:  # noqa: BLE001 - any failure is reported to the user; the folder is as it was
            self.report({"ERROR"}, f"HUD export failed: {e}")
            return {"CANCELLED"}
        self.report({"INFO"}, f"HUD scene written to {folder}")
        return {"FINISHED"}


class HUD_OT_show_light_paths(bpy.types.Operator):
    """Add a mesh of sampled light paths from the emitters to the eye (forward tracing)"""

    bl_idname = "hud.show_light_paths"
    bl_label = "Show Light Paths"
    bl_options = {"REGISTER", "UNDO"}

    particles: IntProperty(name="Particles", default=100_000, min=100, max=10_000_000)
    max_paths: IntProperty(name="Paths shown", default=300, min=1, max=100_000)

    def execute(self, context):
        scene = context.scene
        with tempfile.TemporaryDirectory(prefix="hud-paths-") as tmp:
            tracer_scene = load_scene(export_scene(context.evaluated_depsgraph_get(), Path(tmp) / "scene"))
            paths = INTEGRATORS["forward"](tracer_scene, scene.hud.seed).light_paths(self.particles)
        if not paths:
            self.report({"WARNING"}, f"none of {self.particles:,} particles reached the eye pupil")
            return {"CANCELLED"}
        paths = paths[: self.max_paths]
        unit = M_TO_MM * scene.unit_settings.scale_length
        verts = np.concatenate(paths) / unit
        offsets = np.cumsum([0] + [len(p) for p in paths])
        edges = [(i, i + 1) for a, b in zip(offsets[:-1], offsets[1:], strict=True) for i in range(a, b - 1)]
        mesh = bpy.data.meshes.new("HUD light paths")
        mesh.from_pydata(verts.tolist(), edges, [])
        obj = bpy.data.objects.new("HUD light paths", mesh)
        scene.collection.objects.link(obj)
        self.report({"INFO"}, f"{len(paths)} light paths that reach the eye")
        return {"FINISHED"}


CLASSES = (HUD_OT_add_preset, HUD_OT_export_scene, HUD_OT_show_light_paths)

register, unregister = bpy.utils.register_classes_factory(CLASSES)
