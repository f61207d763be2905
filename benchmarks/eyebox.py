"""Eyebox of a HUD scene: where the eye can move and still see the whole display lit.

    .venv/bin/python benchmarks/eyebox.py [PRESET_OR_SCENE] [--field 6 2] [--step 5] [--half 60 30]

Prints the scan of :func:`tracer.scans.eyebox.eyebox_scan` (the brightness-theorem analysis, chief rays
through every specular branch, every LCD cell clear, at five points of the virtual image: the centre
and 80 % of the half-field toward the corners, fixed in space) as a grid of the eye offsets where
all five stay at or above 50 % of their value at the design eye, and the eyebox's extent.
``hud-trace eyebox`` writes the same scan as eyebox.csv, eyebox.png and eyebox.json.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from presets import PRESETS  # noqa: E402
from tracer.runtime.allocator import keep_freed_memory  # noqa: E402
from tracer.scans.eyebox import eyebox_scan  # noqa: E402
from tracer.scene import load_scene  # noqa: E402
from tracer.transport.world import World  # noqa: E402


def main():
    keep_freed_memory()  # as the command line does (tracer/runtime/allocator.py)
    ap = argparse.ArgumentParser()
    ap.add_argument("scene", nargs="?", default="hud-direct")
    ap.add_argument("--field", type=float, nargs=2, default=(6.0, 2.0), help="display field of view, deg")
    ap.add_argument("--step", type=float, default=5.0, help="grid step, mm")
    ap.add_argument("--half", type=float, nargs=2, default=(60.0, 30.0), help="scan half-widths, mm")
    ap.add_argument("--threshold", type=float, default=0.5, help="share of the design luminance, 0..1")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        folder = PRESETS[args.scene].write(Path(tmp) / "s") if args.scene in PRESETS else Path(args.scene)
        r = eyebox_scan(World(load_scene(folder)), args.half, args.step, args.field, args.threshold)
    ref = r.design_cd_m2
    print(f"design eye: centre {ref[0]:.0f} cd/m^2, corners {', '.join(f'{v:.0f}' for v in ref[1:])}")
    if not r.valid:
        for reason in r.reasons:
            print(f"not valid: {reason}")
        return
    pct = f"{100 * r.threshold:g} %"
    print(f"eye offset grid (rows: up, mm; columns: right, mm); # = whole field >= {pct} of design")
    print("       " + "".join(f"{x:>5.0f}" for x in r.right_mm))
    inside = r.inside
    for j in range(len(r.up_mm) - 1, -1, -1):
        print(f"{r.up_mm[j]:>6.0f} " + "".join(f"{'#' if v else '.':>5}" for v in inside[j]))
    f = r.figures()
    print(f"eyebox (extent of the lit region): {f['grid_width_mm']:.0f} mm wide x {f['grid_height_mm']:.0f} mm high, "
          f"step {args.step:g} mm")
    e = f["edges_mm"]
    print(f"edges where the field falls to {pct} (interpolated): right {e['left']:.1f} to {e['right']:.1f} mm, up "
          f"{e['bottom']:.1f} to {e['top']:.1f} mm: {f['width_mm']:.1f} x {f['height_mm']:.1f} mm"
          + ("; it reaches the edge of the scan" if f["reaches_scan_edge"] else ""))
    u = f["uniformity"]
    print(f"uniformity (min / max of the field points): {u['design_eye']:.3f} at the design eye, {u['eyebox']:.3f} "
          "over the eyebox")


if __name__ == "__main__":
    main()
