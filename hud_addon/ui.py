"""Panels, shown only when the HUD Tracer engine is active."""

import bpy

from ..tracer.integrators import INTEGRATORS
from ..tracer.lights import EMISSION
from ..tracer.optics.materials import MATERIALS
from . import schema_ui

ENGINE = "HUD_TRACER"


class _HudPanel:
    bl_space_type = "PROPERTIES"
    bl_region_type = "WINDOW"
    COMPAT_ENGINES = {ENGINE}

    @classmethod
    def poll(cls, context):
        return context.engine in cls.COMPAT_ENGINES


class HUD_PT_render(_HudPanel, bpy.types.Panel):
    bl_label = "HUD Tracer"
    bl_context = "render"

    def draw(self, context):
        s = context.scene.hud
        col = self.layout.column()
        col.prop(s, "method")
        col.prop(s, "budget")
        col.prop(s, "seconds" if s.budget == "SECONDS" else "rays")
        col.prop(s, "seed")
        if s.method in INTEGRATORS:
            box = col.box()
            box.label(text=f"{s.method.capitalize()} options")
            schema_ui.draw(box, s, INTEGRATORS[s.method].options, f"{s.method}_")
        r = context.scene.render
        col.label(text=f"Retina: {r.resolution_x * r.resolution_percentage // 100} x "
                       f"{r.resolution_y * r.resolution_percentage // 100} px (Output properties)")
        row = col.row()
        row.operator("hud.add_preset")
        row.operator("hud.export_scene")
        col.operator("hud.show_light_paths")


class HUD_PT_object(_HudPanel, bpy.types.Panel):
    bl_label = "HUD Optical Role"
    bl_context = "object"

    @classmethod
    def poll(cls, context):
        return super().poll(context) and context.object is not None and context.object.type == "MESH"

    def draw(self, context):
        h = context.object.hud
        col = self.layout.column()
        col.prop(h, "role")
        if h.role == "none":
            return
        schema = MATERIALS[h.role].schema
        schema_ui.draw(col, h, schema.fields, "", schema.alternatives)
        if schema.can_aim:
            _draw_aim(col, h, "")
            _draw_aim(col, h, "light_")
        col.prop(h, "smooth_normals")
        col.prop(h, "emits")
        if h.emits:
            box = col.box()
            schema_ui.draw(box, h, EMISSION.fields, "emission_", EMISSION.alternatives)
            _draw_aim(box, h, "emission_")


def _draw_aim(col, h, prefix: str):
    col.prop(h, f"{prefix}aim")
    if getattr(h, f"{prefix}aim") != "NONE":
        if getattr(h, f"{prefix}aim") == "OBJECT":
            col.prop(h, f"{prefix}aim_object")
        col.prop(h, f"{prefix}aim_share")
        col.prop(h, f"{prefix}aim_mode")


class HUD_PT_eye(_HudPanel, bpy.types.Panel):
    bl_label = "HUD Eye"
    bl_context = "data"

    @classmethod
    def poll(cls, context):
        return super().poll(context) and context.camera is not None

    def draw(self, context):
        h = context.camera.hud
        col = self.layout.column()
        col.prop(h, "pupil")
        if h.pupil == "FIXED":
            col.prop(h, "pupil_diameter_mm")
        else:
            col.prop(h, "adaptation_luminance")
            col.prop(h, "observer_age")
        col.prop(h, "focal_length_mm")
        col.prop(h, "accommodation_distance_mm")


class HUD_PT_world(_HudPanel, bpy.types.Panel):
    bl_label = "HUD Environment"
    bl_context = "world"

    @classmethod
    def poll(cls, context):
        return super().poll(context) and context.world is not None

    def draw(self, context):
        h = context.world.hud
        col = self.layout.column()
        col.prop(h, "kind")
        if h.kind == "uniform":
            col.prop(h, "luminance")
            col.prop(h, "color")
        elif h.kind == "hdri":
            col.template_ID(h, "image", open="image.open")
            col.prop(h, "calibration")
            col.prop(h, "value")
            col.prop(h, "rotation_deg")


CLASSES = (HUD_PT_render, HUD_PT_object, HUD_PT_eye, HUD_PT_world)

#: Blender's own panels that apply to HUD Tracer renders: resolution, frame range, output and colour
#: management, the camera's lens and display, the mesh's UV maps (an LCD slide needs them). The engine
#: joins their COMPAT_ENGINES on register and leaves on unregister, as Blender's render-engine template
#: and BlendLuxCore do; panels whose settings the tracer does not use (the camera's depth of field: the
#: eye's pupil and accommodation are on the HUD Eye panel) stay hidden.
BUILTIN_PANELS = (
    "RENDER_PT_format", "RENDER_PT_frame_range", "RENDER_PT_output", "RENDER_PT_output_color_management",
    "RENDER_PT_encoding", "RENDER_PT_encoding_video", "RENDER_PT_color_management",
    "RENDER_PT_color_management_curves", "RENDER_PT_color_management_display_settings",
    "RENDER_PT_color_management_white_balance", "DATA_PT_context_camera", "DATA_PT_camera", "DATA_PT_lens",
    "DATA_PT_camera_display", "DATA_PT_camera_safe_areas", "DATA_PT_context_mesh", "DATA_PT_uv_texture",
    "DATA_PT_vertex_groups")


def builtin_panels() -> list:
    """The BUILTIN_PANELS this Blender has (names differ between versions)."""
    return [p for p in (getattr(bpy.types, n, None) for n in BUILTIN_PANELS) if hasattr(p, "COMPAT_ENGINES")]


_register_classes, _unregister_classes = bpy.utils.register_classes_factory(CLASSES)


def register():
    _register_classes()
    for panel in builtin_panels():
        panel.COMPAT_ENGINES.add(ENGINE)


def unregister():
    for panel in builtin_panels():
        panel.COMPAT_ENGINES.discard(ENGINE)
    _unregister_classes()
