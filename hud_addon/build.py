"""A scene folder -> Blender objects: how "Add HUD preset" builds the tracer's own presets in the
current scene (the same preset code, no second copy of the geometry)."""

from __future__ import annotations

import math
from pathlib import Path

import bpy
import numpy as np
from mathutils import Matrix

from ..tracer.integrators import INTEGRATORS
from ..tracer.lights import EMISSION
from ..tracer.optics.materials import MATERIALS
from ..tracer.scene import LEGACY_EMITTER, load_scene
from . import schema_ui
from .export import M_TO_MM

COLLECTION = "HUD"


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
    if material["type"] == LEGACY_EMITTER:  # an absorber that emits, in the files of earlier releases
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


def build_scene(folder, context) -> list:
    """Create the objects, the eye camera and the world settings of a scene folder in the current
    scene (lengths mm -> Blender units). Returns the new objects."""
    scene = context.scene
    sc = load_scene(folder)
    unit = M_TO_MM * scene.unit_settings.scale_length  # mm per Blender unit
    coll = bpy.data.collections.new(f"{COLLECTION} {sc.name}")
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
        obj.location = center / unit
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
        schema_ui.apply(scene.hud, INTEGRATORS[name].options, block, f"{name}_", (), Path(sc.root), by_name)
    _build_eye(sc.eye, scene, coll, unit)
    _build_world(sc, scene)
    return created


def _build_eye(eye, scene, coll, unit):
    cam_data = bpy.data.cameras.new("Eye")
    cam_data.sensor_fit = "HORIZONTAL"
    cam_data.sensor_width = 36.0
    cam_data.lens = 18.0 / math.tan(math.radians(eye.fov_deg[0]) / 2)
    cam_data.clip_start = 0.001
    cam_data.hud.pupil_diameter_mm = eye.pupil_diameter_mm
    cam_data.hud.focal_length_mm = eye.focal_length_mm
    acc = eye.accommodation_distance_mm
    cam_data.hud.accommodation_distance_mm = 0.0 if math.isinf(acc) else acc
    cam = bpy.data.objects.new("Eye", cam_data)
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
