"""F12 after F12 in Blender (the bpy module): when tracing starts and when the render ends, at 1920 x 1080.

    .venv/bin/python benchmarks/blender_f12.py [--preset hud-direct] [--seconds 1] [--size 1920x1080]
                                               [--threads 2] [--renders 3]

Enables the add-on from this checkout in the bpy module (as tests/addon do), adds the preset with Add HUD
Preset, sets the output size, a budget in seconds and Performance > Threads, and renders (F12:
``bpy.ops.render.render()``) several times in one session. Per render it prints: the seconds from F12
until the engine hands the scene to the tracer (export and loading), until tracing starts (that plus the
render's setup: the pilot, and on the first render the worker processes' start), until the render ends
(the image in the Render Result), until its analysis is in the report (the HUD Readouts' figures, which
follow the image), whether the worker pool was started or reused, and the rays traced.
"""

from __future__ import annotations

import argparse
import atexit
import os
import shutil
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
# Blender's user resources (about 100 MB) and the add-on's source repository, removed at exit
_TMP = tempfile.mkdtemp(prefix="hud-f12-")
atexit.register(shutil.rmtree, _TMP, ignore_errors=True)
os.environ["BLENDER_USER_RESOURCES"] = str(Path(_TMP, "user"))
sys.path.insert(0, str(ROOT))

import bpy  # noqa: E402  (the environment above must be set first)

from hud_addon.batch import enable_from_source  # noqa: E402


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--preset", default="hud-direct")
    ap.add_argument("--seconds", type=float, default=1.0)
    ap.add_argument("--size", default="1920x1080")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--renders", type=int, default=3)
    args = ap.parse_args()
    module = enable_from_source(bpy, Path(tempfile.mkdtemp(dir=_TMP)))
    engine = sys.modules[f"{module}.hud_addon.engine"]
    bpy.ops.hud.add_preset(preset=args.preset)
    scene = bpy.context.scene
    w, h = (int(v) for v in args.size.lower().split("x"))
    scene.render.resolution_x, scene.render.resolution_y, scene.render.resolution_percentage = w, h, 100
    scene.hud.method, scene.hud.budget, scene.hud.seconds = "backward", "SECONDS", args.seconds
    scene.render.threads_mode, scene.render.threads = "FIXED", args.threads
    entered, began = [], []
    run_render, render_final = engine.run_render, engine.render_final

    def timed_run_render(*a, **kw):
        entered.append(time.perf_counter())
        return run_render(*a, **kw)

    def timed_render_final(*a, **kw):
        began.append(time.perf_counter())
        return render_final(*a, **kw)

    engine.run_render, engine.render_final = timed_run_render, timed_render_final
    print(f"{args.preset} at {w} x {h}, backward, {args.seconds:g} s, {args.threads} threads, "
          f"bpy {bpy.app.version_string}")
    print(f"{'render':>6} {'to tracer':>10} {'tracing':>8} {'ends':>7} {'analysis':>9} {'pool':>8} {'rays':>11}")
    try:
        for k in range(args.renders):
            entered.clear()
            began.clear()
            t0 = time.perf_counter()
            bpy.ops.render.render()
            ended = time.perf_counter() - t0
            engine.finish_analysis()
            analysed = time.perf_counter() - t0
            report = engine.REPORTS[scene.name]
            details = report["method_details"]
            to_tracer = entered[0] - t0
            tracing = began[0] - t0 + details["setup_seconds"]  # the budget counts from the engine's start (F12)
            print(f"{k + 1:>6} {to_tracer:>8.2f} s {tracing:>6.2f} s {ended:>5.2f} s "
                  f"{analysed:>7.2f} s {details.get('pool', '-'):>8} {report['rays']:>11,}", flush=True)
    finally:
        engine.run_render, engine.render_final = run_render, render_final
        import addon_utils

        addon_utils.disable(module)  # bpy hangs at exit while a render engine is registered


if __name__ == "__main__":
    main()
