"""Rendering on several cores: seed-addressed batches in worker processes, merged exactly.

Batch k of a render draws its random numbers from ``make_rng(seed, k)`` only (see
:mod:`tracer.integrators.base`), so its film does not depend on which process traced it. The same
driver (:func:`drive`) serves local processes here and Dask clusters in :mod:`tracer.distributed`. Workers
(started with "spawn", each with its own copy of the scene and its own Embree scene) trace batches
handed out in increasing order; the parent keeps every batch's film apart until the contiguous
prefix 0..B-1 meets the budget, the same rule a single process applies, and adds exactly that prefix
in batch order. With a budget in rays the image is therefore the same for any number of workers:
the same batches, rays and paths, and pixel values equal to the last bits of rounding (numpy's SIMD
kernels may round a last bit differently with the memory alignment of an array; relative
differences of 1e-16 have been seen, in a few pixels of some runs). With a budget in seconds it is
the prefix that was done in time.
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
    init = (str(Path(local.scene.root)), local.name, local.seed, local.batch_size)
    with mp.get_context("spawn").Pool(workers, initializer=_init_worker, initargs=init) as pool:
        result = drive(local, budget, lambda k: _PoolTask(pool.apply_async(_run_batch, (k,))), 2 * workers,
                       progress, should_stop, f"x{workers}")
        if result.partial:
            pool.terminate()  # cancelled: drop what is still in flight
    result.extra["workers"] = workers
    return result


class _PoolTask:
    def __init__(self, async_result):
        self._r = async_result

    def done(self) -> bool:
        return self._r.ready()

    def result(self):
        return self._r.get()


def drive(local, budget: Budget, submit, in_flight: int, progress=None, should_stop=None,
          label: str = "") -> RenderResult:
    """Hand out batch indices in increasing order through ``submit(k)`` (which returns an object with
    ``done()`` and ``result()``, the tuple of :func:`_run_batch`), keep at most ``in_flight`` running,
    and merge the contiguous prefix of finished batches in order until the budget is met: the rule of
    a single-process render, so the merged film is the same."""
    method = local.name
    done: dict[int, tuple] = {}
    pending: dict[int, object] = {}
    film = Film(local.eye.width, local.eye.height)
    rays = paths = found = truncated = merged = next_index = 0
    partial = False
    start = time.perf_counter()
    while True:
        budget_met = budget.fraction(rays, time.perf_counter() - start) >= 1.0
        if should_stop is not None and not budget_met and should_stop():
            partial = budget_met = True
        if partial:
            break
        if not budget_met:
            while len(pending) < in_flight:
                pending[next_index] = submit(next_index)
                next_index += 1
        elif not pending:
            break
        finished = [k for k, f in pending.items() if f.done()]
        if not finished:
            time.sleep(0.002)
            continue
        for k in finished:
            done[k] = pending.pop(k).result()
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
                         f"{method} {label}: {rays:,} rays, efficiency {eff:.2e}, {time.perf_counter() - start:.1f} s")
        if rays == 0 and merged > 0:
            break  # nothing to trace
    result = RenderResult(method, local.seed, film, rays, paths, found, time.perf_counter() - start, partial,
                          merged, list(local.warnings))
    if hasattr(local, "truncated"):
        local.truncated = truncated
    local.finish(result)
    return result


def films_match(a: RenderResult, b: RenderResult, rtol: float = 1e-12) -> bool:
    """Whether two results hold the same film up to rounding in the last bits (the determinism
    check of the tests: independent sampling would differ by far more)."""
    return (a.film.samples == b.film.samples and np.allclose(a.film.sum_rgb, b.film.sum_rgb, rtol=rtol, atol=0)
            and np.allclose(a.film.sum_y2, b.film.sum_y2, rtol=rtol, atol=0))
