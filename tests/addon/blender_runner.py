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
# Every temp folder of the scenario (Blender's user resources, about 100 MB once bpy starts; the add-on's
# source repository; an installed extension with its wheels, 34 MB; exported scenes) and of the worker
# processes it starts goes into one folder, removed at exit, after the scenario's own exit handlers
# (registered later, run first): every scenario of every test run had stayed in the temp folder (3.4 GB
# of installed extensions after a day). A scenario's files that its test reads are in the test's tmp_path.
tempfile.tempdir = _TMP = tempfile.mkdtemp(prefix="hud-scenario-")
os.environ["TMPDIR"] = _TMP
atexit.register(shutil.rmtree, _TMP, ignore_errors=True)
os.environ["BLENDER_USER_RESOURCES"] = tempfile.mkdtemp(prefix="hud-bpy-user-")
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
