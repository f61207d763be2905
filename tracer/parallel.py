"""Rendering on several cores: seed-addressed batches in worker processes, merged exactly.

Batch k of a render draws its random numbers from ``make_rng(seed, k)`` only (see
:mod:`tracer.integrators.base`), so its film does not depend on which process traced it. The same
driver (:func:`tracer.integrators.base.drive`) serves one process, local worker processes here and
Dask clusters in :mod:`tracer.distributed`. Workers
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
from pathlib import Path

import numpy as np

from .integrators import INTEGRATORS, Budget, RenderResult
from .integrators.base import drive
from .scene import load_scene

_WORKER: dict = {}


def _init_worker(scene_dir: str, method: str, seed: int, batch_size: int):
    _WORKER["integrator"] = INTEGRATORS[method](load_scene(scene_dir), seed, batch_size)


def _run_batch(index: int):
    return _WORKER["integrator"].trace_batch(index)


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


def films_match(a: RenderResult, b: RenderResult, rtol: float = 1e-12) -> bool:
    """Whether two results hold the same film up to rounding in the last bits (the determinism
    check of the tests: independent sampling would differ by far more)."""
    return (a.film.samples == b.film.samples and np.allclose(a.film.sum_rgb, b.film.sum_rgb, rtol=rtol, atol=0)
            and np.allclose(a.film.sum_y2, b.film.sum_y2, rtol=rtol, atol=0))
