"""Save a preset as a .blend, headless, with the bpy module: what Add HUD Preset and File > Save do.

    .venv/bin/python tools/preset_blend.py PRESET FILE.blend

The add-on of this source tree is enabled as hud-render enables it (hud_addon.batch.enable_from_source),
the preset is added to an empty scene (its camera is the eye, its images packed into the file) and the
file is saved; `hud-render FILE.blend` then renders it, as F12 would. Exit 2, one line, for an unknown
preset or a FILE that exists (it is never overwritten) or whose folder does not.
"""

from __future__ import annotations

import atexit
import os
import shutil
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def main(argv: list[str] | None = None) -> int:
    from presets import PRESETS
    from tracer.cli import Parser

    ap = Parser(prog="preset_blend.py", description=__doc__.splitlines()[0])
    ap.add_argument("preset", choices=list(PRESETS))
    ap.add_argument("blend", type=Path)
    args = ap.parse_args(argv)
    target = args.blend.resolve()
    if args.blend.suffix != ".blend":
        ap.error(f"{args.blend}: the file name must end in .blend")
    if target.exists():
        ap.error(f"{args.blend}: exists; give a new file name")
    if not target.parent.is_dir():
        ap.error(f"{args.blend}: no folder {target.parent}")
    tmp = Path(tempfile.mkdtemp(prefix="preset-blend-"))
    atexit.register(shutil.rmtree, tmp, ignore_errors=True)  # Blender's user resources: about 100 MB
    os.environ.setdefault("BLENDER_USER_RESOURCES", str(tmp / "user"))
    import bpy

    from hud_addon.batch import enable_from_source

    enable_from_source(bpy, tmp)
    bpy.ops.hud.add_preset(preset=args.preset)
    bpy.ops.wm.save_as_mainfile(filepath=str(target))
    print(f"{args.preset} -> {target}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
