"""Blender data -> the tracer's scene format (tracer/scene.py), and nothing else.

Only objects with an optical role are exported, as evaluated meshes (modifiers applied), with their
world matrix; Blender's metres (times the scene's unit scale) become millimetres. The active camera
is the eye; the World's HUD settings are the environment.
"""

from __future__ import annotations

import json
import math
import shutil
from pathlib import Path

import bpy
import numpy as np

from ..presets._build import write_obj
from ..tracer.imageio import write_exr
from ..tracer.integrators import INTEGRATORS
from ..tracer.lights import EMISSION
from ..tracer.optics.materials import MATERIALS
from . import schema_ui

#: Metres to millimetres.
M_TO_MM = 1000.0


def _unit_mm(scene) -> float:
    """Millimetres per Blender unit."""
    return M_TO_MM * scene.unit_settings.scale_length


def _mesh_arrays(obj, depsgraph, with_uv: bool):
    """(vertices (v, 3) local Blender units, faces (f, 3), uv (v, 2) or None) of the evaluated mesh.
    With UVs every triangle corner gets its own vertex (UV seams stay exact)."""
    evaluated = obj.evaluated_get(depsgraph)
    mesh = evaluated.to_mesh()
    try:
        mesh.calc_loop_triangles()
        nv, nt = len(mesh.vertices), len(mesh.loop_triangles)
        co = np.empty(nv * 3)
        mesh.vertices.foreach_get("co", co)
        tri = np.empty(nt * 3, dtype=np.int64)
        mesh.loop_triangles.foreach_get("vertices", tri)
        co, tri = co.reshape(-1, 3), tri.reshape(-1, 3)
        if not with_uv or mesh.uv_layers.active is None:
            return co, tri, None
        loops = np.empty(nt * 3, dtype=np.int64)
        mesh.loop_triangles.foreach_get("loops", loops)
        uv_all = np.empty(len(mesh.loops) * 2)
        mesh.uv_layers.active.data.foreach_get("uv", uv_all)
        uv = uv_all.reshape(-1, 2)[loops]
        return co[tri.reshape(-1)], np.arange(nt * 3).reshape(-1, 3), uv
    finally:
        evaluated.to_mesh_clear()


def _matrix_mm(obj, unit_mm: float) -> list[list[float]]:
    m = np.array(obj.matrix_world, dtype=np.float64)
    m[:3, 3] *= unit_mm
    return m.tolist()


def _save_image(image, folder: Path, stem: str) -> str:
    """Copy a Blender image's file into the scene folder, or write its pixels (packed or generated
    images) as EXR values as stored; returns the path relative to the folder."""
    (folder / "textures").mkdir(parents=True, exist_ok=True)
    raw = image.filepath_raw or image.filepath
    src = Path(bpy.path.abspath(raw)) if raw else None
    if src is not None and src.is_file() and not image.packed_file:
        rel = f"textures/{stem}{src.suffix.lower()}"
        shutil.copyfile(src, folder / rel)
        return rel
    w, h = image.size
    if w == 0 or h == 0:
        raise ValueError(f"image {image.name!r} has no pixels")
    px = np.empty(w * h * image.channels, dtype=np.float32)
    image.pixels.foreach_get(px)
    px = px.reshape(h, w, image.channels)[::-1]  # Blender's row 0 is the bottom row
    rgb = px[..., :3] if image.channels >= 3 else np.repeat(px[..., :1], 3, axis=2)
    rel = f"textures/{stem}.exr"
    write_exr(folder / rel, {"R": rgb[..., 0], "G": rgb[..., 1], "B": rgb[..., 2]})
    return rel


def _aim_spec(obj, prefix: str) -> dict | None:
    h = obj.hud
    kind = getattr(h, f"{prefix}aim")
    if kind == "NONE":
        return None
    target = "eye" if kind == "EYE" else (getattr(h, f"{prefix}aim_object").name
                                         if getattr(h, f"{prefix}aim_object") else None)
    if target is None:
        raise ValueError(f"object {obj.name!r}: aim at an object, but none is chosen")
    return {"target": target, "share": getattr(h, f"{prefix}aim_share"), "mode": getattr(h, f"{prefix}aim_mode")}


def material_spec(obj, folder: Path) -> dict:
    """The scene.json material block of an object from its HUD role and the role's schema fields."""
    h = obj.hud
    schema = MATERIALS[h.role].schema

    def save(image, f):
        return _save_image(image, folder, f"{f.name}_{bpy.path.clean_name(obj.name)}")

    try:
        m = {"type": h.role} | schema_ui.export(h, schema.fields, "", schema.alternatives, save)
    except ValueError as e:
        raise ValueError(f"object {obj.name!r}: {e}") from None
    aim = _aim_spec(obj, "") if schema.can_aim else None
    if aim is not None:
        m["aim"] = aim
    return m


def emission_spec(obj) -> dict | None:
    """The scene.json emission block of an object that emits, else None."""
    h = obj.hud
    if not h.emits:
        return None
    e = schema_ui.export(h, EMISSION.fields, "emission_", EMISSION.alternatives)
    aim = _aim_spec(obj, "emission_")
    if aim is not None:
        e["aim"] = aim
    return e


def methods_spec(scene) -> dict:
    """Every method's options from the render settings (the folder renders the same with any method)."""
    return {name: schema_ui.export(scene.hud, cls.options, f"{name}_") for name, cls in INTEGRATORS.items()}


def eye_spec(scene) -> dict:
    """The eye from the active camera: position, gaze (-Z), up (+Y), field from lens and sensor."""
    cam = scene.camera
    if cam is None or cam.type != "CAMERA":
        raise ValueError("the scene needs an active camera: it is the eye")
    unit_mm = _unit_mm(scene)
    r = scene.render
    w = max(1, int(r.resolution_x * r.resolution_percentage / 100))
    h = max(1, int(r.resolution_y * r.resolution_percentage / 100))
    cd = cam.data
    fit = cd.sensor_fit
    horizontal = fit == "HORIZONTAL" or (fit == "AUTO" and w >= h)
    sensor = cd.sensor_height if fit == "VERTICAL" else cd.sensor_width
    half = math.atan(sensor / (2 * cd.lens))
    if horizontal:
        fx, fy = half, math.atan(math.tan(half) * h / w)
    else:
        fy, fx = half, math.atan(math.tan(half) * w / h)
    mw = np.array(cam.matrix_world, dtype=np.float64)
    rot = mw[:3, :3] / np.linalg.norm(mw[:3, :3], axis=0)
    acc = cd.hud.accommodation_distance_mm
    eye = {"position": (mw[:3, 3] * unit_mm).tolist(), "gaze": (-rot[:, 2]).tolist(), "up": rot[:, 1].tolist(),
           "pupil_diameter_mm": cd.hud.pupil_diameter_mm, "focal_length_mm": cd.hud.focal_length_mm,
           "accommodation_distance_mm": acc if acc > 0 else "infinity",
           "resolution": [w, h], "fov_deg": [math.degrees(2 * fx), math.degrees(2 * fy)]}
    if cd.hud.pupil == "AUTO":
        eye.update(pupil_diameter_mm="auto", observer_age=cd.hud.observer_age)
        if cd.hud.adaptation_luminance > 0:
            eye["adaptation_luminance_cd_m2"] = cd.hud.adaptation_luminance
    return eye


def environment_spec(scene, folder: Path) -> dict:
    world = scene.world
    if world is None or world.hud.kind == "none":
        return {"type": "none"}
    h = world.hud
    if h.kind == "uniform":
        return {"type": "uniform", "luminance": h.luminance, "color": [float(c) for c in h.color]}
    if h.image is None:
        raise ValueError("World: an HDRI environment needs a panorama image")
    return {"type": "hdri", "file": _save_image(h.image, folder, "environment"),
            "calibration": {"mode": h.calibration, "value": h.value}, "rotation_deg": h.rotation_deg}


def export_scene(depsgraph, folder) -> Path:
    """Write the scene folder for ``depsgraph``'s scene; returns the folder."""
    scene = depsgraph.scene
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    unit_mm = _unit_mm(scene)
    objects = []
    for obj in scene.objects:
        if obj.type != "MESH" or obj.hud.role == "none" or not obj.visible_get():
            continue
        name = obj.name
        rel = f"meshes/{bpy.path.clean_name(name)}.obj"
        co, tri, uv = _mesh_arrays(obj, depsgraph, with_uv=any(f.kind == "image" for f in
                                                              MATERIALS[obj.hud.role].schema.fields))
        write_obj(folder / rel, co * unit_mm, tri, uv)
        entry = {"name": name, "mesh": rel, "transform": {"matrix": _matrix_mm(obj, unit_mm)},
                 "material": material_spec(obj, folder)}
        if obj.hud.smooth_normals:
            entry["smooth_normals"] = True
        emission = emission_spec(obj)
        if emission is not None:
            entry["emission"] = emission
        objects.append(entry)
    data = {"format": "hud-scene", "version": 1, "name": scene.name,
            "description": f"exported from Blender {bpy.app.version_string}",
            "eye": eye_spec(scene), "environment": environment_spec(scene, folder), "objects": objects,
            "methods": methods_spec(scene)}
    (folder / "scene.json").write_text(json.dumps(data, indent=2) + "\n")
    return folder
