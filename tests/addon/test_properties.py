"""The add-on's properties (hud_addon/properties.py): every property has a tooltip.

Each scenario (a ``scenario_*`` function: the scene set up, rendered or exported inside the bpy module)
sits before the tests that assert on its result, and runs in a process of its own through
tests/addon/blender_runner.py (tests.support.addon.in_blender)."""

from __future__ import annotations

import math
import tempfile
from pathlib import Path

import pytest

from tests.support.addon import in_blender, needs_bpy

pytestmark = [needs_bpy, pytest.mark.slow]


def scenario_tooltips():
    """Every property of the add-on's property groups, as registered, with its description."""
    import bpy

    from tests.support.blender import disable, enable_from_source

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


def test_every_property_has_a_tooltip():
    """Every property of the add-on's property groups has a description."""
    res, _ = in_blender(scenario_tooltips)
    assert len(res["groups"]) >= 3, res["groups"]
    assert res["missing"] == [], res["missing"]


def scenario_role_starting_values(out):
    """Objects given roles by hand, as a user picks them in the Object > HUD Optical Role panel."""
    import json

    import bpy

    from tests.support.blender import disable, enable_from_source

    module = enable_from_source(bpy, Path(tempfile.mkdtemp()))
    made = {}
    for name, roles, touched in (("coating", ["coating"], None), ("screen", ["lambertian_transmitter"], None),
                                 ("back", ["coating", "mirror"], None), ("kept", ["mirror", "coating"], 0.5)):
        bpy.ops.mesh.primitive_plane_add(size=0.1)
        obj = bpy.context.object
        obj.name = name
        for k, role in enumerate(roles):
            obj.hud.role = role
            if k == 0 and touched is not None:
                obj.hud.reflectance = (touched,) * 3  # the user's own value survives the next role
        made[name] = {"reflectance": list(obj.hud.reflectance), "transmittance": list(obj.hud.transmittance)}
    bpy.data.objects["kept"].hud.role = "none"  # R 0.5 + T 0.7: refused, as it should be; left out here
    exported = bpy.ops.hud.export_scene(directory=str(Path(out) / "scene"))
    scene = json.loads((Path(out) / "scene" / "scene.json").read_text())
    disable(module)
    return {"made": made, "exported": sorted(exported),
            "materials": {o["name"]: o["material"] for o in scene["objects"]}}


def test_a_role_chosen_by_hand_starts_from_values_it_accepts(tmp_path):
    """Issue 31's second walk-through: a Coated partial reflector and a Diffuse screen chosen in the panel
    were refused at their own starting values ("reflectance + transmittance must not exceed 1"): every
    role shares one Reflectance and one Transmittance, which started at the mirror's 0.9. A role now
    starts from its own values where the object holds the values of the role before it; a value the
    user set is kept."""
    res, _ = in_blender(scenario_role_starting_values, tmp_path)
    made = res["made"]
    assert made["coating"]["reflectance"] == pytest.approx([0.25] * 3) and \
        made["coating"]["transmittance"] == pytest.approx([0.7] * 3)
    assert made["screen"]["reflectance"] == pytest.approx([0.0] * 3) and \
        made["screen"]["transmittance"] == pytest.approx([0.9] * 3)
    assert made["back"]["reflectance"] == pytest.approx([0.9] * 3)  # the coating's start, so the mirror's
    assert made["kept"]["reflectance"] == pytest.approx([0.5] * 3) and \
        made["kept"]["transmittance"] == pytest.approx([0.7] * 3)
    assert res["exported"] == ["FINISHED"], res
    m = res["materials"]
    assert m["coating"]["type"] == "coating" and m["coating"]["reflectance"] == pytest.approx([0.25] * 3)
    assert m["screen"]["type"] == "lambertian_transmitter" and m["screen"]["transmittance"] == pytest.approx([0.9] * 3)
    assert m["back"]["type"] == "mirror"


def scenario_reset_twins():
    """The twins a panel shows in the scene's units, each set away from its default, then set to its
    declared default as Blender's Reset to Default Value does."""
    import bpy

    from tests.support.blender import disable, enable_from_source

    module = enable_from_source(bpy, Path(tempfile.mkdtemp()))
    cam, s = bpy.context.scene.camera.data.hud, bpy.context.scene.hud
    out = {}
    for owner, twin, stored, value in ((cam, "pupil_diameter_mm_shown", "pupil_diameter_mm", 0.003),
                                       (cam, "focal_length_mm_shown", "focal_length_mm", 0.02),
                                       (s, "eyebox_field_deg_shown", "eyebox_field_deg", (0.2, 0.1))):
        setattr(owner, twin, value)
        moved = getattr(owner, stored)
        prop = owner.bl_rna.properties[twin]
        setattr(owner, twin, tuple(prop.default_array) if prop.is_array else prop.default)
        out[stored] = {"moved": list(moved) if prop.is_array else moved,
                       "reset": list(getattr(owner, stored)) if prop.is_array else getattr(owner, stored)}
    s.eyebox_field_deg_shown = (0.2, 0.1)
    s.eyebox_field_deg_shown = (math.nan, 0.1)  # Reset Single Value: one component
    out["one component"] = list(s.eyebox_field_deg)
    bpy.ops.mesh.primitive_plane_add(size=0.1)
    h = bpy.context.object.hud
    h.role = "coating"
    h.reflectance_grey = 0.5  # the single number the panel shows for a grey factor
    h.reflectance_grey = h.bl_rna.properties["reflectance_grey"].default
    out["coating grey"] = list(h.reflectance)
    disable(module)
    return out


def test_reset_to_default_of_a_field_in_the_scenes_units_gives_its_default():
    """A second walk-through: the fields shown in the scene's units declared no default, so Reset to
    Default Value set them to 0: a pupil of 0.01 mm (its minimum), a focal length of 0.1 mm, with no
    warning. Resetting one now gives the stored property's own default."""
    res, _ = in_blender(scenario_reset_twins)
    assert res["pupil_diameter_mm"]["moved"] == pytest.approx(3.0) and \
        res["pupil_diameter_mm"]["reset"] == pytest.approx(4.0)
    assert res["focal_length_mm"]["moved"] == pytest.approx(20.0) and \
        res["focal_length_mm"]["reset"] == pytest.approx(16.67)
    assert res["eyebox_field_deg"]["reset"] == pytest.approx([6.0, 2.0])
    assert res["one component"] == pytest.approx([6.0, math.degrees(0.1)])  # the other component kept
    # the single Reflectance number of a coating resets to the coating's start, not 0 (a black mirror) nor
    # the 0.9 every role's shared property declares
    assert res["coating grey"] == pytest.approx([0.25] * 3)
