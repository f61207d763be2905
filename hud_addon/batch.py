"""hud-render: render a saved .blend headless with the bpy module.

    hud-render FILE.blend --out DIR [--method auto|backward|forward|hybrid|photon] [--seconds S | --rays N]
               [--seed K]

The add-on is enabled from this source tree through a temporary local extension repository (Blender
disables it at exit, so the bpy module does not hang), the file is opened, its HUD settings are
overridden where options are given, and Blender's own render pipeline runs (the same path as F12).
DIR receives image.exr (multilayer: Combined, the luminance pass Y and its standard error Y_noise,
cd/m^2, with the hud:* header fields of the command line's image.exr), report.json (the command
line's report, tracer.products.report.build_report, with the .blend's path) and falsecolour.png (Y in false
colour, logarithmic, with a legend in cd/m^2: tracer.products.falsecolour), written as a set (tracer.products.outputs,
as hud-trace writes its outputs): DIR and the arguments are checked
and DIR locked before Blender starts (exit 2, one line), Blender renders into a temporary folder, and
the two files are read back and moved into DIR together, or not at all (exit 4, the earlier set
kept); a render in which no path found light exits 3 once its set is written, as hud-trace's. The
report's ``run_id`` names the set. This module imports nothing from the package at import
time (main() takes the tracer's allocator settings) and runs as a top-level script.

With a real Blender and the extension installed:
    blender --background FILE.blend -E HUD_TRACER -o //render/image -F OPEN_EXR_MULTILAYER -f 1
"""

from __future__ import annotations

import argparse
import atexit
import contextlib
import ctypes
import json
import os
import shutil
import sys
import tempfile
import threading
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
EXTENSION_ID = "hud_tracer"
#: The files of a hud-render, written as a set.
OUTPUT_NAMES = ("image.exr", "report.json", "falsecolour.png")


#: The lines Blender prints on standard output for the engine's reports in background mode: hud-render
#: says each again on standard error, in its own words ("warning: ...", "error: FILE: ..."), once.
ENGINE_REPORTS = (b"Error: HUD Tracer: ", b"Warning: HUD Tracer: ", b"Info: HUD Tracer: ")


@contextlib.contextmanager
def _engine_reports_left_out():
    """While the block runs, what the process writes on file descriptor 1 (Blender's own lines, its
    workers') goes on to standard output line by line, except Blender's echo of the engine's reports
    (:data:`ENGINE_REPORTS`). The forwarding thread stays to the process's end: worker processes
    started during the block keep writing into it."""
    try:
        sys.stdout.flush()
        saved = os.dup(1)
    except (OSError, ValueError):  # no file descriptor 1 (an embedding host): nothing to leave out
        yield
        return
    read_end, write_end = os.pipe()

    def forward():
        with os.fdopen(read_end, "rb") as lines:
            for line in lines:
                if not line.startswith(ENGINE_REPORTS):
                    os.write(saved, line)

    threading.Thread(target=forward, name="hud-render stdout", daemon=True).start()
    os.dup2(write_end, 1)
    os.close(write_end)
    try:
        yield
    finally:
        ctypes.CDLL(None).fflush(None)  # Blender's buffered C output into the pipe first
        sys.stdout.flush()
        os.dup2(saved, 1)


def enable_from_source(bpy, tmp: Path) -> str:
    """Enable the add-on of this source tree as an extension; returns its module name."""
    import addon_utils

    repo_dir = tmp / "hud_source"
    repo_dir.mkdir()
    (repo_dir / EXTENSION_ID).symlink_to(ROOT, target_is_directory=True)
    bpy.ops.preferences.extension_repo_add(name="hud_source", type="LOCAL", use_custom_directory=True,
                                           custom_directory=str(repo_dir))
    repo = next(r.module for r in bpy.context.preferences.extensions.repos if r.custom_directory == str(repo_dir))
    module = f"bl_ext.{repo}.{EXTENSION_ID}"
    addon_utils.enable(module, default_set=True)
    atexit.register(addon_utils.disable, module)
    return module


def main(argv: list[str] | None = None) -> int:
    from tracer.cli import Parser, ray_count
    from tracer.methods import INTEGRATORS
    from tracer.runtime.allocator import keep_freed_memory

    keep_freed_memory()  # this process exists to render (see tracer/runtime/allocator.py)
    ap = Parser(prog="hud-render", description="Render a .blend with the HUD Tracer engine.")
    ap.add_argument("blend")
    ap.add_argument("--out", required=True)
    ap.add_argument("--method", choices=sorted(INTEGRATORS), help="the method (default: the .blend's)")
    group = ap.add_mutually_exclusive_group()
    group.add_argument("--seconds", type=float)
    group.add_argument("--rays", type=ray_count)
    ap.add_argument("--seed", type=int)
    ap.add_argument("--scheduler", metavar="ADDRESS", help="render on this Dask scheduler's cluster (tcp://host:8786) "
                    "instead of the .blend's Performance > Threads processes")
    args = ap.parse_args(argv)
    from tracer.cli import ArgumentError, check_render_args
    from tracer.products.outputs import OutputFolderError, OutputSet

    blend = Path(args.blend).resolve()
    if not blend.is_file():
        what = "a folder, not a .blend file" if blend.is_dir() else "no such .blend file"
        print(f"error: {blend}: {what}", file=sys.stderr)
        return 2
    try:
        check_render_args(argparse.Namespace(rays=args.rays, seconds=args.seconds, seed=args.seed or 0,
                                             batch_size=None, workers=1, scheduler=args.scheduler))
        outputs = OutputSet(Path(args.out).resolve(), OUTPUT_NAMES).open()
    except (ArgumentError, OutputFolderError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    try:
        return _render(args, blend, outputs)
    finally:
        outputs.close()


def _blender_reason(error: RuntimeError) -> str:
    """The first line of an operator's RuntimeError without Blender's "Error: " prefix."""
    return str(error).splitlines()[0].removeprefix("Error: ").strip() if str(error) else ""


def _render(args, blend: Path, outputs) -> int:
    """Open ``blend``, render it with Blender's pipeline into a temporary folder and commit the
    image and the report to ``outputs`` (a locked :class:`tracer.products.outputs.OutputSet`)."""
    import numpy as np

    from tracer.core.imageio import read_exr_channels
    from tracer.products.outputs import OutputFile, OutputWriteError, png_file
    from tracer.products.report import finite_json

    tmp = Path(tempfile.mkdtemp(prefix="hud-render-"))
    atexit.register(shutil.rmtree, tmp, ignore_errors=True)
    os.environ.setdefault("BLENDER_USER_RESOURCES", str(tmp / "user"))
    import bpy

    module = enable_from_source(bpy, tmp)
    try:
        bpy.ops.wm.open_mainfile(filepath=str(blend))
    except RuntimeError as e:  # not a .blend, or a truncated one: Blender's reason, on one line
        print(f"error: {blend}: not a readable .blend file ({_blender_reason(e) or 'cannot be opened'})",
              file=sys.stderr)
        return 2
    scene = bpy.context.scene
    scene.render.engine = "HUD_TRACER"
    if args.method:
        scene.hud.method = args.method
    if args.seconds is not None:
        scene.hud.budget, scene.hud.seconds = "SECONDS", args.seconds
    if args.rays is not None:
        scene.hud.budget, scene.hud.rays = "RAYS", args.rays
    if args.seed is not None:
        scene.hud.seed = args.seed
    if args.scheduler is not None:
        scene.hud.scheduler = args.scheduler
    settings = scene.render.image_settings
    settings.file_format = "OPEN_EXR_MULTILAYER"
    settings.color_depth = "32"
    rendered = tmp / "render" / "image.exr"
    scene.render.filepath = str(rendered)
    scene.render.use_file_extension = False
    engine = sys.modules[f"{module}.hud_addon.engine"]
    engine.LAST_RENDER.clear()
    try:
        with _engine_reports_left_out():  # said once below, as "warning: ..." and "error: FILE: ..."
            bpy.ops.render.render(write_still=True)
    except RuntimeError as e:  # the engine reported an error: Blender raises it in background mode
        if "error" not in engine.LAST_RENDER:  # Blender refused before the engine ran: the file's settings
            print(f"error: {blend.name}: {_blender_reason(e)} (Blender's check of the file's scene, camera and "
                  "output)", file=sys.stderr)
            return 2
    engine.finish_analysis()  # the figures that follow the image
    figures = dict(engine.LAST_RENDER)
    for w in figures.get("warnings", []):
        print(f"warning: {w}", file=sys.stderr)
    if "error" in figures:
        print(f"error: {blend.name}: {figures['error']}", file=sys.stderr)
        return 2
    if "stopped" in figures:
        print(f"{blend.name}: {figures['stopped']}; {outputs.folder} keeps what it held", file=sys.stderr)
        return 130
    figures |= {"blend": str(blend)}
    text = finite_json(figures)
    size = (scene.render.resolution_x * scene.render.resolution_percentage // 100,
            scene.render.resolution_y * scene.render.resolution_percentage // 100)

    def check_exr(path):
        channels, attrs = read_exr_channels(path)
        y = next((c for name, c in channels.items() if name.endswith(".Y.X") or name == "Y"), None)
        if y is None or y.shape[::-1] != size or not np.all(np.isfinite(y)):
            raise ValueError(f"expected a finite Y pass of {size[0]} x {size[1]} pixels")
        if attrs.get("hud:run_id") != figures["run_id"]:
            raise ValueError("the image's hud:run_id differs from the report's")

    colour = engine.FALSE_COLOUR[scene.name][0]
    try:
        outputs.commit([OutputFile("image.exr", lambda path: shutil.copyfile(rendered, path), check_exr),
                        OutputFile("report.json", lambda path: path.write_text(text), lambda path: json.loads(
                            path.read_text())),
                        png_file("falsecolour.png", colour)])
    except OutputWriteError as e:
        print(f"error: {e}", file=sys.stderr)
        return 4
    outputs.keep()
    print(f"{figures['method']}: {figures['rays']:,} rays in {figures['seconds']:.1f} s, efficiency "
          f"{figures['efficiency']:.3g}, luminance mean {figures['luminance']['mean']:.4g} cd/m^2 -> "
          f"{outputs.folder}", file=sys.stderr)
    return 3 if figures.get("paths_found_light") == 0 else 0  # as hud-trace render: written, no light found


if __name__ == "__main__":
    sys.exit(main())
