"""Scaling beyond one process: the local worker pool against a Dask LocalCluster of 1 and 2 workers.

    .venv/bin/python benchmarks/cluster.py [--scene hud-direct] [--rays 3e7] [--method backward] [--seed 1]

Renders the scene (a preset) for the same budget in rays with the same seed: in one process; on the
local pool of 2 worker processes (tracer.runtime.parallel: started by the first render, reused by the
second); and on a Dask LocalCluster (one thread per worker process) of 1 and of 2 workers, through
the same code as ``hud-trace render --scheduler`` (tracer.runtime.distributed.connect). Prints for
each the wall time of the render (the cluster's start left out; the scene's upload and each worker's
world counted), rays per second, the speed-up over one process, and whether the image equals the
one-process image (the seed-addressed batches promise it to the last bits of rounding). Needs Dask
(``make test`` installs it).
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from presets import PRESETS  # noqa: E402
from tracer.cli import ray_count  # noqa: E402
from tracer.methods import INTEGRATORS, Budget  # noqa: E402
from tracer.runtime import distributed as dist  # noqa: E402
from tracer.runtime.parallel import close_shared_pool, render_parallel  # noqa: E402
from tracer.scene import load_scene  # noqa: E402


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--scene", default="hud-direct")
    ap.add_argument("--rays", type=ray_count, default=30_000_000)
    ap.add_argument("--method", default="backward")
    ap.add_argument("--seed", type=int, default=1)
    args = ap.parse_args()
    from distributed import LocalCluster

    budget = Budget(rays=args.rays)
    with tempfile.TemporaryDirectory() as tmp:
        folder = PRESETS[args.scene].write(Path(tmp) / args.scene)

        def integrator():
            return INTEGRATORS[args.method](load_scene(folder), args.seed)

        rows = []
        t0 = time.perf_counter()
        one = integrator().render(budget)
        rows.append(("1 process", time.perf_counter() - t0, one))
        for kind in ("started", "reused"):  # the pool's processes start with the first render, serve the next
            t0 = time.perf_counter()
            res = render_parallel(integrator(), budget, 2)
            rows.append((f"local pool, 2 workers ({kind})", time.perf_counter() - t0, res))
        close_shared_pool()
        for n in (1, 2):
            with LocalCluster(n_workers=n, threads_per_worker=1, processes=True, dashboard_address=None) as cluster:
                client = dist.connect(cluster.scheduler_address)
                t0 = time.perf_counter()
                res = dist.render_dask(integrator(), budget, client)
                rows.append((f"Dask LocalCluster, {n} worker{'s' if n > 1 else ''}", time.perf_counter() - t0, res))
                dist.close_clients()
    ref = one.film.rgb()
    base = rows[0][1]
    print(f"{args.scene}, {args.method}, {args.rays:,} rays, seed {args.seed}")
    print(f"{'':32} {'wall':>7} {'rays/s':>12} {'speed-up':>8}  same image")
    for name, wall, res in rows:
        same = bool(np.allclose(res.film.rgb(), ref, rtol=1e-9, atol=0))
        print(f"{name:32} {wall:>5.2f} s {res.rays / wall:>12,.0f} {base / wall:>7.2f}x  {same}")


if __name__ == "__main__":
    main()
