"""Panels, shown only when the HUD Tracer engine is active."""

import json
import math
import textwrap

import bpy

from ..tracer.optics.materials import MATERIALS
from ..tracer.products.report import readouts
from ..tracer.scene import ANALYSER
from ..tracer.scene.methods import METHOD_OPTIONS
from ..tracer.sources.lights import EMISSION
from ..tracer.sources.sun import Sun
from . import engine, operators, schema_ui

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
        col.prop(s, "polarisation")
        col.prop(s, "scheduler")
        if s.method in METHOD_OPTIONS:
            box = col.box()
            box.label(text=f"{s.method.capitalize()} options")
            schema_ui.draw(box, s, METHOD_OPTIONS[s.method].fields, f"{s.method}_")
        if s.method == "forward" and not _aimed(context.scene):
            box = col.box()
            for line in ("Forward tracing reaches the eye's pupil only by chance:",
                         "give the emitters (Emission > Aim) or the scattering surfaces",
                         "(Aim) a target: the eye pupil, or the aperture the light leaves by."):
                box.label(text=line, icon="INFO" if line.startswith("Forward") else "BLANK1")
        r = context.scene.render
        col.label(text=f"Retina: {r.resolution_x * r.resolution_percentage // 100} x "
                       f"{r.resolution_y * r.resolution_percentage // 100} px (Output > Format)")
        row = col.row(align=True)  # Blender's own setting, which its Performance panel shows for Cycles only
        row.prop(r, "threads_mode", text="Processes")
        sub = row.row(align=True)
        sub.enabled = r.threads_mode == "FIXED"
        sub.prop(r, "threads", text="")
        row = col.row()
        row.operator("hud.add_preset")
        row.operator("hud.add_windshield")
        row.operator("hud.add_lamp")
        row.operator("hud.export_scene")
        col.operator("hud.show_light_paths")


def _aimed(scene) -> bool:
    """Whether any object of the scene aims its emission or its scattering (the forward method's
    directed sampling, paper sec. 2)."""
    return any(o.hud.role != "none" and (o.hud.aim != "NONE" or (o.hud.emits and o.hud.emission_aim != "NONE"))
               for o in scene.objects)


class HUD_PT_readouts(_HudPanel, bpy.types.Panel):
    """What an HUD engineer reads off the last render (its report) and the last eyebox sweep."""

    bl_label = "HUD Readouts"
    bl_context = "render"

    def draw(self, context):
        scene = context.scene
        col = self.layout.column()
        report = engine.REPORTS.get(scene.name)
        if report is None and scene.name in engine.REFUSED:
            col.label(text="Blender refused the last render (its message says why): no figures", icon="ERROR")
        elif report is None:
            col.label(text="Render (F12) to see the figures of the image")
        else:
            grid = col.grid_flow(row_major=True, columns=2, even_columns=False)
            for label, text in readouts(report):
                grid.label(text=label)
                grid.label(text=text)
            if report.get("analysis") == "pending":
                col.label(text="The HUD figures follow the image (analysis running)", icon="TIME")
            for w in report["warnings"]:
                _wrapped(col, w, "ERROR")
            col.operator("hud.show_false_colour", icon="IMAGE")
        box = col.box()
        box.label(text="Eyebox")
        s = scene.hud
        for name in ("eyebox_half_width_mm_shown", "eyebox_half_height_mm_shown", "eyebox_step_mm_shown",
                     "eyebox_threshold", "eyebox_field", "eyebox_photons"):
            box.prop(s, name)
        if s.eyebox_field == "GIVEN":
            box.prop(s, "eyebox_field_deg_shown")
        box.prop(s, "eyebox_folder")
        box.operator("hud.eyebox_sweep", icon="PIVOT_BOUNDBOX")
        sweep = operators.EYEBOX.get(scene.name)
        if sweep is not None:
            summary = sweep["summary"]
            f = summary["figures"]
            if f is None:
                for reason in summary["reasons"]:
                    _wrapped(box, f"not valid: {reason}", "ERROR")
                return
            box.label(text=f"Eyebox {f['width_mm']:.1f} x {f['height_mm']:.1f} mm"
                           + (" (reaches the scan's edge: widen it)" if f["reaches_scan_edge"] else ""))
            avg = f["field_average_cd_m2"]
            box.label(text=f"Display average {avg['min']:,.4g} to {avg['max']:,.4g} cd/m² (design eye "
                           f"{avg['design_eye']:,.4g})")
            box.label(text=f"Uniformity {f['uniformity']['design_eye']:.2f} at the design eye, "
                           f"{f['uniformity']['eyebox']:.2f} over the eyebox")
            box.label(text=f"Written to {sweep['folder']} (chart: image eyebox.png)")


#: Characters per line of the panels' longer texts (warnings, reasons), wrapped rather than cut: a cut line
#: lost its advice ("... so their Y_var reads 0 and the").
WRAP = 90


def _wrapped(layout, text: str, icon: str):
    """``text`` as labels of at most :data:`WRAP` characters, the first with ``icon``, the others indented
    as far."""
    for k, line in enumerate(textwrap.wrap(text, WRAP) or [""]):
        layout.label(text=line, icon=icon if k == 0 else ("BLANK1" if icon != "NONE" else "NONE"))


def _surface_kinds(text: str) -> str:
    """The shapes of an object's Exact surfaces (its JSON text), or what is wrong with the text."""
    try:
        blocks = json.loads(text)
    except json.JSONDecodeError:
        return "not valid JSON (the export says where)"
    if not isinstance(blocks, list) or not all(isinstance(b, dict) for b in blocks):
        return "not a list of surface blocks"
    return ", ".join(str(b.get("type", "?")) for b in blocks)


class HUD_PT_optics(_HudPanel, bpy.types.Panel):
    """The optical analysis: where the image is and how good it is (docs/user/optics.md)."""

    bl_label = "HUD Optics"
    bl_context = "render"

    def draw(self, context):
        scene = context.scene
        s = scene.hud
        col = self.layout.column()
        for name in ("optics_eyebox_mm_shown", "optics_ipd_mm_shown", "optics_field_grid", "optics_eye_grid",
                     "optics_folder"):
            col.prop(s, name)
        if s.optics_target:
            _wrapped(col, f"Target: {s.optics_target}", "NONE")
        col.operator("hud.optical_analysis", icon="MOD_UVPROJECT")
        result = operators.OPTICS.get(scene.name)
        if result is None:
            return
        grid = col.grid_flow(row_major=True, columns=2, even_columns=False)
        for label, text in result["rows"]:
            grid.label(text=label)
            grid.label(text=text[:120], icon="NONE" if "NOT met" not in text else "ERROR")
        col.label(text=f"Written to {result['folder']} (images optics-distortion.png, optics-eyebox.png, "
                       "optics-vid.png)")


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
        if h.surfaces:
            col.label(text=f"Exact surfaces: {_surface_kinds(h.surfaces)}", icon="SPHERECURVE")
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
            col.prop(h, "pupil_diameter_mm_shown")
        else:
            if h.pupil == "AUTO":
                col.prop(h, "adaptation_luminance", text="Adaptation (cd/m²)")
            col.prop(h, "observer_age", text="Age (years)")
        col.prop(h, "adaptation")
        col.prop(h, "focal_length_mm_shown")
        col.prop(h, "accommodation_distance_mm_shown")
        schema_ui.draw(col, h, (ANALYSER,))  # analyser_use, and its fields in a box when on
        if h.analyser_use and context.scene.hud.polarisation == "off":
            col.label(text="An analyser needs Render > HUD Tracer > Polarisation: Auto", icon="ERROR")


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
            col.prop(h, "luminance", text="Luminance (cd/m²)")
            col.prop(h, "color")
        elif h.kind == "hdri":
            col.template_ID(h, "image", open="image.open")
            col.prop(h, "calibration")
            col.prop(h, "value", text="Factor" if h.calibration == "scale" else "Luminance (cd/m²)")
            col.prop(h, "rotation_deg_shown")


class HUD_PT_sun(_HudPanel, bpy.types.Panel):
    """A Sun light is the environment's sun (hud_addon.export.sun_spec); other lights are not exported."""

    bl_label = "HUD Sun"
    bl_context = "data"

    @classmethod
    def poll(cls, context):
        return super().poll(context) and getattr(context, "light", None) is not None

    def draw(self, context):
        light = context.light
        col = self.layout.column()
        if light.type != "SUN":
            col.label(text="HUD Tracer exports Sun lights only, as the environment's sun;", icon="INFO")
            col.label(text="a lamp is a mesh that emits: Render Properties > HUD Tracer > Add Lamp, or give a mesh",
                      icon="BLANK1")
            col.label(text="an Optical Role (Object > HUD Optical Role) and tick its Emits light", icon="BLANK1")
            return
        col.prop(light.hud, "illuminance_lux", text="Illuminance (lx)")
        col.prop(light, "angle", text="Angular diameter")
        col.prop(light, "color")
        try:
            sun = Sun((0.0, 0.0, 1.0), light.hud.illuminance_lux, math.degrees(light.angle))
            col.label(text=f"Disk luminance {sun.luminance_cd_m2:.3g} cd/m²")
        except ValueError as e:
            col.label(text=str(e), icon="ERROR")
        col.label(text="Toward the sun: the light's +Z (it shines along -Z)")


CLASSES = (HUD_PT_render, HUD_PT_readouts, HUD_PT_optics, HUD_PT_object, HUD_PT_eye, HUD_PT_world, HUD_PT_sun)

#: Blender's own panels that apply to HUD Tracer renders: resolution, frame range, output and colour
#: management, the camera's lens and display, the mesh's UV maps (an LCD slide needs them) and Metadata
#: (the EXR's header, with the hud:* fields). The engine
#: joins their COMPAT_ENGINES on register and leaves on unregister, as Blender's render-engine template
#: and BlendLuxCore do; panels whose settings the tracer does not use (the camera's depth of field: the
#: eye's pupil and accommodation are on the HUD Eye panel) stay hidden.
BUILTIN_PANELS = (
    "RENDER_PT_format", "RENDER_PT_frame_range", "RENDER_PT_output", "RENDER_PT_output_color_management",
    "RENDER_PT_encoding", "RENDER_PT_encoding_video", "RENDER_PT_color_management",
    "RENDER_PT_color_management_curves", "RENDER_PT_color_management_display_settings",
    "RENDER_PT_color_management_white_balance", "DATA_PT_context_camera", "DATA_PT_camera", "DATA_PT_lens",
    "DATA_PT_camera_display", "DATA_PT_camera_safe_areas", "DATA_PT_context_mesh", "DATA_PT_uv_texture",
    "DATA_PT_vertex_groups", "RENDER_PT_stamp", "RENDER_PT_stamp_note", "RENDER_PT_stamp_burn",
    # Object > Visibility (Disable in Renders), the light's type (the HUD Sun panel asks for a Sun), the
    # World selector (a scene without a World gets one there): hidden for an engine that does not join them
    "OBJECT_PT_visibility", "DATA_PT_context_light", "WORLD_PT_context_world")


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
