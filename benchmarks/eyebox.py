"""Eyebox of a HUD scene: where the eye can move and still see the whole display lit.

    .venv/bin/python benchmarks/eyebox.py [PRESET_OR_SCENE] [--field 6 2] [--step 5]

For eye positions on a grid in the eye's right/up plane, the deterministic brightness-theorem
analysis (tracer.analysis, chief rays through every specular branch) gives the luminance of the
display, with every LCD cell made clear, at five points of its virtual image (the centre and near
the four corners, fixed in space). The eyebox is where all five stay at or above 50 % of their
value at the design eye position.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from presets import PRESETS  # noqa: E402
from tracer.allocator import keep_freed_memory  # noqa: E402
from tracer.analysis import specular_paths  # noqa: E402
from tracer.scene import load_scene  # noqa: E402
from tracer.units import Y_WEIGHTS  # noqa: E402
from tracer.world import World  # noqa: E402


def field_luminance(world: World, offset_right: float, offset_up: float, field_deg) -> np.ndarray:
    """Predicted luminance (cd/m^2), clear LCD, of five points of the virtual image (its centre and
    points at 80 % of the half-field toward its corners, fixed in space at the accommodation
    distance) seen from the eye moved by the given offsets (mm)."""
    eye = world.scene.eye
    right = np.cross(eye.gaze, eye.up)
    right /= np.linalg.norm(right)
    up = np.cross(right, eye.gaze)
    tx, ty = (0.8 * np.tan(np.radians(f) / 2) for f in field_deg)
    corners = [(0, 0), (-tx, ty), (tx, ty), (-tx, -ty), (tx, -ty)]
    base = eye.position
    dist = eye.accommodation_distance_mm
    points = np.array([base + dist * (eye.gaze + a * right + b * up) for a, b in corners])
    moved = dataclasses.replace(eye, position=base + offset_right * right + offset_up * up)
    res = specular_paths(world.with_eye(moved), directions=points - moved.position)
    total = np.zeros(len(points))
    for p in res["paths"]:
        np.add.at(total, p["pixel"], p["luminance"] @ Y_WEIGHTS)
    return total


def main():
    keep_freed_memory()  # as the command line does (tracer/allocator.py)
    ap = argparse.ArgumentParser()
    ap.add_argument("scene", nargs="?", default="hud-direct")
    ap.add_argument("--field", type=float, nargs=2, default=(6.0, 2.0), help="display field of view, deg")
    ap.add_argument("--step", type=float, default=5.0, help="grid step, mm")
    ap.add_argument("--half", type=float, nargs=2, default=(60.0, 30.0), help="scan half-widths, mm")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        folder = PRESETS[args.scene].write(Path(tmp) / "s") if args.scene in PRESETS else Path(args.scene)
        scene = load_scene(folder)
        for o in scene.objects:
            if o.material.type == "lcd":
                o.material.params["image"] = np.ones_like(o.material.params["image"])
        world = World(scene)
        ref = field_luminance(world, 0.0, 0.0, args.field)
        print(f"design eye: centre {ref[0]:.0f} cd/m^2, corners {', '.join(f'{v:.0f}' for v in ref[1:])}")
        xs = np.arange(-args.half[0], args.half[0] + 1e-9, args.step)
        zs = np.arange(-args.half[1], args.half[1] + 1e-9, args.step)
        ok = np.zeros((len(zs), len(xs)), bool)
        for j, z in enumerate(zs):
            for i, x in enumerate(xs):
                ok[j, i] = np.all(field_luminance(world, x, z, args.field) >= 0.5 * ref)
        print("eye offset grid (rows: up, mm; columns: right, mm); # = whole field >= 50 % of design")
        print("       " + "".join(f"{x:>5.0f}" for x in xs))
        for j in range(len(zs) - 1, -1, -1):
            print(f"{zs[j]:>6.0f} " + "".join(f"{'#' if v else '.':>5}" for v in ok[j]))
        cols, rows = np.nonzero(ok.any(axis=0))[0], np.nonzero(ok.any(axis=1))[0]
        if len(cols) and len(rows):
            print(f"eyebox (extent of the lit region): {xs[cols[-1]] - xs[cols[0]]:.0f} mm wide x "
                  f"{zs[rows[-1]] - zs[rows[0]]:.0f} mm high, step {args.step:g} mm")


if __name__ == "__main__":
    main()
