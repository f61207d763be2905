"""Rendering on several cores: seed-addressed batches in worker processes, merged exactly.

Batch k of a render draws its random numbers from ``make_rng(seed, k)`` only (see
:mod:`tracer.integrators.base`), so its film does not depend on which process traced it. Workers
(started with "spawn", each with its own copy of the scene and its own Embree scene) trace batches
handed out in increasing order; the parent keeps every batch's film apart until the contiguous
prefix 0..B-1 meets the budget, the same rule a single process applies, and adds exactly that prefix
in batch order. With a budget in rays the image is therefore identical, bit for bit, for any number
of workers; with a budget in seconds it is the prefix that was done in time.
"""

from __future__ import annotations

import multiprocessing as mp
import time
from pathlib import Path

import numpy as np

from .integrators import INTEGRATORS, Budget, Film, RenderResult
from .sampling import make_rng
from .scene import load_scene

_WORKER: dict = {}


def _init_worker(scene_dir: str, method: str, seed: int, batch_size: int):
    _WORKER["integrator"] = INTEGRATORS[method](load_scene(scene_dir), seed, batch_size)


def _run_batch(index: int):
    integ = _WORKER["integrator"]
    film = Film(integ.eye.width, integ.eye.height)
    rays_before = integ.rays_traced
    truncated_before = getattr(integ, "truncated", 0)
    paths, found = integ.run_batch(make_rng(integ.seed, index), film)
    return (index, film.sum_rgb, film.sum_y2, film.samples, paths, found, integ.rays_traced - rays_before,
            getattr(integ, "truncated", 0) - truncated_before)


def render_parallel(local, budget: Budget, workers: int = 2, progress=None, should_stop=None) -> RenderResult:
    """Render with ``workers`` processes what the integrator ``local`` would render alone (its scene
    folder, method, seed and batch size; see the module docstring)."""
    scene_dir, method, seed, batch_size = str(Path(local.scene.root)), local.name, local.seed, local.batch_size
    ctx = mp.get_context("spawn")
    done: dict[int, tuple] = {}
    film = Film(local.eye.width, local.eye.height)
    rays = paths = found = truncated = merged = 0
    partial = False
    start = time.perf_counter()
    with ctx.Pool(workers, initializer=_init_worker, initargs=(scene_dir, method, seed, batch_size)) as pool:
        pending = {}
        next_index = 0
        while True:
            elapsed = time.perf_counter() - start
            budget_met = budget.fraction(rays, elapsed) >= 1.0
            if should_stop is not None and not budget_met and should_stop():
                partial = True
                budget_met = True
            if not budget_met:
                while len(pending) < 2 * workers:
                    pending[next_index] = pool.apply_async(_run_batch, (next_index,))
                    next_index += 1
            elif not pending:
                break
            finished = [k for k, r in pending.items() if r.ready()]
            if not finished:
                time.sleep(0.002)
                continue
            for k in finished:
                done[k] = pending.pop(k).get()
            # Merge the contiguous prefix, in batch order, while the budget is not yet met.
            while merged in done and budget.fraction(rays, time.perf_counter() - start) < 1.0:
                _, s_rgb, s_y2, samples, p, f, r, t = done.pop(merged)
                film.sum_rgb += s_rgb
                film.sum_y2 += s_y2
                film.samples += samples
                paths, found, rays, truncated = paths + p, found + f, rays + r, truncated + t
                merged += 1
                if progress is not None:
                    eff = found / paths if paths else 0.0
                    progress(budget.fraction(rays, time.perf_counter() - start),
                             f"{method} x{workers}: {rays:,} rays, efficiency {eff:.2e}, "
                             f"{time.perf_counter() - start:.1f} s")
            if rays == 0 and merged > 0:
                break  # nothing to trace
            if budget_met and partial:
                # Cancelled: keep what is merged, drop what is still in flight.
                pool.terminate()
                break
    seconds = time.perf_counter() - start
    result = RenderResult(method, seed, film, rays, paths, found, seconds, partial, merged, list(local.warnings))
    if hasattr(local, "truncated"):
        local.truncated = truncated
    local.finish(result)
    result.extra["workers"] = workers
    return result


def merge_equal(a: RenderResult, b: RenderResult) -> bool:
    """Whether two results hold bit-identical films (the determinism check of the tests)."""
    return (a.film.samples == b.film.samples and np.array_equal(a.film.sum_rgb, b.film.sum_rgb)
            and np.array_equal(a.film.sum_y2, b.film.sum_y2))
