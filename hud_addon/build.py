"""A scene folder -> Blender objects: how "Add HUD preset" builds the tracer's own presets in the
current scene (the same preset code, no second copy of the geometry)."""

from __future__ import annotations

import math
from pathlib import Path

import bpy
import numpy as np
from mathutils import Matrix

from ..tracer.scene import load_scene
from .export import M_TO_MM

COLLECTION = "HUD"


def _apply_material(obj, material, by_name):
    h = obj.hud
    h.role = material.type
    p = material.params
    for key in ("reflectance", "transmittance"):
        if key in p:
            setattr(h, key, tuple(p[key]))
    if material.type == "dielectric":
        h.ior, h.ior_outside = p["ior"], p["ior_outside"]
    if material.type == "diffuser":
        h.sigma_deg = tuple(p["sigma_deg"])
    if material.type == "lcd":
        h.contrast_ratio = p["contrast_ratio"]
    if material.type == "emitter":
        if "luminance" in p:
            h.emission, h.luminance = "LUMINANCE", p["luminance"]
        else:
            h.emission, h.flux = "FLUX", p["flux"]
        h.color = tuple(p["color"])
        h.two_sided = p["two_sided"]
    if material.aim is not None:
        h.aim_share, h.aim_mode = material.aim.share, material.aim.mode
        if material.aim.target == "eye":
            h.aim = "EYE"
        else:
            h.aim, h.aim_object = "OBJECT", by_name[material.aim.target]


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
        _apply_material(by_name[o.name], o.material, by_name)
        if o.material.type == "lcd":
            img = bpy.data.images.load(str(Path(sc.root) / o.material.params["image_file"]), check_existing=False)
            img.pack()
            by_name[o.name].hud.lcd_image = img
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
