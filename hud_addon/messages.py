"""The tracer's errors about an exported folder in Blender's words: the object (or World, camera,
image) and the property at fault, never the temporary scene.json and its JSON path; and warnings of
what Blender will lose when the .blend is opened again."""

from __future__ import annotations

import json
import re
from pathlib import Path

import bpy

from ..tracer.optics.materials import MATERIALS
from ..tracer.scene import ANALYSER
from ..tracer.scene.methods import METHOD_OPTIONS

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
    elif field.startswith("target"):
        key = field[len("target"):].lstrip(".").split("[")[0]
        shown = {"eyebox_mm": "Eyebox", "ipd_mm": "IPD", "field_grid": "Field grid", "eye_grid": "Eye grid"}
        where = "Render Properties > HUD Optics > " + shown.get(key, f"Target ({key})" if key else "Target")
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


def dark_scene_hint(scene) -> str:
    """For a render with no light source, in Blender's terms: the lights Blender shows that the tracer
    does not take (all but Sun lights) and the meshes left out for want of an optical role ("" where
    there are none)."""
    from .export import render_visible
    from .operators import LIGHT_PATHS_TAG

    visible = render_visible(bpy.context.view_layer)
    shown = [o for o in scene.objects if o.name in visible]
    lights = [o for o in shown if o.type == "LIGHT" and o.data.type != "SUN"]
    plain = [o.name for o in shown if o.type == "MESH" and o.hud.role == "none" and not o.get(LIGHT_PATHS_TAG)]
    parts = []
    if lights:
        names = ", ".join(f"{o.data.type.title()} light {o.name!r}" for o in lights[:3])
        parts.append(f"{names}{' and more' if len(lights) > 3 else ''} {'is' if len(lights) == 1 else 'are'} not "
                     "exported: the tracer's light sources are meshes that emit (Render Properties > HUD Tracer > "
                     "Add Lamp, or Object > HUD Optical Role > Emits light), Sun lights and the World")
    if plain:
        names = ", ".join(repr(n) for n in plain[:3]) + (f" and {len(plain) - 3} more" if len(plain) > 3 else "")
        one = len(plain) == 1
        parts.append(f"{names} {'has' if one else 'have'} no optical role (Object > HUD Optical Role) and "
                     f"{'is' if one else 'are'} left out")
    return "; ".join(parts)
