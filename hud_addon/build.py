"""A scene folder -> Blender objects: how "Add HUD preset" builds the tracer's own presets in the
current scene (the same preset code, no second copy of the geometry)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import bpy
import numpy as np
from mathutils import Matrix

from ..tracer.optics.materials import MATERIALS
from ..tracer.scene import ANALYSER, LEGACY_EMITTER, load_scene
from ..tracer.scene.methods import METHOD_OPTIONS
from ..tracer.sources.lights import EMISSION
from . import schema_ui
from .units import unit_mm

COLLECTION = "HUD"
#: Custom property on the collections (and objects) "Add HUD Preset" builds: the preset's name.
TAG = "hud_preset"
#: Viewport and camera clipping of a scene built in millimetres (Blender units = mm).
CLIP_MM = (0.1, 1.0e5)


def _apply_aim(h, prefix: str, aim: dict | None, by_name: dict):
    if aim is None:
        return
    setattr(h, f"{prefix}aim_share", aim.get("share", 0.5))
    setattr(h, f"{prefix}aim_mode", aim.get("mode", "toward"))
    if aim["target"] == "eye":
        setattr(h, f"{prefix}aim", "EYE")
    else:
        setattr(h, f"{prefix}aim", "OBJECT")
        setattr(h, f"{prefix}aim_object", by_name[aim["target"]])


def _apply_object(obj, spec: dict, by_name: dict, root: Path):
    """Set an object's HUD role, material fields and emission from its scene.json entry."""
    h = obj.hud
    material = dict(spec["material"])
    emission = spec.get("emission")
    if material["type"] == LEGACY_EMITTER:  # the legacy type: an absorber that emits
        emission, material = {k: v for k, v in material.items() if k != "type"}, {"type": "absorber"}
    schema = MATERIALS[material["type"]].schema
    h.role = material["type"]
    schema_ui.apply(h, schema.fields, material, "", schema.alternatives, root, by_name)
    _apply_aim(h, "", material.get("aim"), by_name)
    _apply_aim(h, "light_", material.get("light_aim"), by_name)
    if emission is not None:
        h.emits = True
        schema_ui.apply(h, EMISSION.fields, emission, "emission_", EMISSION.alternatives, root, by_name)
        _apply_aim(h, "emission_", emission.get("aim"), by_name)


def surface_blocks(o, center) -> list[dict]:
    """An object's exact surfaces (tracer.scene.model.Surface) as scene.json "surfaces" blocks in the
    coordinates of the Blender object built from it: the world's, in mm, less ``center`` (its origin)."""
    out = []
    for s in o.surfaces:
        frame = np.linalg.inv(s.to_local)
        block = {k: (v.tolist() if isinstance(v, np.ndarray) else v) for k, v in s.params.items()
                 if k not in ("origin", "axis", "x_axis")}
        out.append({"type": s.type} | block | {"origin": (frame[:3, 3] - center).tolist(),
                                               "axis": frame[:3, 2].tolist(), "x_axis": frame[:3, 0].tolist()})
    return out


#: The target block's fields that the HUD Optics panel shows; the rest travel as its Target text.
TARGET_SHOWN = {"eyebox_mm": "optics_eyebox_mm", "ipd_mm": "optics_ipd_mm", "field_grid": "optics_field_grid",
                "eye_grid": "optics_eye_grid"}


def _apply_target(h, target: dict):
    for key, prop in TARGET_SHOWN.items():
        if key in target:
            setattr(h, prop, target[key])
    rest = {k: v for k, v in target.items() if k not in TARGET_SHOWN}
    h.optics_target = json.dumps(rest) if rest else ""


def _is_factory_cube(obj) -> bool:
    """The cube of Blender's startup file: "Cube", 8 vertices at +-1, at the origin, unscaled, no role."""
    if obj.name != "Cube" or obj.type != "MESH" or obj.hud.role != "none" or len(obj.data.vertices) != 8:
        return False
    co = np.array([v.co[:] for v in obj.data.vertices])
    return (np.allclose(np.abs(co), 1.0) and np.allclose(obj.matrix_world, np.eye(4)))


#: Blender's startup camera and light: (name, type, location, rotation in radians), as the factory file has them.
FACTORY = (("Camera", "CAMERA", (7.3589, -6.9258, 4.9583), (1.1093, 0.0, 0.8149)),
           ("Light", "LIGHT", (4.0762, 1.0055, 5.9039), (0.6503, 0.0552, 1.8664)))


def _is_factory_camera_or_light(obj) -> bool:
    """The camera or the point light of Blender's startup file, where they were left: a preset brings its
    own eye (the scene's camera), and the tracer's lights are emitting objects and Sun lights."""
    for name, kind, location, rotation in FACTORY:
        if obj.name == name and obj.type == kind:
            if kind == "LIGHT" and obj.data.type != "POINT":
                return False
            return (np.allclose(obj.location[:], location, atol=1e-3)
                    and np.allclose(obj.rotation_euler[:], rotation, atol=1e-3))
    return False


def _remove_collection(coll):
    """Remove a collection, its objects and the meshes and cameras only they used."""
    for obj in list(coll.all_objects):
        data = obj.data
        bpy.data.objects.remove(obj)
        if isinstance(data, bpy.types.Mesh) and data.users == 0:
            bpy.data.meshes.remove(data)
        elif isinstance(data, bpy.types.Camera) and data.users == 0:
            bpy.data.cameras.remove(data)
    bpy.data.collections.remove(coll)


def clear_previous(scene) -> list[str]:
    """Remove the collections an earlier "Add HUD Preset" built in ``scene`` (and their objects) and
    Blender's startup cube, camera and light (where they were left); returns the names of the
    collections removed, and of the startup objects."""
    removed = []
    for coll in [c for c in scene.collection.children_recursive if TAG in c]:
        removed.append(coll.name)
        _remove_collection(coll)
    for obj in [o for o in scene.objects if _is_factory_cube(o) or _is_factory_camera_or_light(o)]:
        data, kind = obj.data, obj.type
        removed.append(f"the startup {'cube' if kind == 'MESH' else kind.lower()}")
        bpy.data.objects.remove(obj)
        if data.users == 0:
            {"MESH": bpy.data.meshes, "CAMERA": bpy.data.cameras, "LIGHT": bpy.data.lights}[kind].remove(data)
    return removed


def _use_millimetres(scene, context):
    """Blender units = millimetres (Scene > Units), with clipping for scenes a few metres deep."""
    u = scene.unit_settings
    u.system, u.scale_length, u.length_unit = "METRIC", 0.001, "MILLIMETERS"
    screen = getattr(context, "screen", None)
    for area in (screen.areas if screen is not None else []):
        for space in area.spaces:
            if space.type == "VIEW_3D":
                space.clip_start, space.clip_end = CLIP_MM


def build_scene(folder, context, replace: bool = True) -> tuple[list, list[str]]:
    """Create the objects, the eye camera and the world settings of a scene folder in the current
    scene, in a new collection "HUD <name>". With ``replace``, what an earlier
    preset built and Blender's startup cube go first. A scene that holds nothing else is set to
    millimetres (1 Blender unit = 1 mm); otherwise the preset is built in the scene's own units.
    Returns the new objects and the names of the collections replaced."""
    scene = context.scene
    sc = load_scene(folder)
    removed = clear_previous(scene) if replace else []
    others = [o for o in scene.objects if o.type not in ("LIGHT", "CAMERA")]
    if not others:
        _use_millimetres(scene, context)
    unit = unit_mm(scene)  # mm per Blender unit
    coll = bpy.data.collections.new(f"{COLLECTION} {sc.name}")
    coll[TAG] = sc.name
    scene.collection.children.link(coll)
    created, by_name = [], {}
    for o in sc.objects:
        center = o.vertices.mean(axis=0)
        mesh = bpy.data.meshes.new(o.name)
        local = (o.vertices - center) / unit
        mesh.from_pydata(local.tolist(), [], o.faces.tolist())
        if o.uv is not None:
            layer = mesh.uv_layers.new(name="UVMap")
            loop_vertex = np.empty(len(mesh.loops), dtype=np.int64)
            mesh.loops.foreach_get("vertex_index", loop_vertex)
            layer.data.foreach_set("uv", o.uv[loop_vertex].astype(np.float32).ravel())
        mesh.update()
        obj = bpy.data.objects.new(o.name, mesh)
        obj[TAG] = sc.name
        obj.location = center / unit
        if o.surfaces:
            obj.hud.surfaces = json.dumps(surface_blocks(o, center))
        obj.hud.smooth_normals = o.smooth
        if o.smooth:
            mesh.shade_smooth()
        coll.objects.link(obj)
        created.append(obj)
        by_name[o.name] = obj
    for o in sc.objects:
        _apply_object(by_name[o.name], sc.raw["objects"][o.index], by_name, Path(sc.root))
    raw_methods = dict(sc.raw.get("methods", {}))
    raw_methods |= {name: sc.raw[name] for name in ("forward", "backward") if name in sc.raw}
    for name, block in raw_methods.items():
        schema_ui.apply(scene.hud, METHOD_OPTIONS[name].fields, block, f"{name}_", (), Path(sc.root), by_name)
    scene.hud.polarisation = sc.polarisation
    _apply_target(scene.hud, sc.raw.get("target", {}))
    _build_eye(sc.eye, sc.raw["eye"], scene, coll, unit)
    _build_world(sc, scene)
    if not sc.environment.is_black:  # a HUD against an environment: the hybrid method's two channels
        scene.hud.method = "hybrid"
    return created, removed


def _build_eye(eye, raw_eye: dict, scene, coll, unit):
    """The eye camera from the scene's EyeSpec ``eye`` and its scene.json block ``raw_eye`` (the
    analyser, through its schema)."""
    cam_data = bpy.data.cameras.new("Eye")
    cam_data.sensor_fit = "HORIZONTAL"
    cam_data.sensor_width = 36.0
    cam_data.lens = 18.0 / math.tan(math.radians(eye.fov_deg[0]) / 2)
    cam_data.clip_start, cam_data.clip_end = CLIP_MM[0] / unit, CLIP_MM[1] / unit
    cam_data.hud.pupil_diameter_mm = eye.pupil_diameter_mm
    cam_data.hud.adaptation = eye.adaptation
    cam_data.hud.observer_age = eye.observer_age
    if eye.pupil_from_image:
        cam_data.hud.pupil = "IMAGE"
    cam_data.hud.focal_length_mm = eye.focal_length_mm
    acc = eye.accommodation_distance_mm
    cam_data.hud.accommodation_distance_mm = 0.0 if math.isinf(acc) else acc
    schema_ui.apply(cam_data.hud, (ANALYSER,), raw_eye)
    cam = bpy.data.objects.new("Eye", cam_data)
    cam[TAG] = coll[TAG]
    right = np.cross(eye.gaze, eye.up)
    right /= np.linalg.norm(right)
    up = np.cross(right, eye.gaze)
    rot = np.stack([right, up, -eye.gaze], axis=1)
    m = np.eye(4)
    m[:3, :3] = rot
    m[:3, 3] = eye.position / unit
    cam.matrix_world = Matrix(m.tolist())
    coll.objects.link(cam)
    scene.camera = cam
    scene.render.resolution_x, scene.render.resolution_y = eye.resolution
    scene.render.resolution_percentage = 100


def _build_world(sc, scene):
    if scene.world is None:
        scene.world = bpy.data.worlds.new("World")
    h = scene.world.hud
    env = sc.raw.get("environment", {"type": "none"})
    h.kind = env["type"]
    if env["type"] == "uniform":
        h.luminance = env["luminance"]
        h.color = tuple(env.get("color", (1.0, 1.0, 1.0)))
    elif env["type"] == "hdri":
        img = bpy.data.images.load(str(Path(sc.root) / env["file"]), check_existing=False)
        img.pack()
        h.image = img
        h.calibration, h.value = env["calibration"]["mode"], env["calibration"]["value"]
        h.rotation_deg = env.get("rotation_deg", 0.0)
