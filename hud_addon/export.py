"""Blender data -> the tracer's scene format (tracer/scene/load.py), and nothing else.

Only objects with an optical role that a render shows are exported, as the depsgraph evaluates them
(:func:`exported_objects`: at its frame, modifiers applied, every instance an object of its own);
Blender units (the scene's unit scale) become millimetres. The active camera, as evaluated, is the
eye; the World's HUD settings are the environment, and a rendered Sun light its sun.
(:mod:`.messages` turns the tracer's errors about an exported folder back into the Blender objects and
properties they come from.)

An export is written as a set (:func:`export_scene`): first everything that can be checked in Blender
is checked (camera, images, aim objects) and the scene description is built with nothing written; then
every file goes into a hidden staging folder beside the target (:mod:`.export_files`), the staging
folder is checked, and only then it takes the target's place. A failure at any step leaves an earlier
export in the target exactly as it was.
"""

from __future__ import annotations

import json
import math
import shutil
import sys
import uuid
from collections.abc import Callable
from pathlib import Path

import bpy
import numpy as np

from ..tracer.optics.materials import MATERIALS
from ..tracer.products.outputs import replace_folder
from ..tracer.scene import ANALYSER
from ..tracer.scene.methods import METHOD_OPTIONS
from ..tracer.sources.lights import EMISSION
from ..tracer.sources.sun import SUN_MAX_ANGULAR_DIAMETER_DEG
from . import schema_ui
from .export_files import FileNames, Plan, check_replaceable, check_staged, mesh_writer, target_folder
from .units import unit_mm


def _mesh_arrays(evaluated, with_uv: bool):
    """(vertices (v, 3) local Blender units, faces (f, 3), uv (v, 2) or None) of an evaluated object's
    mesh (modifiers applied). With UVs every triangle corner gets its own vertex (UV seams stay exact)."""
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


def _matrix_mm(matrix, mm: float) -> list[list[float]]:
    """A world matrix (Blender units) with its translation in millimetres."""
    m = np.array(matrix, dtype=np.float64)
    m[:3, 3] *= mm
    return m.tolist()


def _aim_spec(obj, prefix: str) -> dict | None:
    """The aim block of the material (``prefix`` ""), its light aim ("light_") or the emission's
    ("emission_"), None when not aimed. Raises ValueError naming the object and the block when the aim
    object is not chosen."""
    h = obj.hud
    kind = getattr(h, f"{prefix}aim")
    if kind == "NONE":
        return None
    target = "eye" if kind == "EYE" else (getattr(h, f"{prefix}aim_object").name
                                         if getattr(h, f"{prefix}aim_object") else None)
    if target is None:
        block = {"": "aim", "light_": "light aim", "emission_": "emission aim"}[prefix]
        raise ValueError(f"object {obj.name!r}: {block}: aim at an object, but none is chosen")
    return {"target": target, "share": getattr(h, f"{prefix}aim_share"), "mode": getattr(h, f"{prefix}aim_mode")}


def material_spec(obj, plan: Plan, stem: str) -> dict:
    """The scene.json material block of an object from its HUD role and the role's schema fields;
    its images are checked and planned as textures named "<field>_<stem>" (made unique).
    Raises ValueError naming the object and the field."""
    h = obj.hud
    schema = MATERIALS[h.role].schema

    def save(image, f):
        return plan.image(image, f"{f.name}_{stem}", f.title)

    try:
        m = {"type": h.role} | schema_ui.export(h, schema.fields, "", schema.alternatives, save)
    except ValueError as e:
        raise ValueError(f"object {obj.name!r}: {e}") from None
    for key, prefix in (("aim", ""), ("light_aim", "light_")):
        aim = _aim_spec(obj, prefix) if schema.can_aim else None
        if aim is not None:
            m[key] = aim
    return m


def emission_spec(obj) -> dict | None:
    """The scene.json emission block of an object that emits, else None. Raises ValueError naming
    the object and the field."""
    h = obj.hud
    if not h.emits:
        return None
    try:
        e = schema_ui.export(h, EMISSION.fields, "emission_", EMISSION.alternatives)
    except ValueError as err:
        raise ValueError(f"object {obj.name!r}: emission: {err}") from None
    aim = _aim_spec(obj, "emission_")
    if aim is not None:
        e["aim"] = aim
    return e


def _json_field(text: str, where: str, kind: type):
    """A JSON text property's value, which must be a ``kind``; ValueError naming ``where`` otherwise."""
    try:
        value = json.loads(text)
    except json.JSONDecodeError as e:
        raise ValueError(f"{where}: not valid JSON ({e})") from None
    if not isinstance(value, kind):
        raise ValueError(f"{where}: expected a JSON {kind.__name__}")
    return value


def target_spec(scene) -> dict:
    """The target block of the optical analysis from the HUD Optics panel (eyebox, IPD, grids) and the
    rest of a preset's block (its Target text)."""
    h = scene.hud
    rest = _json_field(h.optics_target, "Render Properties > HUD Optics > Target", dict) if h.optics_target else {}
    return rest | {"eyebox_mm": list(h.optics_eyebox_mm), "ipd_mm": h.optics_ipd_mm,
                   "field_grid": list(h.optics_field_grid), "eye_grid": list(h.optics_eye_grid)}


def methods_spec(scene) -> dict:
    """Every method's options from the render settings (the folder renders the same with any method)."""
    out = {}
    for name, options in METHOD_OPTIONS.items():
        try:
            out[name] = schema_ui.export(scene.hud, options.fields, f"{name}_")
        except ValueError as e:  # where the panel shows it
            raise ValueError(f"Render Properties > HUD Tracer > {name.capitalize()} options > {e}") from None
    return out


def eye_spec(scene, depsgraph=None) -> dict:
    """The eye from the active camera, as ``depsgraph`` evaluates it (its frame: an animated camera
    moves the eye): position, gaze (-Z), up (+Y), field from lens and sensor; pupil, focus and the
    analyser (polarised sunglasses) from its HUD Eye settings. Raises ValueError when the scene has no
    active camera, or one the eye cannot be (orthographic or panoramic, or with a shifted lens),
    naming the camera."""
    cam = scene.camera
    if cam is None or cam.type != "CAMERA":
        raise ValueError("the scene needs an active camera: it is the eye")
    # Geometry and lens as evaluated; the HUD settings from the original (properties set from Python do
    # not always reach the evaluated copy).
    hud = cam.original.data.hud
    if depsgraph is not None:
        cam = cam.evaluated_get(depsgraph)
    mm = unit_mm(scene)
    r = scene.render
    w = max(1, int(r.resolution_x * r.resolution_percentage / 100))
    h = max(1, int(r.resolution_y * r.resolution_percentage / 100))
    cd = cam.data
    if cd.type != "PERSP":
        raise ValueError(f"camera {cam.name!r}: Lens > Type is {cd.type.title()}; the eye is a thin lens with a "
                         "perspective view: set the type to Perspective")
    if cd.shift_x or cd.shift_y:
        raise ValueError(f"camera {cam.name!r}: Lens > Shift is ({cd.shift_x:g}, {cd.shift_y:g}); the eye looks "
                         "along its axis: set the shift to 0 and turn the camera instead")
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
    acc = hud.accommodation_distance_mm
    eye = {"position": (mw[:3, 3] * mm).tolist(), "gaze": (-rot[:, 2]).tolist(), "up": rot[:, 1].tolist(),
           "pupil_diameter_mm": hud.pupil_diameter_mm, "focal_length_mm": hud.focal_length_mm,
           "accommodation_distance_mm": acc if acc > 0 else "infinity",
           "resolution": [w, h], "fov_deg": [math.degrees(2 * fx), math.degrees(2 * fy)]}
    eye["adaptation"] = hud.adaptation
    if hud.pupil in ("AUTO", "IMAGE"):
        eye.update(pupil_diameter_mm="auto", observer_age=hud.observer_age)
        if hud.pupil == "IMAGE":
            eye["adaptation_luminance_cd_m2"] = "image"
        elif hud.adaptation_luminance > 0:
            eye["adaptation_luminance_cd_m2"] = hud.adaptation_luminance
    eye |= schema_ui.export(hud, (ANALYSER,))  # "analyser": {...} when HUD Eye > Analyser is on
    return eye


def _sun_lights(depsgraph) -> list[dict]:
    """The Sun lights that ``depsgraph`` shows (the render visibility of :func:`exported_objects`;
    instances included, named "<light> @ <instancer>"), each as evaluated at the depsgraph's frame:
    {"name", "direction" (toward the sun: the light shines along its -Z axis, so the sun lies along its
    world +Z), "angle" (Blender's Angle, the disk's angular diameter, radians), "color", "illuminance_lux"
    (HUD Sun, from the original light: properties set from Python do not always reach the evaluated
    copy)}. Read while the depsgraph is iterated (an instance's evaluated data lives only as long)."""
    visible = None if depsgraph.mode == "RENDER" else render_visible(depsgraph.view_layer)
    suns, seen = [], set()

    def read(name, matrix, data, original_data):
        z = np.array(matrix, dtype=np.float64)[:3, 2]
        suns.append({"name": name, "direction": (z / np.linalg.norm(z)).tolist(), "angle": float(data.angle),
                     "color": [float(c) for c in data.color], "illuminance_lux": original_data.hud.illuminance_lux})

    for inst in depsgraph.object_instances:
        ob = inst.object
        if ob.type != "LIGHT" or ob.data.type != "SUN":
            continue
        original = ob.original
        owner = inst.parent.original if inst.is_instance and inst.parent is not None else original
        if visible is not None and owner.name not in visible:
            continue
        if not inst.is_instance:
            seen.add(original.name)
        read(f"{original.name} @ {owner.name}" if inst.is_instance else original.name, inst.matrix_world,
             ob.data, original.data)
    if visible is not None:  # hidden in the viewport only: not in the viewport's depsgraph, but rendered
        for obj in depsgraph.scene.objects:
            if obj.name in visible and obj.name not in seen and obj.type == "LIGHT" and obj.data.type == "SUN":
                read(obj.name, obj.matrix_world, obj.data, obj.data)
    return suns


def sun_spec(depsgraph) -> dict | None:
    """The scene.json sun block (tracer.sources.environment.Sun) of the one Sun light ``depsgraph`` shows, None
    without one: its direction (toward the sun, as evaluated: an animated sun moves), angular diameter
    (Blender's Angle), colour (the light's Color) and illuminance (HUD Sun > Illuminance). Blender's own
    Strength is not used: the tracer's sun is photometric. Raises ValueError naming the lights when more
    than one is rendered, and naming the light when its Angle is not that of a sun (0 < Angle <= 20 deg)."""
    suns = _sun_lights(depsgraph)
    if not suns:
        return None
    if len(suns) > 1:
        names = ", ".join(repr(s["name"]) for s in suns)
        raise ValueError(f"lights {names}: {len(suns)} Sun lights are rendered, and the environment has one sun: "
                         "disable all but one in renders, or delete them")
    sun = suns[0]
    diameter = math.degrees(sun["angle"])
    if not 0 < diameter <= SUN_MAX_ANGULAR_DIAMETER_DEG:
        raise ValueError(f"light {sun['name']!r}: Angle is {diameter:g}°; the sun is a disk of more than 0° and at "
                         f"most {SUN_MAX_ANGULAR_DIAMETER_DEG:g}° (0.53° for the real sun)")
    return {"direction": sun["direction"], "illuminance_lux": sun["illuminance_lux"],
            "angular_diameter_deg": diameter, "color": sun["color"]}


def environment_spec(scene, plan: Plan, depsgraph) -> dict:
    """The scene.json environment block from the World's HUD settings, with the sun of the rendered Sun
    light as ``depsgraph`` evaluates it (:func:`sun_spec`); an HDRI panorama is checked and planned as the
    texture "environment". Raises ValueError starting "World:" (with the image's file path when its file
    cannot be read), or naming the Sun lights at fault."""
    world = scene.world
    h = world.hud if world is not None else None
    if h is None or h.kind == "none":
        spec = {"type": "none"}
    elif h.kind == "uniform":
        spec = {"type": "uniform", "luminance": h.luminance, "color": [float(c) for c in h.color]}
    elif h.image is None:
        raise ValueError("World: an HDRI environment needs a panorama image")
    else:
        spec = {"type": "hdri", "file": plan.image(h.image, "environment", "World: HDRI"),
                "calibration": {"mode": h.calibration, "value": h.value}, "rotation_deg": h.rotation_deg}
    sun = sun_spec(depsgraph)
    if sun is not None:
        spec["sun"] = sun
    return spec


def _mesh_stems(items) -> dict[str, str]:
    """A unique file stem per exported object name (see _FileNames). Names that are already clean
    claim first, then the others, each group by name: "m_a" keeps m_a, "m.a" gets m_a-2, whatever the
    order of the objects in the scene."""
    names = FileNames()
    order = sorted((i.name for i in items), key=lambda n: (bpy.path.clean_name(n) != n, n))
    return {n: names.claim(n) for n in order}


def render_visible(view_layer) -> set[str]:
    """Names of the objects a render of ``view_layer`` shows, as Blender decides for renders: the
    object's own "Disable in Renders" (hide_render) unset, in a collection that is neither excluded
    from the view layer nor disabled in renders anywhere above it. Hiding in the viewport (the eye
    icon, hide_viewport) does not matter: it is for the viewport."""
    names: set[str] = set()

    def walk(layer_collection, hidden: bool):
        if layer_collection.exclude:
            return
        hidden = hidden or bool(getattr(layer_collection.collection, "hide_render", False))
        if not hidden:
            names.update(o.name for o in layer_collection.collection.objects if not o.hide_render)
        for child in layer_collection.children:
            walk(child, hidden)

    walk(view_layer.layer_collection, False)
    return names


class _Item:
    """One exported object: the original (its HUD settings), its name in scene.json, its world matrix
    and the key of its mesh (instances of one mesh share it)."""

    def __init__(self, original, name: str, matrix, mesh_key):
        self.original, self.name, self.matrix, self.mesh_key = original, name, matrix, mesh_key


def _needs_uv(obj) -> bool:
    return any(f.kind == "image" for f in MATERIALS[obj.hud.role].schema.fields)


def _role_on_non_mesh(obj):
    raise ValueError(f"object {obj.name!r}: has the optical role {obj.hud.role!r} but is a {obj.type.title()}, not a "
                     "mesh: convert it (Object > Convert > Mesh) or set its role to None")


def exported_objects(depsgraph) -> tuple[list[_Item], dict]:
    """The objects with an optical role that ``depsgraph`` shows, as evaluated:
    at the depsgraph's frame (animation), with modifiers applied, and with every instance
    (collection instances, geometry-node and particle instances) as an object of its own, named
    "<object> @ <instancer> <k>". Returns the items and {mesh key: (vertices, faces, uv) in Blender
    units}, extracted now (an instance's evaluated data lives only while the depsgraph is iterated).

    Visibility is Blender's for renders: a render depsgraph (F12, hud-render, ``blender -a``) holds
    what the render shows; for the viewport's depsgraph (the export operator), objects disabled in
    renders or in collections disabled in renders or excluded are left out, and objects hidden only
    in the viewport are added (:func:`render_visible`). Raises ValueError naming an object with a role
    that is not a mesh, or whose mesh has no faces."""
    scene = depsgraph.scene
    visible = None if depsgraph.mode == "RENDER" else render_visible(depsgraph.view_layer)
    items: list[_Item] = []
    meshes: dict = {}
    counts: dict = {}
    seen: set[str] = set()

    def mesh_of(evaluated, original) -> object:
        key = (evaluated.data.as_pointer() if evaluated.data is not None else id(evaluated), _needs_uv(original))
        if key not in meshes:
            co, tri, uv = _mesh_arrays(evaluated, key[1])
            if len(tri) == 0:
                raise ValueError(f"object {original.name!r}: the mesh has no faces")
            meshes[key] = (co, tri, uv)
        return key

    for inst in depsgraph.object_instances:
        original = inst.object.original
        if original.hud.role == "none":
            continue
        owner = inst.parent.original if inst.is_instance and inst.parent is not None else original
        if visible is not None and owner.name not in visible:
            continue
        if inst.object.type != "MESH":
            _role_on_non_mesh(original)
        if inst.is_instance:
            k = counts[(original.name, owner.name)] = counts.get((original.name, owner.name), 0) + 1
            name = f"{original.name} @ {owner.name} {k}"
        else:
            name = original.name
            seen.add(name)
        items.append(_Item(original, name, inst.matrix_world.copy(), mesh_of(inst.object, original)))
    if visible is not None:  # hidden in the viewport only: not in the viewport's depsgraph, but rendered
        for obj in scene.objects:
            if obj.name in visible and obj.name not in seen and obj.hud.role != "none" and obj.type != "EMPTY":
                if obj.type != "MESH":
                    _role_on_non_mesh(obj)
                items.append(_Item(obj, obj.name, obj.matrix_world.copy(), mesh_of(obj.evaluated_get(depsgraph), obj)))
    names = [i.name for i in items]
    if len(set(names)) != len(names):
        dup = sorted({n for n in names if names.count(n) > 1})
        raise ValueError(f"object {dup[0]!r}: two exported objects have this name (rename the object)")
    return items, meshes


def export_scene(depsgraph, folder, check: Callable[[Path], object] | None = None) -> Path:
    """Write the scene folder for ``depsgraph``'s scene into ``folder``; returns ``folder``.

    ``check(staging_folder)``, when given, is run on the complete staged export before it takes the
    folder's place (the operator passes the tracer's ``load_scene``, so that a folder that would not
    render never replaces one that does); whatever it raises aborts the export.

    Guarantees:

    - The folder is written as a set: it is either the complete new export (scene.json and every
      mesh and texture it references, nothing else) or, after any failure, exactly what it was
      before (an earlier export byte for byte, or absent). No hidden staging or backup folder
      (".<name>.staging-<id>", ".<name>.backup-<id>" beside it) is left behind.
    - Everything Blender can tell is checked before any file is written: the active camera, every
      image (present, and a file-backed image's file readable), aim objects chosen. A scene that
      cannot be exported raises ValueError naming the object (or "World") and the field, and for an
      image file its path; a file system failure raises OSError.
    - Every object gets its own mesh file, every image its own texture file: readable names
      (``bpy.path.clean_name``), made unique case-insensitively by "-2", "-3", ... (see _mesh_stems).
    - ``folder`` may not hold anything but an earlier export (ValueError, and nothing is touched):
      it is replaced as a whole.
    """
    scene = depsgraph.scene
    target = target_folder(folder)
    check_replaceable(target)
    mm = unit_mm(scene)
    plan = Plan()
    eye = eye_spec(scene, depsgraph)
    environment = environment_spec(scene, plan, depsgraph)
    items, meshes = exported_objects(depsgraph)
    stems = _mesh_stems(items)
    mesh_files: dict = {}
    objects = []
    for item in items:
        obj = item.original
        if item.mesh_key not in mesh_files:
            co, tri, uv = meshes[item.mesh_key]
            mesh_files[item.mesh_key] = plan.add(f"meshes/{stems[item.name]}.obj", mesh_writer(co, tri, uv, mm))
        entry = {"name": item.name, "mesh": mesh_files[item.mesh_key],
                 "transform": {"matrix": _matrix_mm(item.matrix, mm)},
                 "material": material_spec(obj, plan, stems[item.name])}
        if obj.hud.smooth_normals:
            entry["smooth_normals"] = True
        if obj.hud.surfaces:
            entry["surfaces"] = _json_field(obj.hud.surfaces, f"object {item.name!r}: HUD Optical Role > Exact "
                                                               "surfaces", list)
        emission = emission_spec(obj)
        if emission is not None:
            entry["emission"] = emission
        objects.append(entry)
    data = {"format": "hud-scene", "version": 1, "name": scene.name,
            "description": f"exported from Blender {bpy.app.version_string}",
            "eye": eye, "environment": environment, "objects": objects,
            "polarisation": scene.hud.polarisation, "methods": methods_spec(scene), "target": target_spec(scene)}
    text = json.dumps(data, indent=2) + "\n"

    target.parent.mkdir(parents=True, exist_ok=True)
    staging = target.parent / f".{target.name}.staging-{uuid.uuid4().hex}"
    staging.mkdir()
    try:
        plan.write(staging)
        (staging / "scene.json").write_text(text, encoding="utf-8")
        check_staged(staging, target, plan.files)
        if check is not None:
            check(staging)
        leftover = replace_folder(staging, target)
    except BaseException:
        shutil.rmtree(staging, ignore_errors=True)
        raise
    if leftover is not None:
        print(f"HUD export: written to {target}, but the earlier export's copy {leftover} could not be removed",
              file=sys.stderr)
    return Path(folder)


