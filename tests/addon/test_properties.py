"""The add-on's properties (hud_addon/properties.py): every property has a tooltip.

Each scenario (a ``scenario_*`` function: the scene set up, rendered or exported inside the bpy module)
sits before the tests that assert on its result, and runs in a process of its own through
tests/addon/blender_runner.py (tests.support.addon.in_blender)."""

from __future__ import annotations

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
