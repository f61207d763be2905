"""Registering the add-on (hud_addon/__init__.py): unregister leaves nothing behind and the process exits.

Each scenario (a ``scenario_*`` function: the scene set up, rendered or exported inside the bpy module)
sits before the tests that assert on its result, and runs in a process of its own through
tests/addon/blender_runner.py (tests.support.addon.in_blender)."""

from __future__ import annotations

import tempfile
from pathlib import Path

import pytest

from tests.support.addon import in_blender, needs_bpy

pytestmark = [needs_bpy, pytest.mark.slow]


def scenario_unregister():
    import bpy

    from tests.support.blender import disable, enable_from_source, hud_names

    module = enable_from_source(bpy, Path(tempfile.mkdtemp()))
    before = hud_names()
    owners = (bpy.types.Scene, bpy.types.Object, bpy.types.Camera, bpy.types.World, bpy.types.Light)
    props_before = [hasattr(t, "hud") for t in owners]
    disable(module)
    props_after = [hasattr(t, "hud") for t in owners]
    engines = bpy.context.scene.render.bl_rna.properties["engine"].enum_items.keys()
    return {"before": before, "after": hud_names(), "props_before": props_before, "props_after": props_after,
            "engines": [e for e in ("HUD_TRACER",) if e in engines]}


def test_unregister_leaves_nothing_behind_and_the_process_exits():
    res, proc = in_blender(scenario_unregister, timeout=120)
    assert "HUD_OT_add_preset" in res["before"] and res["props_before"] == [True] * 5
    assert res["after"] == [] and res["props_after"] == [False] * 5
    assert res["engines"] == []
