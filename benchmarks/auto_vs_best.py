"""The automatic choice against the best method chosen by hand: the time each takes to reach a given
accuracy on each preset (the goal: auto at most 1.5 times slower than the best single method).

    .venv/bin/python benchmarks/auto_vs_best.py [--presets P ...] [--seconds 16] [--target 0.05] [--ref-seconds 120]

For each preset, against the cached reference of benchmarks/convergence.py (same cache, same metric:
relative RMSE over the bright region, the reference's own noise subtracted), every method that applies
and `auto` render for --seconds on one process. A single method's error falls as t^(-1/2), so it reaches
the target after t (err / target)^2; auto's pilots are a fixed cost, so it reaches it after
t_pilots + (t - t_pilots) (err / target)^2, with t_pilots the seconds its report gives them. The
script prints both times and their ratio, and writes benchmarks/results/auto.md.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from benchmarks.convergence import RESULTS, errors, reference, reference_seconds, scene_folder  # noqa: E402
from tracer.core.units import luminance  # noqa: E402
from tracer.methods import INTEGRATORS, Budget  # noqa: E402
from tracer.methods.pilots import applicable  # noqa: E402
from tracer.runtime.allocator import keep_freed_memory  # noqa: E402
from tracer.scene import load_scene  # noqa: E402
from tracer.scene.methods import CANDIDATES  # noqa: E402
from tracer.transport.world import World  # noqa: E402

PRESETS = ("hud-direct", "hud-direct-condenser", "hud-screen")


def main():
    keep_freed_memory()
    ap = argparse.ArgumentParser()
    ap.add_argument("--presets", nargs="*", default=list(PRESETS))
    ap.add_argument("--seconds", type=float, default=16.0)
    ap.add_argument("--target", type=float, default=0.05, help="relative RMSE over the bright region")
    ap.add_argument("--ref-seconds", type=float, default=120.0)
    ap.add_argument("--workers", type=int, default=2, help="processes of the reference renders")
    args = ap.parse_args()
    lines = ["# auto against the best single method", "",
             f"`benchmarks/auto_vs_best.py --seconds {args.seconds:g} --target {args.target:g}` (one process; time to "
             f"a relative RMSE of {args.target:g} over the bright region, extrapolated at slope -1/2)", "",
             "| preset | method | error at t | seconds to target | |", "|---|---|---|---|---|"]
    worst = 0.0
    for name in args.presets:
        folder = scene_folder(name)
        ref = reference(name, folder, reference_seconds(name, args.ref_seconds), args.workers)
        world = World(load_scene(folder))
        ok = [m for m, why in applicable(world, True, True).items() if why is None and m in CANDIDATES]
        times = {}
        for method in ok + ["auto"]:
            t0 = time.perf_counter()
            res = INTEGRATORS[method](world, 7).render(Budget(seconds=args.seconds))
            wall = time.perf_counter() - t0
            err = errors(luminance(res.film.rgb()), ref, wall)["rel_rmse_region"]
            pilots = 0.0
            if method == "auto":
                scene = res.extra["channels"]["scene"]
                pilots = sum(p["seconds"] for p in scene["pilots"] if p["skipped"] is None)
                label = f"auto ({scene['method']})"
            else:
                label = method
            times[label] = pilots + (wall - pilots) * (err / args.target) ** 2
            print(f"{name:22s} {label:18s} rel. RMSE {err:.4f} after {wall:.1f} s (pilots {pilots:.1f} s): "
                  f"{times[label]:,.0f} s to {args.target:g}", flush=True)
            lines.append(f"| {name} | {label} | {err:.4f} after {wall:.1f} s | {times[label]:,.0f} | "
                         f"{'pilots ' + format(pilots, '.1f') + ' s' if pilots else ''} |")
        auto = next(k for k in times if k.startswith("auto"))
        best = min((k for k in times if k != auto), key=times.get)
        ratio = times[auto] / times[best]
        worst = max(worst, ratio)
        print(f"{name:22s} auto / best ({best}): {ratio:.2f}", flush=True)
        lines.append(f"| {name} | **auto / best ({best})** | | **{ratio:.2f}** | |")
    lines += ["", f"Worst ratio: {worst:.2f} (the goal: at most 1.5)."]
    RESULTS.mkdir(parents=True, exist_ok=True)
    (RESULTS / "auto.md").write_text("\n".join(lines) + "\n")
    print(f"worst auto / best: {worst:.2f} -> {RESULTS / 'auto.md'}")


if __name__ == "__main__":
    main()
