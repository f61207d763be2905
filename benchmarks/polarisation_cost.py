"""What polarised transport costs: each method on a scene that needs it (hud-direct: its windshield
polarises; hud-direct-s: an LCD polariser too) with Stokes vectors and, where the scene allows, without
them (``"polarisation": "off"``, the unpolarised Fresnel average), and on a scene that needs none
(analytic-mirror, where a render is the same code with or without the setting).

    .venv/bin/python benchmarks/polarisation_cost.py [--seconds S] [--repeats R] [--presets P ...] [--out CSV]

One process, the same seeds, a time budget of S seconds per render; the figure is the time per ray
segment (wall seconds over rays traced, the pilot and set-up left out), alternating polarised and
unpolarised renders R times and taking medians (the machine's speed drifts between runs). The
issue's goal: at most 1.5 times the time where a scene needs polarisation, nothing where it does not.
"""

from __future__ import annotations

import argparse
import csv
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.throughput import set_polarisation  # noqa: E402
from presets import PRESETS  # noqa: E402
from tracer.methods import INTEGRATORS, Budget  # noqa: E402
from tracer.runtime.allocator import keep_freed_memory  # noqa: E402
from tracer.scene import load_scene  # noqa: E402
from tracer.transport.world import World  # noqa: E402

#: (preset, methods) measured.
CASES = (("hud-direct", ("forward", "backward", "photon")), ("analytic-mirror", ("forward", "backward")))


def seconds_per_ray(world: World, method: str, seconds: float, seed: int) -> float:
    res = INTEGRATORS[method](world, seed).render(Budget(seconds=seconds))
    return (res.seconds - res.extra.get("setup_seconds", 0.0)) / max(res.rays, 1)


def main():
    keep_freed_memory()
    ap = argparse.ArgumentParser()
    ap.add_argument("--seconds", type=float, default=8.0)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--presets", nargs="*", default=[name for name, _ in CASES])
    ap.add_argument("--out", type=Path, default=Path(__file__).parent / "results" / "polarisation_cost.csv")
    args = ap.parse_args()
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for name, methods in CASES:
            if name not in args.presets:
                continue
            folder = PRESETS[name].write(Path(tmp) / name)
            on = World(load_scene(folder))
            off = World(load_scene(set_polarisation(folder, "off")))
            for method in methods:
                pol, unpol = [], []
                for r in range(args.repeats):
                    pol.append(seconds_per_ray(on, method, args.seconds, 1 + r))
                    unpol.append(seconds_per_ray(off, method, args.seconds, 1 + r))
                a, b = float(np.median(pol)), float(np.median(unpol))
                rows.append({"preset": name, "method": method, "needs_polarisation": on.polarised,
                             "ns_per_ray_polarised": 1e9 * a, "ns_per_ray_off": 1e9 * b, "ratio": a / b})
                print(f"{name:16s} {method:9s} needs polarisation: {str(on.polarised):5s}  "
                      f"{1e9 * a:7.0f} ns/ray with it, {1e9 * b:7.0f} ns/ray off: {a / b:.2f} x", flush=True)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    with args.out.open("w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
