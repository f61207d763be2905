"""Rays per second of the tracer end to end against the raw embreex intersection rate, measured in
the same run on the same geometry (the hud-direct preset unless another scene is named), on one
process and on several, with the time of every stage of the path loop.

    .venv/bin/python benchmarks/throughput.py [PRESET_OR_SCENE] [--seconds S] [--workers W] [--repeats R]
                                              [--polarisation off]

Raw rates, one core: (1) one Embree closest-hit call on 2^20 rays with random origins in the scene's
bounding box and random directions, best of 5 (the ceiling the speed goal is stated against); (2) the
very rays each method traces (recorded from 8 of its batches, bounce by bounce, closest-hit and shadow
queries, and replayed through the same Embree calls, best of 5): the ceiling for that method's ray mix.
End to end: every method variant (forward; backward with next-event estimation; backward without it,
the paper's plain method) for S seconds, on one process and on W worker processes (tracer.runtime.parallel; the
clock starts once every worker has built its world, as in a render, and the start-up is printed apart;
"workers busy" is the share of the workers' time spent inside batches, the rest the pool's own cost,
and "per batch" the rays per second inside a worker's batches against one process's: the machine's own
scaling, so that the ratio is W x busy x per batch),
alternating R times (medians: the machine's speed drifts between runs). "Steady" rates leave out the
first batch. Per stage: the share of one process's wall time spent in each stage of the path loop
(intersect, sensor, shade, shadow, film, other). Peak memory is the largest resident set of this
process and of its workers. ``--polarisation off`` renders the scene with ``"polarisation": "off"``
(the unpolarised model, on which the transport core's speed goal was set; hud-direct's default
carries Stokes vectors through its windshield).
"""

from __future__ import annotations

import argparse
import json
import resource
import shutil
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from presets import PRESETS  # noqa: E402
from tracer.core.sampling import make_rng, uniform_sphere  # noqa: E402
from tracer.methods import INTEGRATORS, Budget  # noqa: E402
from tracer.methods.base import DEFAULT_BATCH  # noqa: E402
from tracer.runtime.allocator import keep_freed_memory  # noqa: E402
from tracer.runtime.parallel import render_parallel  # noqa: E402
from tracer.scene import load_scene  # noqa: E402
from tracer.transport.accel import Accelerator  # noqa: E402
from tracer.transport.world import World  # noqa: E402

#: The method variants measured: label -> (method, options that differ from the scene's).
VARIANTS = {"forward": ("forward", {}), "backward": ("backward", {}),
            "backward, no NEE": ("backward", {"next_event": False}), "photon": ("photon", {})}


#: The transport core's goal for one process: this share of the raw Embree rate, end to end.
GOAL = 0.3


def speedup_needed(rate: float, raw: float, own: float, goal: float = GOAL) -> float:
    """How many times as fast everything but Embree must become for a method that traces ``rate``
    rays/s end to end, whose own rays Embree alone traces at ``own`` rays/s, to reach ``goal`` x
    ``raw`` rays/s (per ray: 1/rate = 1/own + the rest); inf where Embree alone is slower than that."""
    rest_now = 1.0 / rate - 1.0 / own
    rest_goal = 1.0 / (goal * raw) - 1.0 / own
    return max(rest_now, 0.0) / rest_goal if rest_goal > 0 else float("inf")


#: Paths per batch of the measured renders: the command line's batch for a budget in rays (None: sized
#: from the pilot to 2 % of the time budget, as --seconds does; --batch-size auto).
BATCH = DEFAULT_BATCH


def make(world: World, label: str, seed: int):
    method, changes = VARIANTS[label]
    opts = dict(world.scene.method_options(method)) | changes
    return INTEGRATORS[method](world, seed, batch_size=BATCH, options=opts)


def set_polarisation(folder: Path, mode: str) -> Path:
    """Rewrite ``folder``'s scene.json with the top-level ``"polarisation": mode`` (unless it already
    says so); returns the folder."""
    scene_json = folder / "scene.json"
    data = json.loads(scene_json.read_text())
    if data.get("polarisation") != mode:
        scene_json.write_text(json.dumps(data | {"polarisation": mode}, indent=1))
    return folder


def tracing_rate(res) -> float:
    """Rays per second from the first batch issued to the end: a render's wall time less its set-up
    (the pilot and the workers' start-up, which a time budget includes; reported separately)."""
    return res.rays / max(res.seconds - res.extra.get("setup_seconds", 0.0), 1e-9)


def busy_share(res, workers: int) -> float:
    """The share of ``workers`` processes' time, from the first batch issued to the end, spent inside
    batches (the sum of their stage timers): the rest is the pool's own cost (results crossing the
    pipes, the parent's merges) and workers idle at the deadline, apart from the machine's scaling."""
    return sum(res.stages.values()) / (workers * max(res.seconds - res.extra.get("setup_seconds", 0.0), 1e-9))


def raw_embree_rate(scene, n: int = 1 << 20, repeats: int = 5) -> float:
    objs = scene.traced_objects
    accel = Accelerator(objs)
    allv = np.concatenate([o.vertices for o in objs])
    lo, hi = allv.min(axis=0), allv.max(axis=0)
    rng = make_rng(0)
    o = lo + (hi - lo) * rng.random((n, 3))
    d = uniform_sphere(rng.random((2, n))).T
    o32, d32 = (o - accel.center).astype(np.float32), d.astype(np.float32)
    best = 0.0
    for _ in range(repeats):
        t = time.perf_counter()
        accel._scene.run(o32, d32, output=True)
        best = max(best, n / (time.perf_counter() - t))
    return best


def own_rays_rate(integrator, batches: int = 8, repeats: int = 5) -> float:
    """Raw Embree rate (rays/s, one core) on the rays ``integrator`` traces in ``batches`` batches."""
    accel = integrator.world.accel
    recorded = []
    intersect, occluded = accel.intersect, accel.occluded

    def rec_intersect(o, d):
        recorded.append(("INTERSECT", *accel._rays32(o, d), None))
        return intersect(o, d)

    def rec_occluded(o, d, tmax):
        recorded.append(("OCCLUDED", *accel._rays32(o, d), np.ascontiguousarray(np.minimum(tmax, 3e38), np.float32)))
        return occluded(o, d, tmax)

    accel.intersect, accel.occluded = rec_intersect, rec_occluded
    try:
        for k in range(batches):
            integrator.trace_batch(k)
    finally:
        del accel.intersect, accel.occluded
    n = sum(len(r[1]) for r in recorded)
    best = 0.0
    for _ in range(repeats):
        t = time.perf_counter()
        for query, o32, d32, tmax in recorded:
            if query == "INTERSECT":
                accel._scene.run(o32, d32, output=True)
            else:
                accel._scene.run(o32, d32, dists=tmax, query="OCCLUDED")
        best = max(best, n / (time.perf_counter() - t))
    return best


def main():
    keep_freed_memory()  # as the command line does (tracer/runtime/allocator.py)
    ap = argparse.ArgumentParser()
    ap.add_argument("scene", nargs="?", default="hud-direct")
    ap.add_argument("--seconds", type=float, default=20.0)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--variants", nargs="*", default=list(VARIANTS))
    ap.add_argument("--polarisation", choices=("auto", "off"), default=None,
                    help="write the scene with this top-level polarisation (default: the scene's own)")
    ap.add_argument("--batch-size", default=str(DEFAULT_BATCH),
                    help=f"paths per batch (default {DEFAULT_BATCH}, as with --rays), or 'auto' (sized to the time "
                         "budget, as with --seconds)")
    args = ap.parse_args()
    global BATCH
    BATCH = None if args.batch_size == "auto" else int(args.batch_size)
    with tempfile.TemporaryDirectory() as tmp:
        folder = PRESETS[args.scene].write(Path(tmp) / "s") if args.scene in PRESETS else Path(args.scene)
        if args.polarisation is not None:  # on a copy: the folder may be the user's
            folder = set_polarisation(Path(shutil.copytree(folder, Path(tmp) / "polarisation")), args.polarisation)
        scene = load_scene(folder)
        world = World(scene)
        print(f"scene {args.scene}: polarisation {scene.polarisation!r}, "
              f"{'polarised' if world.polar is not None else 'unpolarised'} transport")
        raw = raw_embree_rate(scene)
        print(f"raw embreex intersection rate: {raw:,.0f} rays/s (one call on 2^20 random rays, best of 5)")
        for label in args.variants:
            own = own_rays_rate(make(World(scene), label, 99))
            print(f"{label:16s} raw embreex on its own rays: {own:,.0f} rays/s")
            # One process and W processes alternate, --repeats times, and the medians are compared:
            # this machine's speed drifts by tens of percent between runs a minute apart.
            one, many, stages, startup, busy, inside = [], [], [], [], [], []
            for r in range(args.repeats):
                res = make(world, label, 1 + r).render(Budget(seconds=args.seconds))
                par = render_parallel(make(world, label, 1 + r), Budget(seconds=args.seconds), args.workers)
                one.append((tracing_rate(res), res.extra["steady_rays_per_second"]))
                many.append((tracing_rate(par), par.extra["steady_rays_per_second"]))
                stages.append({k: v / (res.seconds - res.extra["setup_seconds"]) for k, v in res.stages.items()})
                startup.append(par.extra["startup_seconds"])
                busy.append(busy_share(par, args.workers))
                inside.append((par.rays / sum(par.stages.values())) / (res.rays / sum(res.stages.values())))
                print(f"{label:16s} run {r + 1}: one process {tracing_rate(res):,.0f} rays/s ({res.rays:,} rays in "
                      f"{res.seconds:.1f} s), {args.workers} processes {tracing_rate(par):,.0f} rays/s "
                      f"({par.rays:,} rays in {par.seconds:.1f} s, start-up {par.extra['startup_seconds']:.1f} s, "
                      f"workers busy {busy[-1]:.3f}); "
                      f"efficiency {res.efficiency:.3g}", flush=True)
            (rate, steady), (par_rate, par_steady) = np.median(one, axis=0), np.median(many, axis=0)
            share = {k: float(np.median([s.get(k, 0.0) for s in stages])) for k in stages[0]}
            print(f"{label:16s} end to end (median): {rate:,.0f} rays/s = {rate / raw:.2f} of raw, {rate / own:.2f} "
                  f"of raw on its own rays")
            print(f"{label:16s} Embree alone traces its own rays at {own / raw:.2f} of raw; {GOAL} of raw needs "
                  f"everything else {speedup_needed(rate, raw, own):.2f} x as fast")
            print(f"{label:16s} on {args.workers} processes (median): {par_rate:,.0f} rays/s = {par_rate / rate:.2f} x "
                  f"one process; steady (without the first batch) {par_steady / steady:.2f} x; start-up "
                  f"{np.median(startup):.1f} s, not in the rate; workers busy {np.median(busy):.3f} of the time, "
                  f"per batch {np.median(inside):.3f} x one process's speed")
            print(f"{label:16s} stages (share of one process's wall time): "
                  + ", ".join(f"{k} {v:.2f}" for k, v in share.items()))
        # Only this process: a spawned worker's ru_maxrss starts from the parent's resident size at the
        # fork that precedes its exec, so RUSAGE_CHILDREN would repeat this figure. A render's own peak:
        # /usr/bin/time -v hud-trace render ... --workers 1 (docs/results/speed.md).
        own = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
        print(f"peak memory: {own:.0f} MiB (this process, holding every variant's world and the raw rays)")


if __name__ == "__main__":
    main()
