"""Operators: add a preset, export the scene folder, show sampled light paths, show the last render's
false-colour view, sweep the eyebox, run the optical analysis."""

from __future__ import annotations

import contextlib
import json
import tempfile
from pathlib import Path

import bpy
import numpy as np
from bpy.props import BoolProperty, EnumProperty, FloatProperty, FloatVectorProperty, IntProperty, StringProperty

from ..presets import PRESETS
from ..tracer.analysis.optics import OpticsError, analyse
from ..tracer.core.errors import SceneError, TracerError
from ..tracer.core.validate import MAX_LUMINANCE
from ..tracer.methods import INTEGRATORS
from ..tracer.products.optics import OUTPUT_NAMES as OPTICS_FILES
from ..tracer.products.optics import output_files as optics_files
from ..tracer.products.optics import readouts as optics_readouts
from ..tracer.products.outputs import OutputSet
from ..tracer.scans.eyebox import OUTPUT_NAMES as EYEBOX_FILES
from ..tracer.scans.eyebox import FieldNotFound, ScanArgumentError, eyebox_scan
from ..tracer.scans.eyebox import output_files as eyebox_files
from ..tracer.scene import load_scene
from ..tracer.scene.windshield import radius_problem, windshield_mesh
from ..tracer.transport.sequential import ChainError
from ..tracer.transport.world import World
from . import engine
from .build import build_scene
from .export import export_scene
from .messages import blender_terms
from .units import unit_mm

#: The last eyebox sweep of each scene by name: its summary (tracer.scans.eyebox.EyeboxResult.summary), the
#: grid of offsets inside the eyebox and the folder it was written to; the HUD Readouts panel shows it.
EYEBOX: dict[str, dict] = {}
#: The last optical analysis of each scene by name: its readouts (tracer.products.optics.readouts), its
#: summary and the folder it was written to; the HUD Optics panel shows it.
OPTICS: dict[str, dict] = {}
#: The pictures of the optical analysis, the first shown in the Image Editor.
OPTICS_PICTURES = ("optics-distortion.png", "optics-eyebox.png", "optics-vid.png")


def _preset_items(self, context):
    return [(name, name, mod.SUMMARY) for name, mod in PRESETS.items()]


class HUD_OT_add_preset(bpy.types.Operator):
    """Build one of the tracer's presets in the current scene (from the tracer's own preset code)"""

    bl_idname = "hud.add_preset"
    bl_label = "Add HUD Preset"
    bl_options = {"REGISTER", "UNDO"}

    preset: EnumProperty(name="Preset", items=_preset_items)
    replace: BoolProperty(name="Replace", default=True,
                          description="Remove what an earlier Add HUD Preset built in this scene (and Blender's "
                                      "startup cube) first")

    def execute(self, context):
        with tempfile.TemporaryDirectory(prefix="hud-preset-") as tmp:
            folder = PRESETS[self.preset].write(Path(tmp) / self.preset)
            objects, replaced = build_scene(folder, context, self.replace)
        context.scene.render.engine = "HUD_TRACER"
        mm = unit_mm(context.scene)
        units = "1 unit = 1 mm" if abs(mm - 1.0) < 1e-6 else f"1 unit = {mm:g} mm"
        note = f", replacing {', '.join(replaced)}" if replaced else ""
        self.report({"INFO"}, f"{self.preset}: {len(objects)} objects in collection HUD {self.preset} ({units}){note}")
        return {"FINISHED"}


def unsaved_relative(folder: str, what: str) -> str | None:
    """The message for a folder relative to the .blend ("//") while the .blend is not saved (Blender would
    resolve it against the working directory, wherever that is), or None."""
    if folder.startswith("//") and not bpy.data.filepath:
        return f"{what}: the folder is relative to the .blend, which is not saved: save it or choose an absolute folder"
    return None


class HUD_OT_add_windshield(bpy.types.Operator):
    """Add a windshield made from its parameters at the 3D cursor: a closed glass shell (flat, wedged or
    curved) with its two exact surfaces, its inner surface facing the object's +Z (turn it toward the
    driver), the glass behind it (scene.json objects[].windshield; docs/user/optics.md)"""

    bl_idname = "hud.add_windshield"
    bl_label = "Add Windshield"
    bl_options = {"REGISTER", "UNDO"}

    size_mm: FloatVectorProperty(name="Size (mm)", size=2, default=(1400.0, 800.0), min=1.0, max=5000.0,
                                 description="Width (x) and height (y) of the inner surface's outline, mm")
    thickness_mm: FloatProperty(name="Thickness (mm)", default=4.76, min=0.01, max=100.0,
                                description="Thickness of the glass at the object's origin, mm")
    wedge_mrad: FloatProperty(name="Wedge (mrad)", default=0.0, min=-50.0, max=50.0,
                              description="Angle between the outer and the inner surface, mrad (a few tenths fuse "
                                          "a HUD's ghost)")
    wedge_direction_deg: FloatProperty(name="Wedge direction (deg)", default=90.0, min=-360.0, max=360.0,
                                       description="Direction the glass thickens in, degrees from +X toward +Y "
                                                   "(90: toward the top)")
    radius_x_mm: FloatProperty(name="Radius across (mm)", default=0.0, min=-1e7, max=1e7,
                               description="Inner radius in the X-Z section, mm, positive concave toward +Z "
                                           "(the driver); 0 flat")
    radius_y_mm: FloatProperty(name="Radius up (mm)", default=0.0, min=-1e7, max=1e7,
                               description="Inner radius in the Y-Z section, mm; 0 flat")
    ior: FloatProperty(name="IOR", default=1.52, min=1.0, max=4.0, description="The glass's refractive index")

    def execute(self, context):
        p = {"size_mm": list(self.size_mm), "thickness_mm": self.thickness_mm, "depth_mm": 0.0,
             "wedge_mrad": self.wedge_mrad, "wedge_direction_deg": self.wedge_direction_deg,
             "radius_x_mm": self.radius_x_mm, "radius_y_mm": self.radius_y_mm, "cells": None}
        if (bad := radius_problem(p)) is not None:
            self.report({"ERROR"}, f"Add Windshield: {bad[0]}: {bad[1]}")
            return {"CANCELLED"}
        try:
            v, f, surfaces = windshield_mesh(p)
        except ValueError as e:
            self.report({"ERROR"}, f"Add Windshield: {e}")
            return {"CANCELLED"}
        mm = unit_mm(context.scene)
        mesh = bpy.data.meshes.new("windshield")
        mesh.from_pydata((v / mm).tolist(), [], f.tolist())
        mesh.update()
        obj = bpy.data.objects.new("windshield", mesh)
        obj.location = context.scene.cursor.location
        context.collection.objects.link(obj)
        obj.hud.role, obj.hud.ior = "dielectric", self.ior
        obj.hud.surfaces = json.dumps(surfaces)
        for o in context.selected_objects:
            o.select_set(False)
        obj.select_set(True)
        context.view_layer.objects.active = obj
        self.report({"INFO"}, f"windshield: {len(f)} triangles, {len(surfaces)} exact surfaces")
        return {"FINISHED"}


class HUD_OT_add_lamp(bpy.types.Operator):
    """Add a lamp at the 3D cursor: a flat rectangle that emits as a Lambertian source toward its +Z
    (the optical role Absorber with Emits light: black where light falls on it)"""

    bl_idname = "hud.add_lamp"
    bl_label = "Add Lamp"
    bl_options = {"REGISTER", "UNDO"}

    size_mm: FloatVectorProperty(name="Size (mm)", size=2, default=(100.0, 100.0), min=0.001, max=1e6,
                                 description="Width (x) and height (y) of the emitting rectangle, mm")
    luminance: FloatProperty(name="Luminance (cd/m²)", default=1000.0, min=0.0, max=MAX_LUMINANCE,
                             description="Luminance of its face, cd/m^2 (an LED backlight: 1e5 to 1e7)")
    two_sided: BoolProperty(name="Two-sided", default=False, description="Emit from both faces")

    def execute(self, context):
        w, h = (v / unit_mm(context.scene) / 2.0 for v in self.size_mm)
        mesh = bpy.data.meshes.new("lamp")
        mesh.from_pydata([(-w, -h, 0.0), (w, -h, 0.0), (w, h, 0.0), (-w, h, 0.0)], [], [(0, 1, 2, 3)])
        mesh.update()
        obj = bpy.data.objects.new("lamp", mesh)
        obj.location = context.scene.cursor.location
        context.collection.objects.link(obj)
        hud = obj.hud
        hud.role, hud.emits = "absorber", True
        hud.emission_by, hud.emission_luminance = "luminance", self.luminance
        hud.emission_two_sided = self.two_sided
        for o in context.selected_objects:
            o.select_set(False)
        obj.select_set(True)
        context.view_layer.objects.active = obj
        self.report({"INFO"}, f"{obj.name}: {self.size_mm[0]:g} x {self.size_mm[1]:g} mm at {self.luminance:g} cd/m², "
                              f"emitting toward its {'+Z and -Z' if self.two_sided else '+Z'}")
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
        if (message := unsaved_relative(self.directory, "HUD export")) is not None:
            self.report({"ERROR"}, message)
            return {"CANCELLED"}
        scene = context.scene

        def check(staged: Path):
            # The tracer's own validation runs on the staged folder: one that would not render never
            # replaces an earlier export. Its errors are told in Blender's terms (the object or setting,
            # not the staged scene.json's path and JSON field).
            try:
                load_scene(staged)
            except SceneError as e:
                raise ValueError(blender_terms(e, staged, scene)) from None

        try:
            folder = export_scene(context.evaluated_depsgraph_get(), Path(bpy.path.abspath(self.directory)),
                                  check=check)
        except Exception as e:  # noqa: BLE001 - any failure is reported to the user; the folder is as it was
            self.report({"ERROR"}, f"HUD export failed: {e}")
            return {"CANCELLED"}
        self.report({"INFO"}, f"HUD scene written to {folder}")
        return {"FINISHED"}


#: The name of the mesh Show Light Paths makes, and the custom property that marks its object.
LIGHT_PATHS, LIGHT_PATHS_TAG = "HUD light paths", "hud_light_paths"


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
            folder = Path(tmp) / "scene"
            try:  # as Export and F12 report it: the object or setting at fault, not the staged scene.json
                tracer_scene = load_scene(export_scene(context.evaluated_depsgraph_get(), folder))
                forward = INTEGRATORS["forward"](tracer_scene, scene.hud.seed)
                paths = forward.light_paths(self.particles)
                hint = "" if paths else forward.no_paths_hint()
            except SceneError as e:
                self.report({"ERROR"}, f"Show Light Paths: {blender_terms(e, folder, scene)}")
                return {"CANCELLED"}
            except (ValueError, TracerError, OSError) as e:
                self.report({"ERROR"}, f"Show Light Paths: {e}")
                return {"CANCELLED"}
        if not paths:
            self.report({"WARNING"}, f"Show Light Paths: none of {self.particles:,} particles reached the eye pupil"
                                     + (f": {hint}" if hint else ""))
            return {"CANCELLED"}
        paths = paths[: self.max_paths]
        verts = np.concatenate(paths) / unit_mm(scene)
        offsets = np.cumsum([0] + [len(p) for p in paths])
        edges = [(i, i + 1) for a, b in zip(offsets[:-1], offsets[1:], strict=True) for i in range(a, b - 1)]
        mesh = bpy.data.meshes.new(LIGHT_PATHS)
        mesh.from_pydata(verts.tolist(), edges, [])
        obj = next((o for o in scene.objects if o.get(LIGHT_PATHS_TAG)), None)
        if obj is None or obj.type != "MESH":  # pressed again: the earlier paths are replaced, not kept beside
            obj = bpy.data.objects.new(LIGHT_PATHS, mesh)
            obj[LIGHT_PATHS_TAG] = True
            scene.collection.objects.link(obj)
        else:
            old, obj.data = obj.data, mesh
            if old.users == 0:
                bpy.data.meshes.remove(old)
                mesh.name = LIGHT_PATHS  # it had come as "HUD light paths.001" beside the old one
        self.report({"INFO"}, f"{len(paths)} light paths that reach the eye")
        return {"FINISHED"}


def show_image(context, name: str, rgb: np.ndarray):
    """Put an sRGB uint8 image (H, W, 3) into the image datablock ``name`` (made or resized) and show it
    in the first Image Editor of the screen, if there is one. Returns the image."""
    h, w = rgb.shape[:2]
    image = bpy.data.images.get(name)
    if image is None or tuple(image.size) != (w, h):
        if image is not None:
            bpy.data.images.remove(image)
        image = bpy.data.images.new(name, w, h, alpha=False)
    rgba = np.concatenate([rgb[::-1].astype(np.float32) / 255.0, np.ones((h, w, 1), np.float32)], axis=2)
    image.pixels.foreach_set(rgba.ravel())
    image.update()
    _in_image_editor(context, image)
    return image


def _in_image_editor(context, image):
    """Show ``image`` in the first Image Editor of the screen, if there is one (none in background mode)."""
    screen = getattr(context, "screen", None)
    for area in (screen.areas if screen is not None else []):
        if area.type == "IMAGE_EDITOR":
            area.spaces.active.image = image
            break


@contextlib.contextmanager
def _exported(context, prefix: str):
    """The scene as Export HUD Scene writes it, loaded (tracer.scene.Scene) from a temporary folder that
    lasts the body's time; a SceneError, the loader's or the body's (the analyses read fields too), comes
    out as a ValueError in Blender's terms (the object or panel and the property)."""
    with tempfile.TemporaryDirectory(prefix=prefix) as tmp:
        folder = export_scene(context.evaluated_depsgraph_get(), Path(tmp) / "scene")
        try:
            yield load_scene(folder)
        except SceneError as e:
            raise ValueError(blender_terms(e, folder, context.scene)) from None


class HUD_OT_show_false_colour(bpy.types.Operator):
    """Show the last render's luminance in false colour (logarithmic, cd/m² with a legend) as the image
    "HUD False Colour"; renders written to a file also get it beside them (<file>.falsecolour.png)"""

    bl_idname = "hud.show_false_colour"
    bl_label = "Show False Colour"

    @classmethod
    def poll(cls, context):
        return context.scene.name in engine.FALSE_COLOUR or context.scene.name in engine.ANALYSES

    def execute(self, context):
        engine.finish_analysis(context.scene.name)  # the view is made after the image, with the analysis
        if context.scene.name not in engine.FALSE_COLOUR:
            self.report({"ERROR"}, "Show False Colour: no render of this scene to show")
            return {"CANCELLED"}
        rgb, info = engine.FALSE_COLOUR[context.scene.name]
        show_image(context, "HUD False Colour", rgb)
        self.report({"INFO"}, f"HUD False Colour: {info['lo']:.3g} to {info['hi']:.3g} cd/m² ({info['decades']} "
                              "decades, logarithmic)")
        return {"FINISHED"}


class HUD_OT_eyebox_sweep(bpy.types.Operator):
    """Sweep the eye over a grid of positions around the camera and find the eyebox: where every point of
    the display (its centre and corners, every LCD cell clear) keeps the threshold share of its luminance
    at the camera (brightness-theorem analysis; a photon map where a screen is lit through optics). Writes
    eyebox.csv, eyebox.png and eyebox.json"""

    bl_idname = "hud.eyebox_sweep"
    bl_label = "Eyebox Sweep"

    def execute(self, context):
        scene = context.scene
        s = scene.hud
        folder = Path(bpy.path.abspath(s.eyebox_folder))
        if (message := unsaved_relative(s.eyebox_folder, "Eyebox Sweep")) is not None:
            self.report({"ERROR"}, message)
            return {"CANCELLED"}
        half = (s.eyebox_half_width_mm, s.eyebox_half_height_mm)
        field = None if s.eyebox_field == "AUTO" else tuple(s.eyebox_field_deg)
        wm = context.window_manager
        wm.progress_begin(0.0, 1.0)
        try:
            with _exported(context, "hud-eyebox-") as loaded:
                world = World(loaded)
                outputs = OutputSet(folder, EYEBOX_FILES).open()  # checked and locked before the sweep
                try:
                    result = eyebox_scan(world, half, s.eyebox_step_mm, field, s.eyebox_threshold,
                                         progress=lambda f, _m: wm.progress_update(f), photons=s.eyebox_photons,
                                         seed=s.seed)
                    outputs.commit(eyebox_files(result))
                    outputs.keep()
                finally:
                    outputs.close()
        except FieldNotFound as e:  # the command line's words for giving it, in the panel's
            self.report({"ERROR"}, "Eyebox Sweep: " + str(e).replace(
                "give it (field_deg, --field FX FY)",
                "set Display field to Given and give its Field (full width and height)"))
            return {"CANCELLED"}
        except (ScanArgumentError, TracerError, ValueError, OSError) as e:
            self.report({"ERROR"}, f"Eyebox Sweep: {e}")
            return {"CANCELLED"}
        finally:
            wm.progress_end()
        summary = result.summary()
        EYEBOX[scene.name] = {"summary": summary, "region": result.region.tolist(), "folder": str(folder),
                              "right_mm": result.right_mm.tolist(), "up_mm": result.up_mm.tolist()}
        chart = bpy.data.images.load(str(folder / "eyebox.png"), check_existing=True)
        chart.reload()
        f = summary["figures"]
        if not result.valid:
            reasons = "; ".join(result.reasons).replace("--photons", "Photons")  # the panel's word for it
            self.report({"WARNING"}, f"Eyebox Sweep: not valid: {reasons}")
        else:
            self.report({"INFO"}, f"eyebox {f['width_mm']:.1f} x {f['height_mm']:.1f} mm, uniformity "
                                  f"{f['uniformity']['eyebox']:.2f}; written to {folder}")
        return {"FINISHED"}


class HUD_OT_optical_analysis(bpy.types.Operator):
    """Trace the optical analysis of the scene as it would be exported: virtual image distance, distortion,
    ghost separation and binocular disparity from the camera (the design eye point) and over the eyebox,
    through the specular chain from the camera to the LCD. Writes optics.json, optics.csv and three
    pictures, and opens the distortion grid in the Image Editor"""

    bl_idname = "hud.optical_analysis"
    bl_label = "Optical Analysis"

    def execute(self, context):
        scene = context.scene
        s = scene.hud
        folder = Path(bpy.path.abspath(s.optics_folder))
        if (message := unsaved_relative(s.optics_folder, "Optical Analysis")) is not None:
            self.report({"ERROR"}, message)
            return {"CANCELLED"}
        OPTICS.pop(scene.name, None)
        try:
            with _exported(context, "hud-optics-") as loaded:
                outputs = OutputSet(folder, OPTICS_FILES).open()  # checked and locked before the first ray
                try:
                    doc = analyse(loaded)
                    outputs.commit(optics_files(doc))
                    outputs.keep()
                finally:
                    outputs.close()
        except (OpticsError, ChainError) as e:
            self.report({"ERROR"}, f"Optical Analysis: {e}".replace("aim the eye", "aim the camera"))
            return {"CANCELLED"}
        except (TracerError, ValueError, OSError) as e:
            self.report({"ERROR"}, f"Optical Analysis: {e}")
            return {"CANCELLED"}
        OPTICS[scene.name] = {"rows": optics_readouts(doc), "summary": doc["summary"], "folder": str(folder),
                              "requirements_met": doc["requirements_met"]}
        images = []
        for name in OPTICS_PICTURES:
            image = bpy.data.images.load(str(folder / name), check_existing=True)
            image.reload()
            images.append(image)
        _in_image_editor(context, images[0])
        d = doc["summary"]["design_eye"]
        self.report({"INFO"} if doc["requirements_met"] else {"WARNING"},
                    f"VID {d['vid_mm']:.0f} mm, ghost {d.get('ghost_separation_centre_arcmin') or 0:.2f} arcmin"
                    + ("" if doc["requirements_met"] else "; a requirement is not met") + f"; written to {folder}")
        return {"FINISHED"}


CLASSES = (HUD_OT_add_preset, HUD_OT_add_windshield, HUD_OT_add_lamp, HUD_OT_export_scene, HUD_OT_show_light_paths,
           HUD_OT_show_false_colour, HUD_OT_eyebox_sweep, HUD_OT_optical_analysis)

register, unregister = bpy.utils.register_classes_factory(CLASSES)
