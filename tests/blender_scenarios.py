"""Scenarios run inside the bpy 4.5 module, one per process (bpy is imported once per process and
hangs at exit while a Python render engine is registered, so every scenario disables the add-on
before it returns). Run by tests/test_blender_addon.py; prints its result as one line "HUD_RESULT <json>"."""

from __future__ import annotations

import hashlib
import json
import os
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
os.environ["BLENDER_USER_RESOURCES"] = tempfile.mkdtemp(prefix="hud-bpy-user-")
sys.path.insert(0, str(ROOT))

import bpy  # noqa: E402  (the environment above must be set first)

from hud_addon.batch import enable_from_source  # noqa: E402


def disable(module: str):
    import addon_utils  # importable once bpy is

    addon_utils.disable(module)


def install_zip(zip_path: str) -> str:
    repo_dir = Path(tempfile.mkdtemp(prefix="hud-repo-")) / "hud_test"
    repo_dir.mkdir()
    bpy.ops.preferences.extension_repo_add(name="hud_test", type="LOCAL", use_custom_directory=True,
                                           custom_directory=str(repo_dir))
    repo = next(r.module for r in bpy.context.preferences.extensions.repos if r.custom_directory == str(repo_dir))
    bpy.ops.extensions.package_install_files(filepath=zip_path, repo=repo, enable_on_install=True)
    return f"bl_ext.{repo}.hud_tracer"


def hud_names() -> list[str]:
    return sorted(n for n in dir(bpy.types) if n.startswith(("HUD_", "HudRender", "HudScene", "HudObject")))


def render_preset(module: str, out: Path, preset: str, method: str, rays: int, seed: int) -> dict:
    bpy.ops.hud.add_preset(preset=preset)
    scene = bpy.context.scene
    scene.hud.method, scene.hud.budget, scene.hud.rays, scene.hud.seed = method, "RAYS", rays, seed
    s = scene.render.image_settings
    s.file_format, s.color_depth = "OPEN_EXR_MULTILAYER", "32"
    scene.render.filepath = str(out / "blender.exr")
    scene.render.use_file_extension = False
    bpy.ops.render.render(write_still=True)
    bpy.ops.hud.export_scene(directory=str(out / "scene"))
    return dict(sys.modules[f"{module}.hud_addon.engine"].LAST_RENDER)


#: Blender's own panels a user of HUD Tracer needs (issue 11, finding 1).
NEEDED_PANELS = ("RENDER_PT_format", "RENDER_PT_output", "RENDER_PT_frame_range", "RENDER_PT_color_management",
                 "DATA_PT_lens", "DATA_PT_uv_texture")


def panels_with_engine() -> dict:
    return {n: "HUD_TRACER" in getattr(bpy.types, n).COMPAT_ENGINES for n in NEEDED_PANELS}


def scenario_install_render(zip_path, out, preset, method, rays, seed):
    module = install_zip(zip_path)
    enabled = module in bpy.context.preferences.addons
    panels = panels_with_engine()
    figures = render_preset(module, Path(out), preset, method, int(rays), int(seed))
    disable(module)
    return {"module": module, "enabled": enabled, "figures": figures, "left_after_disable": hud_names(),
            "panels": panels, "panels_after_disable": panels_with_engine(), "threads": bpy.context.scene.render.threads}


def scenario_roundtrip(out):
    module = enable_from_source(bpy, Path(tempfile.mkdtemp()))
    scene = bpy.context.scene
    scene.unit_settings.scale_length = 1.0
    bpy.ops.mesh.primitive_plane_add(size=0.2, location=(0.1, 0.2, 0.3), rotation=(0.5, 0.0, 0.25))
    mirror = bpy.context.object
    mirror.name = "mirror"
    mirror.hud.role, mirror.hud.reflectance, mirror.hud.smooth_normals = "mirror", (0.8, 0.7, 0.6), True
    subdiv = mirror.modifiers.new("subdivide", "SUBSURF")  # exported evaluated: 2 triangles become 8
    subdiv.subdivision_type, subdiv.levels = "SIMPLE", 1
    bpy.ops.mesh.primitive_cube_add(size=0.1, location=(0.0, 0.5, 0.0))
    glass = bpy.context.object
    glass.name = "glass"
    glass.scale = (1.0, 0.05, 1.0)
    glass.hud.role, glass.hud.ior = "dielectric", 1.6
    bpy.ops.mesh.primitive_plane_add(size=0.01, location=(0.0, 0.8, 0.0))
    led = bpy.context.object
    led.name = "led"
    led.hud.role, led.hud.emits, led.hud.emission_by, led.hud.emission_luminance = "absorber", True, "luminance", 1234.0
    h = led.hud
    h.emission_aim, h.emission_aim_object, h.emission_aim_share, h.emission_aim_mode = "OBJECT", mirror, 0.7, "toward"
    bpy.ops.mesh.primitive_plane_add(size=0.1, location=(0.3, 0.5, 0.0))
    floor = bpy.context.object
    floor.name = "floor"
    floor.hud.role, floor.hud.reflectance = "lambertian", (0.5, 0.5, 0.5)
    floor.hud.light_aim, floor.hud.light_aim_object, floor.hud.light_aim_share = "OBJECT", mirror, 0.6
    scene.hud.backward_max_depth, scene.hud.backward_next_event = 17, False  # method options are exported
    cam = scene.camera
    cam.location = (0.0, -1.0, 0.1)
    cam.data.hud.pupil_diameter_mm, cam.data.hud.accommodation_distance_mm = 3.5, 2000.0
    cam.data.hud.focal_length_mm = 17.0
    scene.hud.seed = 4  # not exported: a render setting
    bpy.ops.hud.export_scene(directory=str(Path(out) / "fixed_pupil"))
    cam.data.hud.pupil, cam.data.hud.adaptation_luminance, cam.data.hud.observer_age = "AUTO", 292.0, 30.0
    scene.render.resolution_x, scene.render.resolution_y, scene.render.resolution_percentage = 320, 160, 50
    img = bpy.data.images.new("sky", 16, 8, float_buffer=True)
    img.pixels.foreach_set([0.5] * (16 * 8 * 4))
    img.filepath_raw = str(Path(out) / "sky.exr")
    img.file_format = "OPEN_EXR"
    img.save()
    world = scene.world or bpy.data.worlds.new("World")
    scene.world = world
    world.hud.kind, world.hud.image, world.hud.calibration, world.hud.value = "hdri", img, "mean", 500.0
    world.hud.rotation_deg = 45.0
    bpy.ops.hud.export_scene(directory=str(Path(out) / "scene"))
    expected = {
        "mirror_location_mm": [100.0, 200.0, 300.0], "glass_location_mm": [0.0, 500.0, 0.0],
        "camera_location_mm": [0.0, -1000.0, 100.0],
        "camera_up": list(cam.matrix_world.to_3x3().col[1]), "camera_gaze": list(-cam.matrix_world.to_3x3().col[2]),
        "lens": cam.data.lens, "sensor": cam.data.sensor_width,
    }
    disable(module)
    return expected


def _world_vertices_mm(obj) -> list:
    """The object's vertices in world millimetres (unit scale 1)."""
    return [list(obj.matrix_world @ v.co * 1000.0) for v in obj.data.vertices]


def _float_image(name: str, value: float, w: int = 8, h: int = 4):
    img = bpy.data.images.new(name, w, h, float_buffer=True)
    img.pixels.foreach_set([value, value, value, 1.0] * (w * h))
    return img


def scenario_name_collision(out):
    """Objects whose names clean to the same file name ("m.a", "m_a", "M.A"; LCDs "s.1", "s_1" with
    different slides) export to one mesh / texture file each."""
    module = enable_from_source(bpy, Path(tempfile.mkdtemp()))
    scene = bpy.context.scene
    scene.unit_settings.scale_length = 1.0
    expected = {}
    for name, add in (("m.a", lambda: bpy.ops.mesh.primitive_plane_add(size=0.1, location=(0.0, 0.3, 0.0))),
                      ("m_a", lambda: bpy.ops.mesh.primitive_cube_add(size=0.1, location=(0.2, 0.5, 0.1))),
                      ("M.A", lambda: bpy.ops.mesh.primitive_ico_sphere_add(radius=0.05, location=(-0.2, 0.7, -0.1)))):
        add()
        obj = bpy.context.object
        obj.name = name
        obj.hud.role = "mirror"
        expected[name] = {"vertices_mm": _world_vertices_mm(obj)}
    for name, value, loc in (("s.1", 0.25, (0.0, 1.0, 0.0)), ("s_1", 0.75, (0.3, 1.0, 0.0))):
        bpy.ops.mesh.primitive_plane_add(size=0.1, location=loc)
        obj = bpy.context.object
        obj.name = name
        obj.hud.role, obj.hud.image, obj.hud.image_encoding = "lcd", _float_image(f"slide {name}", value), "linear"
        expected[name] = {"vertices_mm": _world_vertices_mm(obj), "slide": value}
    bpy.ops.hud.export_scene(directory=str(Path(out) / "scene"))
    disable(module)
    return expected


def scenario_visibility(out):
    """Render visibility decides what is exported (issue 11, finding 3): an object hidden in the
    viewport only is exported; one disabled in renders, one in a collection disabled in renders and
    one in a collection excluded from the view layer are not."""
    module = enable_from_source(bpy, Path(tempfile.mkdtemp()))
    scene = bpy.context.scene
    names = {}
    for i, name in enumerate(("shown", "viewport_hidden", "render_hidden", "in_hidden_collection",
                              "in_excluded_collection")):
        bpy.ops.mesh.primitive_plane_add(size=0.1, location=(0.2 * i, 0.5, 0.0))
        obj = bpy.context.object
        obj.name = name
        obj.hud.role = "mirror"
        names[name] = obj
    names["viewport_hidden"].hide_set(True)
    names["viewport_hidden"].hide_viewport = True
    names["render_hidden"].hide_render = True
    for name, flag in (("in_hidden_collection", "hide_render"), ("in_excluded_collection", "exclude")):
        coll = bpy.data.collections.new(f"{name}_coll")
        scene.collection.children.link(coll)
        obj = names[name]
        for c in list(obj.users_collection):
            c.objects.unlink(obj)
        coll.objects.link(obj)
        if flag == "hide_render":
            coll.hide_render = True
        else:
            bpy.context.view_layer.layer_collection.children[coll.name].exclude = True
    bpy.ops.hud.export_scene(directory=str(Path(out) / "scene"))
    disable(module)
    return {}


def scenario_animation(out):
    """A camera keyframed at x = -50, 0, +50 mm over frames 1-3 (issue 11, finding 2): Blender's own
    animation render (``render(animation=True)``, as ``blender -b file.blend -a``) writes one EXR per
    frame, each exported from the depsgraph at its frame."""
    module = enable_from_source(bpy, Path(tempfile.mkdtemp()))
    bpy.ops.hud.add_preset(preset="analytic-mirror")
    scene = bpy.context.scene
    unit_mm = 1000.0 * scene.unit_settings.scale_length
    cam = scene.camera
    x0 = cam.location.x
    for frame, dx_mm in ((1, -50.0), (2, 0.0), (3, 50.0)):
        cam.location.x = x0 + dx_mm / unit_mm
        cam.keyframe_insert("location", index=0, frame=frame)
    scene.frame_start, scene.frame_end = 1, 3
    scene.hud.method, scene.hud.budget, scene.hud.rays, scene.hud.seed = "backward", "RAYS", 300_000, 3
    s = scene.render.image_settings
    s.file_format, s.color_depth = "OPEN_EXR_MULTILAYER", "32"
    scene.render.filepath = str(Path(out) / "frame_####")
    engine_mod = sys.modules[f"{module}.hud_addon.engine"]
    eyes = {}

    def remember(scene_, depsgraph=None):
        eyes[scene_.frame_current] = dict(engine_mod.LAST_RENDER).get("run_id")

    bpy.app.handlers.render_post.append(remember)
    bpy.ops.render.render(animation=True)
    bpy.app.handlers.render_post.remove(remember)
    exported = {}
    for frame in (1, 2, 3):  # the export operator at each frame (the viewport's depsgraph)
        scene.frame_set(frame)
        bpy.ops.hud.export_scene(directory=str(Path(out) / f"scene_{frame}"))
        exported[frame] = json.loads((Path(out) / f"scene_{frame}" / "scene.json").read_text())["eye"]["position"]
    disable(module)
    return {"x0_mm": x0 * unit_mm, "run_ids": eyes, "exported_eye_mm": exported,
            "files": sorted(p.name for p in Path(out).glob("frame_*.exr"))}


def scenario_instances(out):
    """Collection instances and an object hidden from renders (issue 11, finding 2): a mirror in a
    collection excluded from the view layer, instanced by two empties, exports as two mirrors at the
    instances' places; a third instance disabled in renders is left out."""
    module = enable_from_source(bpy, Path(tempfile.mkdtemp()))
    scene = bpy.context.scene
    scene.unit_settings.scale_length = 0.001  # 1 Blender unit = 1 mm
    coll = bpy.data.collections.new("optics")
    scene.collection.children.link(coll)
    bpy.ops.mesh.primitive_plane_add(size=20.0, location=(0.0, 0.0, 0.0))
    mirror = bpy.context.object
    mirror.name = "mirror"
    mirror.hud.role, mirror.hud.reflectance = "mirror", (0.9, 0.9, 0.9)
    for c in list(mirror.users_collection):
        c.objects.unlink(mirror)
    coll.objects.link(mirror)
    bpy.context.view_layer.layer_collection.children[coll.name].exclude = True
    places = {"inst_a": (100.0, 0.0, 0.0), "inst_b": (0.0, 200.0, 0.0), "inst_hidden": (0.0, 0.0, 300.0)}
    for name, loc in places.items():
        empty = bpy.data.objects.new(name, None)
        empty.instance_type, empty.instance_collection = "COLLECTION", coll
        empty.location = loc
        scene.collection.objects.link(empty)
    bpy.data.objects["inst_hidden"].hide_render = True
    bpy.ops.hud.export_scene(directory=str(Path(out) / "scene"))
    disable(module)
    return {"places": places}


def scenario_preset_twice():
    """Add HUD Preset on Blender's startup scene, twice, then once more without replacing (issue 11,
    finding 9)."""
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


def scenario_colour_space(out):
    """An LCD's slide encoding follows the image's own Color Space (issue 11, finding 6)."""
    module = enable_from_source(bpy, Path(tempfile.mkdtemp()))
    bpy.ops.hud.add_preset(preset="hud-direct")
    lcd = next(o for o in bpy.context.scene.objects if o.hud.role == "lcd")
    image = lcd.hud.image
    lcd.hud.image_encoding = "linear"  # the old Encoding property: no longer what decides
    result = {"spaces": {}}
    for space in ("sRGB", "Non-Color", "ACEScg"):
        try:
            image.colorspace_settings.name = space
        except TypeError:
            continue  # not in this Blender's OCIO configuration
        try:
            bpy.ops.hud.export_scene(directory=str(Path(out) / space))
            data = json.loads((Path(out) / space / "scene.json").read_text())
            mat = next(o["material"] for o in data["objects"] if o["material"]["type"] == "lcd")
            result["spaces"][space] = mat["image_encoding"]
        except RuntimeError as e:
            result["spaces"][space] = "error: " + str(e)
    result["is_float"] = image.is_float
    result["image"] = image.name
    disable(module)
    return result


def scenario_tooltips():
    """Every property of the add-on's property groups, as registered, with its description (issue 11,
    finding 9: properties without a tooltip)."""
    module = enable_from_source(bpy, Path(tempfile.mkdtemp()))
    missing, groups = [], []
    for owner in (bpy.types.Scene, bpy.types.Object, bpy.types.Camera, bpy.types.World, bpy.types.Light):
        pointer = owner.bl_rna.properties.get("hud")
        if pointer is None:
            continue
        group = pointer.fixed_type
        groups.append(group.identifier)
        for prop in group.properties:
            if prop.identifier not in ("rna_type", "name") and not prop.description.strip():
                missing.append(f"{group.identifier}.{prop.identifier}")
    disable(module)
    return {"missing": missing, "groups": groups}


def _file_hashes(folder: Path) -> dict:
    """SHA-256 of every file under ``folder`` by relative path."""
    return {p.relative_to(folder).as_posix(): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(folder.rglob("*")) if p.is_file()}


def scenario_failed_export(out):
    """A good export into F, then exports into F that fail (missing HDRI file, LCD without slide, an aim
    object not chosen, an orthographic or shifted camera, a role on a text, no camera; and a folder
    holding other files): what each says, and F afterwards."""
    module = enable_from_source(bpy, Path(tempfile.mkdtemp()))
    export_scene = sys.modules[f"{module}.hud_addon.export"].export_scene
    out = Path(out)
    parent = out / "exports"
    target = parent / "F"
    scene = bpy.context.scene
    scene.unit_settings.scale_length = 1.0
    bpy.ops.mesh.primitive_plane_add(size=0.2, location=(0.0, 0.3, 0.0))
    mirror = bpy.context.object
    mirror.name, mirror.hud.role = "mirror", "mirror"
    bpy.ops.mesh.primitive_plane_add(size=0.1, location=(0.0, 0.6, 0.0))
    lcd = bpy.context.object
    slide = _float_image("slide", 0.5)
    lcd.name, lcd.hud.role, lcd.hud.image, lcd.hud.image_encoding = "lcd panel", "lcd", slide, "linear"
    bpy.ops.mesh.primitive_plane_add(size=0.01, location=(0.0, 0.8, 0.0))
    led = bpy.context.object
    led.name, led.hud.role, led.hud.emits, led.hud.emission_luminance = "led", "absorber", True, 1000.0
    bpy.ops.mesh.primitive_plane_add(size=0.05, location=(0.3, 0.3, 0.0))
    extra = bpy.context.object
    extra.name, extra.hud.role = "extra", "absorber"
    sky_file = out / "sky.exr"
    made = _float_image("sky source", 0.5, 16, 8)
    made.filepath_raw, made.file_format = str(sky_file), "OPEN_EXR"
    made.save()
    sky = bpy.data.images.load(str(sky_file), check_existing=False)
    sky.name = "sky"
    world = scene.world or bpy.data.worlds.new("World")
    scene.world = world
    world.hud.kind, world.hud.image, world.hud.calibration, world.hud.value = "hdri", sky, "mean", 500.0

    def depsgraph():
        return bpy.context.evaluated_depsgraph_get()

    export_scene(depsgraph(), target)
    good = _file_hashes(target)
    # Change the geometry and the slide, so that anything the failing exports write shows in F's files.
    for v in mirror.data.vertices:
        v.co.x *= 2.0
    slide.pixels.foreach_set([0.9] * (8 * 4 * 4))
    attempts = {}

    def attempt(case, folder=target, operator=False):
        try:
            if operator:
                bpy.ops.hud.export_scene(directory=str(folder))
            else:
                export_scene(depsgraph(), folder)
            message = None
        except Exception as e:  # noqa: BLE001 - the message is what is tested
            message = f"{type(e).__name__}: {e}"
        attempts[case] = {"message": message, "hashes": _file_hashes(folder),
                          "hidden": sorted(n for n in os.listdir(parent) if n.startswith("."))}

    missing = out / "missing" / "sky.exr"
    sky.filepath = str(missing)
    attempt("hdri_missing")
    attempt("hdri_missing_operator", operator=True)
    sky.filepath = str(sky_file)
    lcd.hud.image = None
    attempt("lcd_no_image")
    lcd.hud.image = slide
    led.hud.emission_aim, led.hud.emission_aim_object = "OBJECT", None
    attempt("aim_unset")
    led.hud.emission_aim = "NONE"
    # File system failures: a disk that fills while meshes are written; a staging folder that cannot
    # take F's place (after F was moved aside).
    export_mod = sys.modules[f"{module}.hud_addon.export"]
    write_obj, rename = export_mod.write_obj, os.rename

    def write_half(path, *args, **kwargs):
        Path(path).write_text("v 0 0 0\n")
        raise OSError(28, "No space left on device", str(path))

    def rename_fails_for_staging(src, dst):
        if ".staging-" in str(src):
            raise OSError(13, "Permission denied", str(dst))
        return rename(src, dst)

    export_mod.write_obj = write_half
    attempt("disk_full")
    export_mod.write_obj = write_obj
    os.rename = rename_fails_for_staging
    try:
        attempt("rename_fails")
    finally:
        os.rename = rename
    # The tracer's validation rejects the staged folder (an open dielectric: a plane of glass).
    extra.hud.role = "dielectric"
    attempt("tracer_rejects", operator=True)
    extra.hud.role = "absorber"
    foreign = parent / "G"
    foreign.mkdir()
    (foreign / "notes.txt").write_text("not an export\n")
    attempt("foreign_folder", folder=foreign)
    camera = scene.camera
    camera.data.type = "ORTHO"
    attempt("ortho_camera")
    camera.data.type = "PERSP"
    camera.data.shift_x = 0.1
    attempt("shifted_camera")
    camera.data.shift_x = 0.0
    bpy.ops.object.text_add(location=(0.0, 0.4, 0.0))
    text = bpy.context.object
    text.name, text.hud.role = "label", "mirror"
    attempt("role_on_text")
    bpy.data.objects.remove(text)
    camera_data = camera.data
    bpy.data.objects.remove(camera)
    attempt("no_camera")
    # Put the camera back and drop "extra": the export now replaces F as a whole.
    camera = bpy.data.objects.new("Camera", camera_data)
    scene.collection.objects.link(camera)
    camera.location = (0.0, -1.0, 0.0)
    scene.camera = camera
    bpy.data.objects.remove(extra)
    attempt("after_fix")
    # A folder relative to the .blend ("//") while the .blend is not saved: Blender resolved it against
    # the working directory, and the export landed wherever that was.
    cwd = os.getcwd()
    os.chdir(out)
    try:
        bpy.ops.hud.export_scene(directory="//hud_export/")
        relative = None
    except RuntimeError as e:
        relative = str(e)
    finally:
        os.chdir(cwd)
    attempts["relative_unsaved"] = {"message": relative, "written": (out / "hud_export").exists()}
    disable(module)
    return {"good": good, "attempts": attempts, "missing": str(missing)}


class _Pass:
    def __init__(self, channels, n):
        self.channels, self.n, self.values = channels, n, None
        self.rect = self

    def foreach_set(self, values):
        assert len(values) == self.n * self.channels, (len(values), self.n, self.channels)
        self.values = list(map(float, values[:: max(1, len(values) // 1000)]))


class StubEngine:
    """Stands in for a RenderEngine: test_break turns true after ``stop_after`` calls, or (``stop_after``
    None) at the first call after the render reported progress, that is after its first merged batch."""

    def __init__(self, stop_after):
        self.stop_after, self.calls, self.progress, self.reports, self.passes = stop_after, 0, [], [], {}
        self.updates, self.stamps, self.result = 0, {}, None

    def test_break(self):
        self.calls += 1
        return bool(self.progress) if self.stop_after is None else self.calls > self.stop_after

    def update_progress(self, f):
        self.progress.append(f)

    def update_stats(self, a, b):
        pass

    def report(self, kind, msg):
        self.reports.append(msg)

    def add_pass(self, name, channels, chan_id):
        self.passes[name] = channels

    def begin_result(self, x, y, w, h):
        class Layer:
            passes = {"Combined": _Pass(4, w * h), **{k: _Pass(c, w * h) for k, c in self.passes.items()}}

        stamps = self.stamps

        class Result:
            layers = [Layer()]

            @staticmethod
            def stamp_data_add_field(key, value):
                stamps[key] = value

        self.result = Result()
        return self.result

    def update_result(self, rr):
        self.updates += 1

    def get_result(self):
        return self.result

    def end_result(self, rr):
        pass


def scenario_cancel(threads, when):
    """A 600 s render on ``threads`` processes cancelled at the first test_break after the first batch
    was merged (``when`` "after_first_batch") or at the very first one ("at_once")."""
    import time

    module = enable_from_source(bpy, Path(tempfile.mkdtemp()))
    bpy.ops.hud.add_preset(preset="hud-direct")
    scene = bpy.context.scene
    scene.hud.method, scene.hud.budget, scene.hud.seconds = "forward", "SECONDS", 600.0
    scene.render.threads_mode, scene.render.threads = "FIXED", int(threads)
    engine_mod = sys.modules[f"{module}.hud_addon.engine"]
    engine_mod.REPORTS[scene.name] = {"blender": {"frame": scene.frame_current}}  # an earlier render's
    stub = StubEngine(stop_after={"after_first_batch": None, "at_once": 0}[when])
    t0 = time.perf_counter()
    figures = engine_mod.render_final(stub, bpy.context.evaluated_depsgraph_get())
    seconds = time.perf_counter() - t0
    passes = stub.result.layers[0].passes if stub.result is not None else {}
    out = {"figures": figures, "test_break_calls": stub.calls, "seconds": seconds, "reports": stub.reports,
           "samples": {k: passes[k].values for k in ("Combined", "Y", "Y_noise") if k in passes},
           "kept_report": scene.name in engine_mod.REPORTS, "last_render": dict(engine_mod.LAST_RENDER)}
    disable(module)
    return out


def scenario_world_and_slide_messages(out):
    """Exports that fail on the World's fields and on a slide's pixels: what each says."""
    module = enable_from_source(bpy, Path(tempfile.mkdtemp()))
    bpy.ops.hud.add_preset(preset="hud-direct")
    scene = bpy.context.scene
    world = scene.world or bpy.data.worlds.new("World")
    scene.world = world
    sky = bpy.data.images.new("old sky", 16, 8, float_buffer=True)
    sky.pixels.foreach_set([1.0] * 16 * 8 * 4)
    sky.pack()
    world.hud.image = sky
    messages = {}

    def attempt(case):
        try:
            bpy.ops.hud.export_scene(directory=str(Path(out) / case))
            messages[case] = None
        except RuntimeError as e:
            messages[case] = str(e)

    world.hud.kind, world.hud.luminance = "uniform", 1e300  # the panorama is left over, not used
    attempt("uniform luminance")
    world.hud.kind, world.hud.calibration, world.hud.value = "hdri", "scale", 1e300
    attempt("calibration value")
    world.hud.kind = "none"
    lcd = next(o for o in scene.objects if o.hud.role == "lcd")
    hot = bpy.data.images.new("hot slide", 8, 8, float_buffer=True)  # generated, filled: its pixels are here
    hot.pixels.foreach_set([2.0] * 256)
    lcd.hud.image = hot
    attempt("slide above 1")
    disable(module)
    return messages


def scenario_option_messages(out):
    """Exports and an Eyebox Sweep that fail on render settings, object references, the lens and a mesh:
    what each says."""
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


def scenario_unsupported_output(out):
    """F12 (bpy.ops.render.render, write_still) of analytic-mirror with each output setting the engine
    cannot honour, and with more processes than the memory holds (the add-on's tracer told the machine
    has 1 GiB): the error Blender reports, and the files written."""
    module = enable_from_source(bpy, Path(tempfile.mkdtemp()))
    engine_mod = sys.modules[f"{module}.hud_addon.engine"]
    validate = sys.modules[f"{module}.tracer.core.validate"]
    cases = {"region, cropped": {"use_border": True, "use_crop_to_border": True},
             "region": {"use_border": True, "use_crop_to_border": False},
             "stereoscopy": {"use_multiview": True},
             "pixel aspect": {"pixel_aspect_x": 2.0},
             "threads": {"threads_mode": "FIXED", "threads": 16}}
    result = {}
    for name, settings in cases.items():
        bpy.ops.hud.add_preset(preset="analytic-mirror")
        scene = bpy.context.scene
        scene.hud.budget, scene.hud.rays = "RAYS", 100_000
        scene.render.resolution_x, scene.render.resolution_y = 32, 24
        scene.render.border_min_x, scene.render.border_max_x = 0.25, 0.75
        for key, value in settings.items():
            setattr(scene.render, key, value)
        folder = Path(out) / name.replace(", ", "_").replace(" ", "_")
        folder.mkdir(parents=True)
        scene.render.image_settings.file_format = "OPEN_EXR_MULTILAYER"
        scene.render.filepath, scene.render.use_file_extension = str(folder / "img.exr"), False
        memory = validate.physical_memory_bytes
        validate.physical_memory_bytes = lambda: 2**30
        try:
            bpy.ops.render.render(write_still=True)
            raised = None
        except RuntimeError as e:
            raised = str(e)
        finally:
            validate.physical_memory_bytes = memory
        for key in settings:  # back to the defaults for the next case
            setattr(scene.render, key, {"threads_mode": "AUTO", "threads": 1, "pixel_aspect_x": 1.0}.get(key, False))
        result[name] = {"raised": raised, "error": engine_mod.LAST_RENDER.get("error"),
                        "files": sorted(p.name for p in folder.iterdir())}
    disable(module)
    return result


def scenario_progressive(seconds):
    """A render of ``seconds`` with Blender's default Performance > Threads (auto-detect): the number of
    processes, and how often the Render Result was updated while it ran."""
    module = enable_from_source(bpy, Path(tempfile.mkdtemp()))
    bpy.ops.hud.add_preset(preset="hud-direct")
    scene = bpy.context.scene
    scene.hud.method, scene.hud.budget, scene.hud.seconds = "backward", "SECONDS", float(seconds)
    stub = StubEngine(stop_after=10**9)
    report = sys.modules[f"{module}.hud_addon.engine"].render_final(stub, bpy.context.evaluated_depsgraph_get())
    disable(module)
    return {"workers": report["workers"], "batches": report["batches"], "seconds": report["seconds"],
            "updates": stub.updates, "threads_mode": scene.render.threads_mode, "cpus": os.cpu_count()}


def scenario_light_paths():
    module = enable_from_source(bpy, Path(tempfile.mkdtemp()))
    bpy.ops.hud.add_preset(preset="analytic-mirror")
    bpy.ops.hud.show_light_paths(particles=20000, max_paths=50)
    obj = bpy.data.objects["HUD light paths"]
    verts = [tuple(v.co) for v in obj.data.vertices]
    edges = len(obj.data.edges)
    eye = tuple(bpy.context.scene.camera.location)
    mm = 1000.0 * bpy.context.scene.unit_settings.scale_length
    errors = {}
    scene = bpy.context.scene
    camera, scene.camera = scene.camera, None
    try:
        bpy.ops.hud.show_light_paths(particles=1000)
    except RuntimeError as e:
        errors["no camera"] = str(e)
    scene.camera = camera
    bpy.ops.mesh.primitive_plane_add(size=10, location=(0, 100, 0))
    plate = bpy.context.object
    plate.name, plate.hud.role = "glass plate", "dielectric"
    try:
        bpy.ops.hud.show_light_paths(particles=1000)
    except RuntimeError as e:
        errors["open glass"] = str(e)
    disable(module)
    return {"vertices": verts, "edges": edges, "eye": eye, "mm_per_unit": mm, "errors": errors}


def scenario_no_light():
    module = enable_from_source(bpy, Path(tempfile.mkdtemp()))
    bpy.ops.hud.add_preset(preset="analytic-mirror")
    scene = bpy.context.scene
    bpy.data.objects["panel"].hud.emission_luminance = 0.0
    scene.hud.method, scene.hud.budget, scene.hud.rays = "backward", "RAYS", 200_000
    stub = StubEngine(stop_after=10**9)
    figures = sys.modules[f"{module}.hud_addon.engine"].render_final(stub, bpy.context.evaluated_depsgraph_get())
    disable(module)
    return {"figures": figures, "reports": stub.reports}


def scenario_misaimed():
    """analytic-mirror with its pupil image (the panel's aim target) shrunk to half its size, rendered
    forward: what the engine reports, before the first ray and after the render."""
    module = enable_from_source(bpy, Path(tempfile.mkdtemp()))
    bpy.ops.hud.add_preset(preset="analytic-mirror")
    scene = bpy.context.scene
    bpy.data.objects["pupil_image"].scale = (0.5, 0.5, 0.5)
    scene.hud.method, scene.hud.budget, scene.hud.rays = "forward", "RAYS", 200_000
    stub = StubEngine(stop_after=10**9)
    figures = sys.modules[f"{module}.hud_addon.engine"].render_final(stub, bpy.context.evaluated_depsgraph_get())
    disable(module)
    return {"figures": figures, "reports": stub.reports}


def scenario_unregister():
    module = enable_from_source(bpy, Path(tempfile.mkdtemp()))
    before = hud_names()
    owners = (bpy.types.Scene, bpy.types.Object, bpy.types.Camera, bpy.types.World, bpy.types.Light)
    props_before = [hasattr(t, "hud") for t in owners]
    disable(module)
    props_after = [hasattr(t, "hud") for t in owners]
    engines = bpy.context.scene.render.bl_rna.properties["engine"].enum_items.keys()
    return {"before": before, "after": hud_names(), "props_before": props_before, "props_after": props_after,
            "engines": [e for e in ("HUD_TRACER",) if e in engines]}


def scenario_save_generated_hdri(path):
    """analytic-mirror with an HDRI environment whose image is generated, filled, neither saved nor
    packed, saved into a .blend (its pixels are gone when the file is opened again)."""
    module = enable_from_source(bpy, Path(tempfile.mkdtemp()))
    bpy.ops.hud.add_preset(preset="analytic-mirror")
    img = bpy.data.images.new("sky", 64, 32, float_buffer=True)
    img.pixels.foreach_set([1.0] * (64 * 32 * 4))
    world = bpy.context.scene.world
    world.hud.kind, world.hud.image = "hdri", img
    warnings = sys.modules[f"{module}.hud_addon.export"].generated_image_warnings(bpy.context.scene)
    bpy.ops.wm.save_as_mainfile(filepath=path)
    disable(module)
    return {"warnings": warnings}


class _Layout:
    """Stands in for a panel's layout: counts the labels drawn."""

    def __init__(self, counter):
        self.counter = counter

    def label(self, text="", icon="NONE"):
        self.counter.append(text)

    def __getattr__(self, name):
        if name in ("column", "row", "box", "grid_flow"):
            return lambda *a, **k: _Layout(self.counter)
        return lambda *a, **k: None


def scenario_readouts(out):
    """hud-direct rendered with write_still into out/frame.exr, the HUD Readouts panel drawn, the false
    colour shown, an eyebox sweep with the command line's grid (+-90 x +-30 mm, 10 mm) into out/eyebox."""
    module = enable_from_source(bpy, Path(tempfile.mkdtemp()))
    bpy.ops.hud.add_preset(preset="hud-direct")
    scene = bpy.context.scene
    scene.hud.method, scene.hud.budget, scene.hud.rays, scene.hud.seed = "backward", "RAYS", 2_000_000, 1
    s = scene.render.image_settings
    s.file_format, s.color_depth = "OPEN_EXR_MULTILAYER", "32"
    scene.render.filepath = str(Path(out) / "frame.exr")
    scene.render.use_file_extension = False
    bpy.ops.render.render(write_still=True)
    pkg = f"{module}.hud_addon"
    engine_mod, ui_mod = sys.modules[f"{pkg}.engine"], sys.modules[f"{pkg}.ui"]
    rows = sys.modules[f"{module}.tracer.products.report"].readouts(engine_mod.REPORTS[scene.name])
    labels = []

    class Panel:
        layout = _Layout(labels)

    ui_mod.HUD_PT_readouts.draw(Panel(), bpy.context)
    bpy.ops.hud.show_false_colour()
    image = bpy.data.images["HUD False Colour"]
    expected = engine_mod.FALSE_COLOUR[scene.name][0].shape
    h = scene.hud
    h.eyebox_half_width_mm, h.eyebox_half_height_mm, h.eyebox_step_mm = 90.0, 30.0, 10.0
    h.eyebox_folder = str(Path(out) / "eyebox")
    bpy.ops.hud.eyebox_sweep()
    chart = "eyebox.png" in bpy.data.images
    disable(module)
    return {"rows": rows, "panel_labels": len(labels), "eyebox_image": chart,
            "false_colour": {"size": list(image.size), "expected_size": [expected[1], expected[0]]}}


def scenario_hybrid_passes(out):
    """hud-direct against a uniform 1000 cd/m^2 World, rendered with the hybrid method into a
    multilayer EXR: one pass per channel."""
    module = enable_from_source(bpy, Path(tempfile.mkdtemp()))
    bpy.ops.hud.add_preset(preset="hud-direct")
    scene = bpy.context.scene
    scene.world.hud.kind, scene.world.hud.luminance = "uniform", 1000.0
    scene.hud.method, scene.hud.budget, scene.hud.rays, scene.hud.seed = "hybrid", "RAYS", 3_000_000, 2
    scene.render.resolution_percentage = 50
    s = scene.render.image_settings
    s.file_format, s.color_depth = "OPEN_EXR_MULTILAYER", "32"
    scene.render.filepath = str(Path(out) / "hybrid.exr")
    scene.render.use_file_extension = False
    bpy.ops.render.render(write_still=True)
    report = dict(sys.modules[f"{module}.hud_addon.engine"].LAST_RENDER)
    disable(module)
    return {"channels": {k: v.get("method") for k, v in report["method_details"]["channels"].items()}}


def scenario_study_preset(out, preset):
    """A study preset (a HUD against a real panorama) added in Blender and rendered as built (its
    method, its eye): the passes and what the report says of the pupil and the channels."""
    module = enable_from_source(bpy, Path(tempfile.mkdtemp()))
    bpy.ops.hud.add_preset(preset=preset)
    scene = bpy.context.scene
    method, pupil = scene.hud.method, scene.camera.data.hud.pupil
    scene.hud.budget, scene.hud.rays, scene.hud.seed = "RAYS", 4_000_000, 1
    s = scene.render.image_settings
    s.file_format, s.color_depth = "OPEN_EXR_MULTILAYER", "32"
    scene.render.filepath = str(Path(out) / "study.exr")
    scene.render.use_file_extension = False
    bpy.ops.render.render(write_still=True)
    report = dict(sys.modules[f"{module}.hud_addon.engine"].LAST_RENDER)
    disable(module)
    return {"method": method, "pupil": pupil, "pupil_report": report["method_details"].get("pupil"),
            "channels": {k: v.get("method") for k, v in report["method_details"]["channels"].items()},
            "adaptation_mode": report["adaptation_mode"]}


def scenario_sun(out):
    """A Sun light as the environment's sun: a 4 m Lambertian floor seen from 0.5 m above; a Sun light
    turned 60 deg about x (it shines along its -Z: toward +y and down, so the sun stands 30 deg high
    toward -y), Angle 0.53 deg, a warm colour, HUD Sun 80,000 lx, keyframed to turn 90 deg about z at
    frame 2; a point light beside it (not exported). Exports: frame 1 with no World, frame 2, frame 1
    with an HDRI World calibrated to its minimum; then the failures: a second Sun light rendered, the
    same disabled in renders (exported again), an Angle of 0, a black Color in an F12 render; and the
    HUD Sun panel drawn."""
    import math
    import types

    module = enable_from_source(bpy, Path(tempfile.mkdtemp()))
    export_mod = sys.modules[f"{module}.hud_addon.export"]
    ui_mod = sys.modules[f"{module}.hud_addon.ui"]
    out = Path(out)
    scene = bpy.context.scene
    scene.unit_settings.scale_length = 1.0
    for obj in list(scene.objects):
        if obj.type != "CAMERA":
            bpy.data.objects.remove(obj)
    scene.world = None
    bpy.ops.mesh.primitive_plane_add(size=4.0, location=(0.0, 0.0, 0.0))
    floor = bpy.context.object
    floor.name, floor.hud.role, floor.hud.reflectance = "floor", "lambertian", (0.5, 0.5, 0.5)
    cam = scene.camera
    cam.location, cam.rotation_euler = (0.0, 0.0, 0.5), (0.0, 0.0, 0.0)  # looking straight down
    scene.render.resolution_x, scene.render.resolution_y, scene.render.resolution_percentage = 8, 8, 100
    light = bpy.data.lights.new("Sun", type="SUN")
    light.angle, light.color, light.hud.illuminance_lux = math.radians(0.53), (1.0, 0.9, 0.8), 80_000.0
    sun = bpy.data.objects.new("Sun", light)
    scene.collection.objects.link(sun)
    for frame, turn in ((1, 0.0), (2, 90.0)):
        sun.rotation_euler = (math.radians(60.0), 0.0, math.radians(turn))
        sun.keyframe_insert("rotation_euler", frame=frame)
    lamp = bpy.data.objects.new("lamp", bpy.data.lights.new("lamp", type="POINT"))
    scene.collection.objects.link(lamp)

    def export(name):
        try:
            bpy.ops.hud.export_scene(directory=str(out / name))
            return None
        except RuntimeError as e:  # the operator's report
            return str(e)

    scene.frame_set(1)
    messages = {"frame1": export("frame1")}
    scene.frame_set(2)
    messages["frame2"] = export("frame2")
    scene.frame_set(1)
    directions = {"frame1": list(sun.matrix_world.col[2][:3])}
    scene.frame_set(2)
    directions["frame2"] = list(sun.matrix_world.col[2][:3])
    scene.frame_set(1)
    sky = bpy.data.images.new("sky", 16, 8, float_buffer=True)
    sky.pixels.foreach_set([0.2 + 0.01 * (i % 7) if i % 4 != 3 else 1.0 for i in range(16 * 8 * 4)])
    sky.filepath_raw, sky.file_format = str(out / "sky.exr"), "OPEN_EXR"
    sky.save()
    world = bpy.data.worlds.new("World")
    scene.world = world
    world.hud.kind, world.hud.image, world.hud.calibration, world.hud.value = "hdri", sky, "min", 5.0
    messages["hdri_min"] = export("hdri_min")
    second = bpy.data.objects.new("Sun.second", bpy.data.lights.new("Sun.second", type="SUN"))
    scene.collection.objects.link(second)
    messages["two_suns"] = export("two_suns")
    second.hide_render = True
    messages["second_hidden"] = export("second_hidden")
    light.angle = 0.0
    messages["angle_0"] = export("angle_0")
    light.angle = math.radians(0.53)
    light.color = (0.0, 0.0, 0.0)  # refused by the tracer's validation: F12 names the light and its Color
    engine_mod = sys.modules[f"{module}.hud_addon.engine"]
    messages["black_f12"] = engine_mod.render_final(StubEngine(10**9), bpy.context.evaluated_depsgraph_get())["error"]
    light.color = (1.0, 0.9, 0.8)
    labels = []

    class Panel:
        layout = _Layout(labels)

    context = types.SimpleNamespace(light=light, engine="HUD_TRACER", scene=scene)
    polls = {"sun": ui_mod.HUD_PT_sun.poll(context),
             "other engine": ui_mod.HUD_PT_sun.poll(types.SimpleNamespace(light=light, engine="CYCLES")),
             "no light": ui_mod.HUD_PT_sun.poll(types.SimpleNamespace(light=None, engine="HUD_TRACER"))}
    ui_mod.HUD_PT_sun.draw(Panel(), context)
    spec_direct = export_mod.sun_spec(bpy.context.evaluated_depsgraph_get())
    disable(module)
    return {"messages": messages, "directions": directions, "polls": polls, "labels": labels,
            "spec_direct": spec_direct}


class _PropLayout:
    """Stands in for a panel's layout: records the names of the properties drawn."""

    def __init__(self, names):
        self.names = names

    def prop(self, owner, name, **kw):
        self.names.append(name)

    def __getattr__(self, name):
        if name in ("column", "row", "box", "grid_flow"):
            return lambda *a, **k: _PropLayout(self.names)
        return lambda *a, **k: None


def scenario_polarisation(out):
    """The polarisation of the scene in Blender: hud-direct with its LCD's output polariser on, a
    retarder film, a coating given for s and p light, a metal mirror, polarised emission, the eye's
    analyser (axis 90, along 0.9, across 0.01) and Polarisation "auto": panels drawn, exported to
    out/pol; with Polarisation "off" the export is refused and an F12-style export names the Blender
    settings; out/pol built back with Add HUD Preset's build_scene; the hud-direct-s-sunglasses preset
    added when the tracer has it."""
    import types

    module = enable_from_source(bpy, Path(tempfile.mkdtemp()))
    pkg = f"{module}.hud_addon"
    export_mod, build_mod, ui_mod = (sys.modules[f"{pkg}.{m}"] for m in ("export", "build", "ui"))
    out = Path(out)
    bpy.ops.hud.add_preset(preset="hud-direct")
    scene = bpy.context.scene
    lcd = next(o for o in scene.objects if o.hud.role == "lcd")
    lcd.hud.polariser_use, lcd.hud.polariser_axis_deg = True, 45.0
    led = next(o for o in scene.objects if o.hud.emits)
    led.hud.emission_polarisation_use = True
    led.hud.emission_polarisation_axis_deg, led.hud.emission_polarisation_degree = 30.0, 0.5
    extras = {}
    for k, (name, role) in enumerate((("film", "retarder"), ("splitter", "coating"), ("metal", "mirror"))):
        bpy.ops.mesh.primitive_plane_add(size=5.0, location=(1000.0 + 20.0 * k, 1000.0, 1000.0))
        obj = extras[name] = bpy.context.object
        obj.name, obj.hud.role = name, role
    h = extras["film"].hud
    h.transmittance, h.axis_deg, h.retardance_deg = (0.95, 0.95, 0.95), 22.5, 90.0
    h = extras["splitter"].hud
    h.by = "reflectance_s"
    h.reflectance_s, h.reflectance_p = (0.3,) * 3, (0.1,) * 3
    h.transmittance_s, h.transmittance_p = (0.6,) * 3, (0.8,) * 3
    h = extras["metal"].hud
    h.reflectance, h.metal_use, h.metal_complex_ior = (0.9, 0.9, 0.9), True, (1.2, 7.0)
    eye = scene.camera.data.hud
    eye.analyser_use = True
    eye.analyser_axis_deg, eye.analyser_transmittance_along, eye.analyser_transmittance_across = 90.0, 0.9, 0.01
    scene.hud.polarisation = "auto"
    drawn = {}
    for panel, ctx in (("eye", types.SimpleNamespace(camera=scene.camera.data, scene=scene)),
                       ("render", types.SimpleNamespace(scene=scene)),
                       *((name, types.SimpleNamespace(object=obj)) for name, obj in (("lcd", lcd), *extras.items()))):
        names = drawn[panel] = []
        cls = {"eye": ui_mod.HUD_PT_eye, "render": ui_mod.HUD_PT_render}.get(panel, ui_mod.HUD_PT_object)
        cls.draw(types.SimpleNamespace(layout=_PropLayout(names)), ctx)
    bpy.ops.hud.export_scene(directory=str(out / "pol"))
    scene.hud.polarisation = "off"
    try:
        bpy.ops.hud.export_scene(directory=str(out / "off"))
        refused = None
    except RuntimeError as e:  # the operator's report
        refused = str(e)
    load_scene = sys.modules[f"{module}.tracer.scene"].load_scene
    scene_error = sys.modules[f"{module}.tracer.core.errors"].SceneError
    in_blender_terms = []  # what an F12 render says (the engine's export, then blender_terms)
    for _ in range(2):
        export_mod.export_scene(bpy.context.evaluated_depsgraph_get(), out / "off_unchecked")
        try:
            load_scene(out / "off_unchecked")
            in_blender_terms.append(None)
        except scene_error as e:
            in_blender_terms.append(export_mod.blender_terms(e, out / "off_unchecked", scene))
        # The next element that needs polarisation, once these are off: the retarder film.
        eye.analyser_use = lcd.hud.polariser_use = led.hud.emission_polarisation_use = False
    lcd_name = lcd.name
    for obj in extras.values():
        bpy.data.objects.remove(obj)
    scene.hud.polarisation = "off"  # build_scene sets it back
    build_mod.build_scene(out / "pol", bpy.context)
    cam = scene.camera.data.hud
    by_name = {o.name: o for o in scene.objects}
    built = {"polarisation": scene.hud.polarisation,
             "analyser": [cam.analyser_use, cam.analyser_axis_deg, cam.analyser_transmittance_along,
                          cam.analyser_transmittance_across],
             "lcd": [by_name[lcd_name].hud.polariser_use, by_name[lcd_name].hud.polariser_axis_deg],
             "film": [by_name["film"].hud.role, by_name["film"].hud.axis_deg, by_name["film"].hud.retardance_deg],
             "splitter": [by_name["splitter"].hud.by, list(by_name["splitter"].hud.reflectance_p)],
             "metal": [by_name["metal"].hud.metal_use, list(by_name["metal"].hud.metal_complex_ior)]}
    presets = sys.modules[f"{module}.presets"].PRESETS
    sunglasses = None
    if "hud-direct-s-sunglasses" in presets:
        folder = presets["hud-direct-s-sunglasses"].write(out / "sunglasses")
        bpy.ops.hud.add_preset(preset="hud-direct-s-sunglasses")
        cam = scene.camera.data.hud
        raw = json.loads((Path(folder) / "scene.json").read_text())
        sunglasses = {"analyser": raw["eye"].get("analyser"), "raw_polarisation": raw.get("polarisation", "auto"),
                      "built": {"use": cam.analyser_use, "axis_deg": cam.analyser_axis_deg,
                                "transmittance_along": cam.analyser_transmittance_along,
                                "transmittance_across": cam.analyser_transmittance_across},
                      "polarisation": scene.hud.polarisation}
    items = [(i.identifier, i.description) for i in scene.hud.bl_rna.properties["polarisation"].enum_items]
    disable(module)
    return {"drawn": drawn, "refused": refused, "in_blender_terms": in_blender_terms, "built": built,
            "sunglasses": sunglasses, "lcd": lcd_name, "items": items}


if __name__ == "__main__":
    name, *args = sys.argv[1:]
    result = globals()[f"scenario_{name}"](*args)
    print("HUD_RESULT " + json.dumps(result), flush=True)
