"""Runs one add-on scenario inside the bpy 4.5 module, one scenario per process: bpy is imported once per
process and hangs at exit while a Python render engine is registered, so every scenario disables the add-on
before it returns. Usage: ``python tests/addon/blender_runner.py TEST_MODULE FUNCTION [ARG ...]``, with
TEST_MODULE the path of the test module that holds the scenario (tests.support.addon.in_blender passes it);
prints the function's result as one line "HUD_RESULT <json>"."""

from __future__ import annotations

import atexit
import importlib
import json
import os
import shutil
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
# Blender's user resources (about 100 MB once bpy starts): removed at exit, after the scenario's own exit
# handlers (registered later, run first), or every scenario of every test run stays in the temp folder
os.environ["BLENDER_USER_RESOURCES"] = _USER = tempfile.mkdtemp(prefix="hud-bpy-user-")
atexit.register(shutil.rmtree, _USER, ignore_errors=True)
sys.path.insert(0, str(ROOT))

import bpy  # noqa: E402, F401  (the environment above must be set first)

from hud_addon.batch import enable_from_source  # noqa: E402, F401


def run(path: str, name: str, *args: str):
    """Import the test module at ``path`` by its name under the repository (tests.addon.test_...) and call
    its function ``name`` with ``args``."""
    module = importlib.import_module(".".join(Path(path).resolve().relative_to(ROOT).with_suffix("").parts))
    return getattr(module, name)(*args)


if __name__ == "__main__":
    result = run(*sys.argv[1:])
    print("HUD_RESULT " + json.dumps(result), flush=True)
