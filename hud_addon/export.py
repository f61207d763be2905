"""Blender data -> the tracer's scene format (tracer/scene/load.py), and nothing else.

Only objects with an optical role that a render shows are exported, as the depsgraph evaluates them
(:func:`exported_objects`: at its frame, modifiers applied, every instance an object of its own);
Blender units (the scene's unit scale) become millimetres. The active camera, as evaluated, is the
eye; the World's HUD settings are the environment, and a rendered Sun light its sun.
:func:`blender_terms` turns the tracer's errors
about an exported folder back into the Blender objects and properties they come from.

An export is written as a set (:func:`export_scene`): first everything that can be checked in Blender
is checked (camera, images, aim objects) and the scene description is built with nothing written; then
every file goes into a hidden staging folder beside the target, the staging folder is checked, and only
then it takes the target's place. A failure at any step leaves an earlier export in the target exactly
as it was.
"""

from __future__ import annotations

import json
import math
import os
import re
import shutil
import sys
import uuid
from collections.abc import Callable
from pathlib import Path

import bpy
import numpy as np

from ..presets._build import write_obj
from ..tracer.core.imageio import write_exr
from ..tracer.optics.materials import MATERIALS
from ..tracer.products.outputs import replace_folder
from ..tracer.scene import ANALYSER
from ..tracer.scene.methods import METHOD_OPTIONS
from ..tracer.sources.lights import EMISSION
from ..tracer.sources.sun import SUN_MAX_ANGULAR_DIAMETER_DEG
from . import schema_ui
from .units import unit_mm

#: What an export folder holds; a folder holding anything else is not replaced (see _check_replaceable).
EXPORT_ENTRIES = frozenset({"scene.json", "meshes", "textures"})
#: Files the file manager of an OS puts into any folder it shows: replaced along with an export.
_OS_FILES = frozenset({".DS_Store", "Thumbs.db", "desktop.ini"})
#: File names Windows refuses whatever their extension.
_WINDOWS_RESERVED = frozenset({"CON", "PRN", "AUX", "NUL", *(f"COM{i}" for i in range(1, 10)),
                               *(f"LPT{i}" for i in range(1, 10))})


class _FileNames:
    """Unique, readable file stems within one folder of the export.

    A stem is the name made safe for file systems (``bpy.path.clean_name``); when that stem is taken,
    "-2", "-3", ... is appended. Stems are compared case-insensitively, so that no two files of an
    export collide on the case-insensitive file systems of Windows and macOS either. The same claims
    in the same order give the same stems.
    """

    def __init__(self):
        self._taken: set[str] = set()

    def claim(self, name: str) -> str:
        base = bpy.path.clean_name(name) or "unnamed"
        if base.upper() in _WINDOWS_RESERVED:
            base += "_"
        stem, k = base, 1
        while stem.casefold() in self._taken:
            k += 1
            stem = f"{base}-{k}"
        self._taken.add(stem.casefold())
        return stem


class _Plan:
    """The files of one export, each checked when it is planned and written only by :meth:`write`.

    ``files`` maps a path relative to the export folder to the function that writes it (given the
    absolute path to write to).
    """

    def __init__(self):
        self.files: dict[str, Callable[[Path], None]] = {}
        self.textures = _FileNames()

    def add(self, rel: str, write: Callable[[Path], None]) -> str:
        assert rel not in self.files, rel  # stems are unique
        self.files[rel] = write
        return rel

    def image(self, image, name: str, what: str) -> str:
        """Plan a texture file for ``image`` named after ``name`` (made unique); returns its path
        relative to the folder. Raises ValueError, naming ``what``, the image and, for an image
        kept in a file, the file's path, when the image cannot be read."""
        suffix, write = _image_writer(image, what)
        return self.add(f"textures/{self.textures.claim(name)}{suffix}", write)

    def write(self, folder: Path):
        """Write every planned file under ``folder``."""
        for rel, write in self.files.items():
            path = folder / rel
            path.parent.mkdir(parents=True, exist_ok=True)
            write(path)


def _image_writer(image, what: str) -> tuple[str, Callable[[Path], None]]:
    """(file suffix, write(path)) of an image, checked now: an image kept in a file (not packed) is
    copied as it is, and that file must exist and be readable; a packed or generated image is
    written as EXR with its pixel values as stored, and must have pixels.

    Raises ValueError "<what> image '<name>' cannot be read: <path> (<reason>)" or
    "<what> image '<name>' has no pixels".
    """
    label = f"{what} image {image.name!r}"
    raw = image.filepath_raw or image.filepath
    src = Path(bpy.path.abspath(raw)) if raw else None
    from_file = image.packed_file is None and src is not None and (image.source == "FILE" or src.is_file())
    if from_file:
        reason = None
        if not src.exists():
            reason = "file not found"
        elif not src.is_file():
            reason = "not a file"
        else:
            try:
                with open(src, "rb") as fh:
                    if not fh.read(1):
                        reason = "empty file"
            except OSError as e:
                reason = e.strerror or str(e)
        if reason is not None:
            raise ValueError(f"{label} cannot be read: {src} ({reason})")
        return src.suffix.lower(), lambda path: shutil.copyfile(src, path)
    w, h = image.size
    if w == 0 or h == 0:
        raise ValueError(f"{label} has no pixels")

    def write(path: Path):
        px = np.empty(w * h * image.channels, dtype=np.float32)
        image.pixels.foreach_get(px)
        px = px.reshape(h, w, image.channels)[::-1]  # Blender's row 0 is the bottom row
        rgb = px[..., :3] if image.channels >= 3 else np.repeat(px[..., :1], 3, axis=2)
        write_exr(path, {"R": rgb[..., 0], "G": rgb[..., 1], "B": rgb[..., 2]})

    return ".exr", write


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


def _mesh_writer(co: np.ndarray, tri: np.ndarray, uv, mm: float) -> Callable[[Path], None]:
    """write(path) of a mesh's arrays as OBJ in millimetres."""
    return lambda path: write_obj(path, co * mm, tri, uv)


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


def material_spec(obj, plan: _Plan, stem: str) -> dict:
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


def environment_spec(scene, plan: _Plan, depsgraph) -> dict:
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
    names = _FileNames()
    order = sorted((i.name for i in items), key=lambda n: (bpy.path.clean_name(n) != n, n))
    return {n: names.claim(n) for n in order}


def _image_fields(block: dict, fields) -> list[str]:
    """The image paths of a (material) block, groups included."""
    out = []
    for f in fields:
        if f.name in block and f.kind == "image":
            out.append(block[f.name])
        elif f.name in block and f.kind == "group":
            out += _image_fields(block[f.name], f.fields)
    return out


def _check_staged(staging: Path, target: Path, planned) -> None:
    """Raise ValueError unless scene.json in ``staging`` parses and every file it references, and
    every planned file, exists there and is not empty."""
    try:
        data = json.loads((staging / "scene.json").read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as e:
        raise ValueError(f"the export to {target} could not be checked: scene.json: {e}") from None
    refs = set(planned)
    for o in data["objects"]:
        refs.add(o["mesh"])
        refs.update(_image_fields(o["material"], MATERIALS[o["material"]["type"]].schema.fields))
    if "file" in data["environment"]:
        refs.add(data["environment"]["file"])
    bad = [rel for rel in sorted(refs) if not (staging / rel).is_file() or (staging / rel).stat().st_size == 0]
    if bad:
        raise ValueError(f"the export to {target} is incomplete: {', '.join(bad)} missing or empty")


def _target_folder(folder) -> Path:
    """The absolute folder an export replaces: a symbolic link is followed (the link stays valid)."""
    target = Path(os.path.abspath(folder))
    if target.is_symlink():
        target = Path(os.path.realpath(target))
    if not target.name:
        raise ValueError(f"cannot export into {target}: choose a folder (it is replaced as a whole)")
    return target


def _check_replaceable(target: Path) -> None:
    """Raise ValueError unless ``target`` is absent, empty, or an earlier export (scene.json, meshes/,
    textures/ and nothing else): an export replaces its folder as a whole, and must never take a
    user's other files with it."""
    if not target.exists():
        return
    if not target.is_dir():
        raise ValueError(f"cannot export into {target}: it is a file, not a folder")
    entries = {p.name for p in target.iterdir()} - _OS_FILES
    if not entries:
        return
    foreign = sorted(entries - EXPORT_ENTRIES)
    if foreign or "scene.json" not in entries:
        what = ", ".join(foreign[:5]) + (", ..." if len(foreign) > 5 else "") if foreign else "no scene.json"
        raise ValueError(f"cannot export into {target}: it holds files that are not a HUD scene export ({what}); "
                         "choose an empty or new folder, or an earlier export (an export replaces its folder as a "
                         "whole)")


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
    target = _target_folder(folder)
    _check_replaceable(target)
    mm = unit_mm(scene)
    plan = _Plan()
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
            mesh_files[item.mesh_key] = plan.add(f"meshes/{stems[item.name]}.obj", _mesh_writer(co, tri, uv, mm))
        entry = {"name": item.name, "mesh": mesh_files[item.mesh_key],
                 "transform": {"matrix": _matrix_mm(item.matrix, mm)},
                 "material": material_spec(obj, plan, stems[item.name])}
        if obj.hud.smooth_normals:
            entry["smooth_normals"] = True
        emission = emission_spec(obj)
        if emission is not None:
            entry["emission"] = emission
        objects.append(entry)
    data = {"format": "hud-scene", "version": 1, "name": scene.name,
            "description": f"exported from Blender {bpy.app.version_string}",
            "eye": eye, "environment": environment, "objects": objects,
            "polarisation": scene.hud.polarisation, "methods": methods_spec(scene)}
    text = json.dumps(data, indent=2) + "\n"

    target.parent.mkdir(parents=True, exist_ok=True)
    staging = target.parent / f".{target.name}.staging-{uuid.uuid4().hex}"
    staging.mkdir()
    try:
        plan.write(staging)
        (staging / "scene.json").write_text(text, encoding="utf-8")
        _check_staged(staging, target, plan.files)
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


#: The export's own relative file names at the start of a tracer message ("'textures/x.exr': ...").
_EXPORT_FILE = re.compile(r"^'?(?:textures|meshes)/[^':]*'?:\s*")


#: The Blender terms of the fields of the environment's sun block.
_SUN_TERMS = {"direction": "rotation", "illuminance_lux": "HUD Sun > Illuminance", "angular_diameter_deg": "Angle",
              "color": "Color"}
#: World > HUD Environment's labels of the environment block's fields (the image's own: "file").
_ENVIRONMENT_TERMS = {"type": "Environment", "luminance": "Luminance", "color": "Color",
                      "calibration": "Calibration", "calibration.mode": "Calibration",
                      "calibration.value": "Value", "rotation_deg": "Rotation"}


#: How the tracer says, in scene.json's terms, that an element needs polarisation on (tracer.scene).
_POLARISATION_OFF = re.compile(r'remove "polarisation": "off"(?: \(or this block\))?')


def _image_hint(image) -> str:
    """Why a generated image may hold none of the pixels the user made: only where Blender has
    regenerated it (it is not dirty: not painted or filled since it was made or the file was opened);
    an image whose pixels are in memory, and wrong, gets no hint."""
    if image is not None and image.source == "GENERATED" and image.packed_file is None and not image.is_dirty:
        return (f" (image {image.name!r} is a generated image that is not packed: Blender does not save its pixels "
                "with the .blend and regenerates them when the file is opened; pack it with Image > Pack, or save it "
                "to a file)")
    return ""


def _in_blender_words(message: str) -> str:
    """The tracer's scene.json wording of a message, as a Blender user meets the same things."""
    def no_object(m):
        name = json.loads(m.group(1))
        if name in bpy.data.objects:
            obj = bpy.data.objects[name]
            why = ("the camera (the eye itself), not an object the rays meet" if obj.type == "CAMERA"
                   else "an object the render does not see: give it a HUD Optical Role (and leave it enabled in "
                        "renders)")
            return f"{name!r} is {why}"
        return f"no object named {name!r}"
    message = re.sub(r'no object named ("(?:[^"\\]|\\.)*")(?: \(or use "eye"\))?', no_object, message)
    return message.replace("an LCD needs texture coordinates (an OBJ with vt lines)",
                           "an LCD needs texture coordinates: add a UV map (Object Data Properties > UV Maps)")


def blender_terms(error, folder: Path, scene) -> str:
    """A tracer SceneError about an exported scene folder, in Blender's terms: the object, World or
    camera and the property at fault instead of the temporary scene.json and its JSON path, with a hint
    where a generated image lost its pixels."""
    try:
        data = json.loads((Path(folder) / "scene.json").read_text(encoding="utf-8"))
    except (OSError, ValueError):
        data = {}
    field, message = error.field, _EXPORT_FILE.sub("", error.message)
    message = _POLARISATION_OFF.sub("set Render Properties > HUD Tracer > Polarisation to Auto (or change this)",
                                    message)
    m = re.match(r"objects\[(\d+)\](?:\.(\w+))?(?:\.(\w+))?", field)
    hint = ""
    if m and int(m.group(1)) < len(data.get("objects", [])):
        entry = data["objects"][int(m.group(1))]
        name, block, key = entry["name"], m.group(2), m.group(3)
        original = bpy.data.objects.get(name.split(" @ ")[0])
        where = f"object {name!r}"
        if block == "material" and key:
            schema = MATERIALS[entry["material"]["type"]].schema
            f = next((f for f in schema.fields if f.name == key), None)
            where += f": {f.title if f else 'HUD Optical Role' if key == 'type' else key}"
            if f is not None and f.kind == "image" and original is not None:
                hint = _image_hint(getattr(original.hud, key, None))
        elif block == "emission":
            where += f": emission{': ' + key if key else ''}"
        elif block:
            where += f": {block}"
    elif field.startswith("environment.sun"):
        suns = [o.name for o in scene.objects if o.type == "LIGHT" and o.data.type == "SUN" and not o.hide_render]
        where = f"light {suns[0]!r}" if len(suns) == 1 else "the Sun light"
        key = field[len("environment.sun"):].lstrip(".").split("[")[0]
        where += ": " + _SUN_TERMS.get(key, "HUD Sun")
    elif field.startswith("environment"):
        world = scene.world
        image = world.hud.image if world is not None else None
        where = f"World {world.name!r}" if world is not None else "World"
        key = field[len("environment"):].lstrip(".").split("[")[0]
        if key in ("", "file") and image is not None:  # the panorama itself: its file or pixels
            where += f": HDRI image {image.name!r}"
            hint = _image_hint(image)
        elif key in _ENVIRONMENT_TERMS:
            where += f": HUD Environment > {_ENVIRONMENT_TERMS[key]}"
    elif field.startswith("eye"):
        where = f"camera {scene.camera.name!r}" if scene.camera is not None else "camera"
        if field == "eye.fov_deg":
            where += ": Lens and Sensor (the field of view they give)"
        if field.startswith("eye.analyser"):
            key = field[len("eye.analyser"):].lstrip(".")
            f = next((f for f in ANALYSER.fields if f.name == key), None)
            where += f": HUD Eye > {ANALYSER.title}" + (f" > {f.title}" if f is not None else "")
    elif field == "polarisation":
        where = "Render Properties > HUD Tracer > Polarisation"
    elif field.startswith("methods."):
        method, _, option = field[len("methods."):].partition(".")
        where = f"Render Properties > HUD Tracer > {method.capitalize()} options"
        fields = METHOD_OPTIONS[method].fields if method in METHOD_OPTIONS else ()
        for key in filter(None, option.split(".")):  # the panel's labels, down nested groups (exit pupil)
            f = next((f for f in fields if f.name == key.split("[")[0]), None)
            where += f" > {f.label or key if f is not None else key}"
            fields = f.fields if f is not None and f.fields else ()
    else:
        where = field or "scene"
    return f"{where}: {_in_blender_words(message)}{hint}"


def generated_image_warnings(scene) -> list[str]:
    """Images the render uses whose pixels will not survive saving and opening the .blend again: generated
    images that are neither packed nor saved, but were painted or filled (their pixels differ from what
    Blender would regenerate)."""
    images = []
    if scene.world is not None and scene.world.hud.kind == "hdri" and scene.world.hud.image is not None:
        images.append(("World: HDRI", scene.world.hud.image))
    for obj in scene.objects:
        if obj.hud.role != "none":
            for f in MATERIALS[obj.hud.role].schema.fields:
                img = getattr(obj.hud, f.name, None) if f.kind == "image" else None
                if img is not None:
                    images.append((f"object {obj.name!r}: {f.title}", img))
    return [f"{what} image {img.name!r} is generated and not packed: its pixels are lost when the .blend is saved "
            "and opened again; pack it (Image > Pack) or save it to a file"
            for what, img in images if img.source == "GENERATED" and img.packed_file is None and img.is_dirty]
