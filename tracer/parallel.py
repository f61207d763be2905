"""Rendering on several cores: seed-addressed batches in worker processes, merged exactly.

Batch k of a render draws its random numbers from ``make_rng(seed, k)`` only (see
:mod:`tracer.integrators.base`), so its film does not depend on which process traced it. The same
driver (:func:`tracer.integrators.base.drive`) serves one process, local worker processes here and
Dask clusters in :mod:`tracer.distributed`. Workers (started with "spawn", each with its own render
world and Embree scene, built from the scene folder) trace batches handed out in increasing order;
the parent keeps every batch's film apart until the contiguous prefix 0..B-1 meets the budget, the
same rule a single process applies, and adds exactly that prefix in batch order. With a budget in
rays the image is therefore the same for any number of workers: the same batches, rays and paths,
and pixel values equal to the last bits of rounding. With a budget in seconds it is the prefix that
was done in time.

The clock of the budget starts when every worker has built its world (start-up is reported apart,
as ``startup_seconds``); the parent blocks on a queue that the pool's completion callbacks fill,
so it takes no CPU from the workers while it waits.
"""

from __future__ import annotations

import multiprocessing as mp
import queue
import signal
import time
from pathlib import Path

import numpy as np

from .allocator import keep_freed_memory
from .integrators import INTEGRATORS, Budget, RenderResult
from .integrators.base import drive
from .scene import load_scene

_WORKER: dict = {}


def _init_worker(scene_dir: str, method: str, seed: int, batch_size: int, ready):
    # The parent decides when to stop: a terminal's Ctrl-C or SIGHUP reaches the whole process group,
    # and a worker must not die of it mid-batch with a traceback. SIGTERM keeps its default (a quiet
    # exit): the pool ends its workers with it.
    for name in ("SIGINT", "SIGHUP"):
        if hasattr(signal, name):
            signal.signal(getattr(signal, name), signal.SIG_IGN)
    keep_freed_memory()  # a worker process exists to trace
    integrator = INTEGRATORS[method](load_scene(scene_dir), seed, batch_size)
    integrator.reference_luminance  # noqa: B018  (the pilot, before the clock starts)
    _WORKER["integrator"] = integrator
    ready.put(1)


def _run_batch(index: int):
    return _WORKER["integrator"].trace_batch(index)


class PoolExecutor:
    """The driver's executor over a multiprocessing pool: completions arrive on a queue."""

    def __init__(self, pool, workers: int):
        self.pool = pool
        self.workers = workers
        self.done: queue.Queue = queue.Queue()

    def submit(self, index: int):
        return self.pool.apply_async(_run_batch, (index,), callback=lambda _r, k=index: self.done.put(k),
                                     error_callback=lambda _e, k=index: self.done.put(k))

    def wait(self, handles: dict, timeout: float | None) -> list[int]:
        try:
            first = self.done.get(timeout=timeout)
        except queue.Empty:
            return []
        out = [first]
        while True:
            try:
                out.append(self.done.get_nowait())
            except queue.Empty:
                break
        return [k for k in out if k in handles]

    def result(self, handle):
        return handle.get()


def render_parallel(local, budget: Budget, workers: int = 2, progress=None, should_stop=None) -> RenderResult:
    """Render with ``workers`` processes what the integrator ``local`` would render alone (its scene
    folder, method, seed and batch size; see the module docstring)."""
    started = time.perf_counter()  # a time budget counts the pilot and the workers' start-up
    local.fit_batch(budget)  # before the workers take the batch size
    ctx = mp.get_context("spawn")
    ready = ctx.Queue()
    init = (str(Path(local.scene.root)), local.name, local.seed, local.batch_size, ready)
    t0 = time.perf_counter()
    with ctx.Pool(workers, initializer=_init_worker, initargs=init) as pool:
        for _ in range(workers):
            ready.get(timeout=600)
        startup = time.perf_counter() - t0
        result = drive(local, budget, PoolExecutor(pool, workers), 2 * workers, progress, should_stop, f"x{workers}",
                       started=started)
        # Batches still in flight are not needed, but the workers finish them (at most two each, of a
        # few hundred milliseconds) rather than be terminated mid-batch: Pool.terminate() then hung
        # now and then in CPython's task handler (waiting for the inqueue's lock, never released).
        pool.close()
        pool.join()
    result.extra["workers"] = workers
    result.extra["startup_seconds"] = startup
    return result


def films_match(a: RenderResult, b: RenderResult, rtol: float = 1e-12) -> bool:
    """Whether two results hold the same film up to rounding in the last bits (the determinism
    check of the tests: independent sampling would differ by far more)."""
    fa, fb = a.film, b.film
    return (fa.norm == fb.norm and fa.replicates == fb.replicates
            and all(np.allclose(fa.sums[k], fb.sums[k], rtol=rtol, atol=0) for k in fa.kinds)
            and np.allclose(fa.rep_sq, fb.rep_sq, rtol=rtol, atol=0))
