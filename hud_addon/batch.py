"""hud-render: render a saved .blend headless with the bpy module.

    hud-render FILE.blend --out DIR [--method backward|forward] [--seconds S | --rays N] [--seed K]

The add-on is enabled from this source tree through a temporary local extension repository (Blender
disables it at exit, so the bpy module does not hang), the file is opened, its HUD settings are
overridden where options are given, and Blender's own render pipeline runs (the same path as F12).
DIR receives image.exr (multilayer: Combined and the luminance pass Y, cd/m^2) and report.json.
This module imports nothing from the package at import time (main() takes the tracer's allocator
settings) and runs as a top-level script.

With a real Blender and the extension installed:
    blender --background FILE.blend -E HUD_TRACER -o //render/image -F OPEN_EXR_MULTILAYER -f 1
"""

from __future__ import annotations

import argparse
import atexit
import json
import os
import shutil
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
EXTENSION_ID = "hud_tracer"


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
    from tracer.allocator import keep_freed_memory

    keep_freed_memory()  # this process exists to render (see tracer/allocator.py)
    ap = argparse.ArgumentParser(prog="hud-render", description="Render a .blend with the HUD Tracer engine.")
    ap.add_argument("blend")
    ap.add_argument("--out", required=True)
    ap.add_argument("--method")
    group = ap.add_mutually_exclusive_group()
    group.add_argument("--seconds", type=float)
    group.add_argument("--rays", type=int)
    ap.add_argument("--seed", type=int)
    args = ap.parse_args(argv)
    blend = Path(args.blend).resolve()
    if not blend.is_file():
        print(f"error: {blend}: no such .blend file", file=sys.stderr)
        return 2
    tmp = Path(tempfile.mkdtemp(prefix="hud-render-"))
    atexit.register(shutil.rmtree, tmp, ignore_errors=True)
    os.environ.setdefault("BLENDER_USER_RESOURCES", str(tmp / "user"))
    import bpy

    module = enable_from_source(bpy, tmp)
    bpy.ops.wm.open_mainfile(filepath=str(blend))
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
    out = Path(args.out).resolve()
    out.mkdir(parents=True, exist_ok=True)
    settings = scene.render.image_settings
    settings.file_format = "OPEN_EXR_MULTILAYER"
    settings.color_depth = "32"
    scene.render.filepath = str(out / "image.exr")
    scene.render.use_file_extension = False
    bpy.ops.render.render(write_still=True)
    figures = dict(sys.modules[f"{module}.hud_addon.engine"].LAST_RENDER)
    figures["blend"] = str(blend)
    (out / "report.json").write_text(json.dumps(figures, indent=2) + "\n")
    for w in figures.get("warnings", []):
        print(f"warning: {w}", file=sys.stderr)
    if "error" in figures:
        print(f"error: {figures['error']}", file=sys.stderr)
        return 2
    print(f"{figures['method']}: {figures['rays']:,} rays in {figures['seconds']:.1f} s, efficiency "
          f"{figures['efficiency']:.3g}, luminance mean {figures['luminance']['mean']:.4g} cd/m^2 -> {out}",
          file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
