"""The add-on tests outside Blender: each scenario (a function of a test module that sets up and renders a
scene inside the bpy module) runs in a process of its own through tests/addon/blender_runner.py, since bpy
is imported once per process and hangs at exit while a Python render engine is registered; its result
comes back as JSON. Also: the add-on tests' skip where bpy is missing, and a multilayer EXR read back."""

from __future__ import annotations

import importlib.util
import inspect
import json
import subprocess
import sys

import pytest

from tests.support.paths import ROOT

#: The add-on tests need the bpy 4.5 module (looked for without importing it, which takes seconds).
needs_bpy = pytest.mark.skipif(importlib.util.find_spec("bpy") is None,
                               reason="the bpy 4.5 module is needed for the add-on tests")

RUNNER = ROOT / "tests" / "addon" / "blender_runner.py"


def in_blender(scenario, *args, timeout=600):
    """Run ``scenario(*args)`` (a function of a test module; the arguments as strings) inside Blender, in a
    process of its own: (its result, the finished process)."""
    proc = subprocess.run([sys.executable, str(RUNNER), inspect.getsourcefile(scenario), scenario.__name__,
                           *map(str, args)], capture_output=True, text=True, timeout=timeout, cwd=ROOT)
    assert proc.returncode == 0, proc.stderr[-3000:] + proc.stdout[-3000:]
    line = next(x for x in proc.stdout.splitlines() if x.startswith("HUD_RESULT "))
    return json.loads(line[len("HUD_RESULT "):]), proc


def read_multilayer(path):
    """Every channel of a multilayer EXR, by its full name ("ViewLayer.Combined.R", ...)."""
    import OpenImageIO as oiio

    inp = oiio.ImageInput.open(str(path))
    spec = inp.spec()
    px = inp.read_image(oiio.FLOAT)
    inp.close()
    return {name: px[:, :, i] for i, name in enumerate(spec.channelnames)}
