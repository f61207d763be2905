"""Rendering on several cores: seed-addressed batches in worker processes, merged exactly.

Batch k of a render draws its random numbers from ``make_rng(seed, k)`` only (see
:mod:`tracer.methods.base`), so its film does not depend on which process traced it. The same
driver (:func:`tracer.methods.base.drive`) serves one process, local worker processes here and
Dask clusters in :mod:`tracer.runtime.distributed`. Workers (started with "spawn", each with its own render
world and Embree scene, built from the scene folder) trace batches handed out in increasing order;
the parent keeps every batch's film apart until the contiguous prefix 0..B-1 meets the budget, the
same rule a single process applies, and adds exactly that prefix in batch order. With a budget in
rays the image is therefore the same for any number of workers: the same batches, rays and paths,
and pixel values equal to the last bits of rounding. With a budget in seconds it is the prefix that
was done in time.

A time budget counts the workers' start-up (``startup_seconds``, until every worker has built its
world): until the first is ready the parent traces the batches itself (:class:`PoolExecutor`), then
it blocks on a queue that the pool's completion callbacks fill, so it takes no CPU from the workers
while it waits.

Workers are plain Python processes, whether the parent is the command line or Blender. Inside
Blender the tracer is a subpackage of the extension (``bl_ext.<repository>.hud_tracer.tracer``),
whose top packages Blender makes up at run time: a worker first recreates them from the parent's
package paths (:func:`_bootstrap`), so that the functions and results that cross between the
processes keep their names. The parent's main module (a Blender script, the console script) is
hidden from the workers: they need only the tracer.
"""

from __future__ import annotations

import contextlib
import dataclasses
import importlib.machinery
import multiprocessing as mp
import os
import queue
import signal
import sys
import threading
import time
import types
from pathlib import Path

from ..core.errors import STOP_SIGNALS
from ..core.validate import check_workers
from ..methods import INTEGRATORS, Budget, RenderResult
from ..methods.base import drive
from ..scene import EyeSpec, load_scene
from ..transport.eye import ThinLensEye
from ..transport.world import World
from .allocator import keep_freed_memory

_WORKER: dict = {}
#: What a worker puts on the start-up queue once its world is built (otherwise: what went wrong).
READY = "ready"
#: Seconds the parent waits for its workers to start.
STARTUP_TIMEOUT = 600.0


def _init_worker(scene_dir: str, method: str, seed: int, batch_size: int, options: dict, eye: dict, scene_hash: str,
                 allow_external: bool, ready, ending):
    """A worker's start: its own world (the scene folder's, seen by the parent's eye ``eye``, the fields
    of an EyeSpec: a pupil that follows the image was chosen there), the integrator of ``method`` with
    the parent's ``options`` (what its prepare decided), and the roulette's pilot. The folder must still
    hold the parent's scene (``scene_hash``): one edited since, on disk or in the parent's memory, would
    render another scene in the workers. Arguments are plain data: inside Blender nothing of the tracer
    can be unpickled before tracer/runtime/worker_bootstrap.py ran."""
    # The parent decides when to stop: a terminal's Ctrl-C or SIGHUP, and a batch scheduler's SIGTERM,
    # reach the whole process group, and a worker must not die of it mid-batch (the pool would start
    # another and wait for the lost batch forever). SIGTERM still ends a worker when the parent ends the
    # pool itself (``ending``, a multiprocessing Event, set first).
    for name in ("SIGINT", "SIGHUP"):
        if hasattr(signal, name):
            signal.signal(getattr(signal, name), signal.SIG_IGN)
    if hasattr(signal, "SIGTERM"):
        signal.signal(signal.SIGTERM, lambda _s, _f: os._exit(0) if ending.is_set() else None)
    if hasattr(signal, "pthread_sigmask"):  # blocked since the parent spawned us: what came meanwhile lands now
        signal.pthread_sigmask(signal.SIG_UNBLOCK, STOP_SIGNALS)
    keep_freed_memory()  # a worker process exists to trace
    try:
        scene = load_scene(scene_dir, allow_external=allow_external)
        if scene.scene_hash != scene_hash:
            raise RuntimeError(f"{scene_dir} holds another scene than the one the render began with (changed on disk "
                               "since, or edited in memory: workers load the folder)")
        integrator = INTEGRATORS[method](World(scene, ThinLensEye(EyeSpec(**eye))), seed, batch_size, options)
        integrator.reference_luminance  # noqa: B018  (the pilot, before the clock starts)
    except Exception as e:  # noqa: BLE001 - told to the parent, which stops the pool (a raise would respawn us)
        ready.put(f"{type(e).__name__}: {e}")
        return
    _WORKER["integrator"] = integrator
    ready.put(READY)


def quiet_resource_tracker():
    """Start multiprocessing's resource tracker with SIGHUP ignored (an ignored signal stays ignored in
    the child): a terminal's hang-up reaches the whole process group, and the tracker, which ignores
    SIGINT and SIGTERM only, printed KeyError tracebacks for the queues' semaphores as it died."""
    if not hasattr(signal, "SIGHUP") or threading.current_thread() is not threading.main_thread():
        return
    from multiprocessing import resource_tracker

    previous = signal.signal(signal.SIGHUP, signal.SIG_IGN)
    try:
        resource_tracker.ensure_running()
    finally:
        signal.signal(signal.SIGHUP, previous)


def _run_batch(index: int):
    return _WORKER["integrator"].trace_batch(index)


#: This package's import name ("tracer" on the command line; a subpackage inside Blender).
PACKAGE = __name__.rpartition(".")[0]


def _made_up_packages() -> list[tuple[str, list[str]]]:
    """(name, search path) of the packages above this one that a plain interpreter cannot import from
    ``sys.path`` (Blender's ``bl_ext`` and its repositories, which have no file of their own), outermost
    first; empty on the command line."""
    parts = PACKAGE.split(".")
    out = []
    for i in range(1, len(parts)):
        name = ".".join(parts[:i])
        module = sys.modules[name]
        origin = getattr(getattr(module, "__spec__", None), "origin", None)
        if origin and os.path.isfile(origin):
            break  # a package with its own __init__.py: it and what lies below import as usual
        if i == 1 and importlib.machinery.PathFinder.find_spec(name, sys.path) is not None:
            break
        out.append((name, list(getattr(module, "__path__", None) or [])))
    return out


def _worker_init(init_args: tuple):
    """(initializer, initargs) of the pool. Where this package imports under its own name in a plain
    interpreter, the initializer is :func:`_init_worker`; otherwise the made-up packages must exist
    before anything of this package can be unpickled in the worker, so the initializer is
    ``runpy.run_path`` (a standard-library function) of tracer/runtime/worker_bootstrap.py, a script that
    imports nothing of this package, with the arguments in its globals."""
    packages = _made_up_packages()
    if not packages:
        return _init_worker, init_args
    import runpy

    script = str(Path(__file__).with_name("worker_bootstrap.py"))
    return runpy.run_path, (script, {"ARGS": (packages, PACKAGE, init_args)}, "__hud_worker__")


def python_executable() -> str | None:
    """The Python interpreter that runs worker processes: ``sys.executable`` when it is one (the
    command line; Blender 2.91 and later point it at their bundled Python), else the interpreter under
    ``sys.prefix``, else None (no workers can start)."""
    name = Path(sys.executable).name.lower()
    if name.startswith("python"):
        return sys.executable
    for cand in (Path(sys.prefix) / "bin" / f"python{sys.version_info[0]}.{sys.version_info[1]}",
                 Path(sys.prefix) / "bin" / "python3", Path(sys.prefix) / "python.exe",
                 Path(sys.prefix) / "bin" / "python.exe"):
        if cand.is_file() and os.access(cand, os.X_OK):
            return str(cand)
    return None


@contextlib.contextmanager
def _main_hidden():
    """While workers start, the parent's main module is an empty one: "spawn" would otherwise run a
    Blender script or console script again in every worker, and workers need only this package."""
    saved = sys.modules.get("__main__")
    sys.modules["__main__"] = types.ModuleType("__main__")
    try:
        yield
    finally:
        if saved is not None:
            sys.modules["__main__"] = saved


class _Local:
    """A batch that the parent traces itself (handed out before any worker was ready)."""

    __slots__ = ("index", "result")

    def __init__(self, index: int):
        self.index, self.result = index, None


class PoolExecutor:
    """The driver's executor over a multiprocessing pool: completions arrive on a queue. Until the first
    worker has built its world (``starting``: the pool, its start-up queue and the integrator of the
    parent), the parent traces the batches it hands out itself, so that a short budget is not spent
    waiting for the workers to import the tracer and load the scene; a batch is seed-addressed, so the
    image is the same whoever traced it."""

    def __init__(self, pool, workers: int, ready_queue, local):
        self.pool = pool
        self.workers = workers
        self.done: queue.Queue = queue.Queue()
        self.ready_queue = ready_queue  # what workers put once their world is built; None once all are
        self.local = local
        self.ready = 0
        self.pids = {p.pid for p in pool._pool}  # the pool's processes (a private attribute, stable since 3.2)
        self.deadline = time.perf_counter() + STARTUP_TIMEOUT
        self.t0 = time.perf_counter()
        self.startup_seconds: float | None = None

    def _poll_ready(self):
        """Count the workers that have built their worlds; raise RuntimeError when one could not, or a worker
        process exited while starting (the pool would start another in its place, forever)."""
        if self.ready_queue is None:
            return
        while self.ready < self.workers:
            try:
                msg = self.ready_queue.get_nowait()
            except queue.Empty:
                if {p.pid for p in self.pool._pool} - self.pids or any(p.exitcode is not None for p in self.pool._pool):
                    raise RuntimeError("a worker process exited while starting (see its message above)") from None
                if time.perf_counter() > self.deadline:
                    raise RuntimeError(f"the worker processes did not start within {STARTUP_TIMEOUT:.0f} s") from None
                return
            if msg != READY:
                raise RuntimeError(f"a worker process could not start: {msg}")
            self.ready += 1
        self.startup_seconds = time.perf_counter() - self.t0
        self.ready_queue = None

    def submit(self, index: int):
        self._poll_ready()
        if self.ready == 0:
            return _Local(index)
        return self.pool.apply_async(_run_batch, (index,), callback=lambda _r, k=index: self.done.put(k),
                                     error_callback=lambda _e, k=index: self.done.put(k))

    def wait(self, handles: dict, timeout: float | None) -> list[int]:
        self._poll_ready()
        local = [k for k, h in handles.items() if isinstance(h, _Local)]
        out = []
        if local:  # trace the first of the parent's own batches now (what the workers finished meanwhile too)
            k = min(local)
            handles[k].result = self.local.trace_batch(k)
            out.append(k)
            timeout = 0.0
        try:
            out.append(self.done.get_nowait() if timeout == 0.0 else self.done.get(timeout=timeout))
        except queue.Empty:
            return out
        while True:
            try:
                out.append(self.done.get_nowait())
            except queue.Empty:
                break
        return [k for k in out if k in handles]

    def result(self, handle):
        return handle.result if isinstance(handle, _Local) else handle.get()


def render_parallel(local, budget: Budget, workers: int = 2, progress=None, should_stop=None,
                    preview=None) -> RenderResult:
    """Render with ``workers`` processes what the integrator ``local`` would render alone (its scene
    folder, method, seed and batch size; see the module docstring). Raises RuntimeError when no
    Python interpreter for the workers is found (:func:`python_executable`), and
    :class:`tracer.core.validate.WorkersError` when the machine's memory does not hold ``workers``
    processes."""
    check_workers(workers, local.scene.eye.resolution)  # WorkersError before the pilot and any process
    # a time budget counts the pilot and the workers' start-up
    started = time.perf_counter() if budget.since is None else budget.since
    budget = local.prepare(budget)  # before the workers take the batch size and the options
    executable = python_executable()
    if executable is None:
        raise RuntimeError(f"no Python interpreter to run worker processes (sys.executable is {sys.executable})")
    ctx = mp.get_context("spawn")
    ctx.set_executable(executable)
    quiet_resource_tracker()  # before the first semaphore: the queue's registers with it
    ready, ending = ctx.Queue(), ctx.Event()
    initializer, initargs = _worker_init((str(Path(local.scene.root)), local.name, local.seed, local.batch_size,
                                          local.worker_options(), dataclasses.asdict(local.eye.spec),
                                          local.scene.scene_hash, local.scene.allow_external, ready, ending))
    # The workers start with the stop signals blocked (a blocked mask survives fork and exec), so that a
    # Ctrl-C to the process group while they import does not end them with a traceback; _init_worker
    # unblocks them once its handlers are set. Blocked here, a signal to this process waits (it is not
    # lost) and lands when the mask is restored; the pool's own threads keep the mask and never take one.
    masked = hasattr(signal, "pthread_sigmask")
    previous_mask = signal.pthread_sigmask(signal.SIG_BLOCK, STOP_SIGNALS) if masked else None
    try:
        with _main_hidden():
            pool = ctx.Pool(workers, initializer=initializer, initargs=initargs)
    finally:
        if masked:
            signal.pthread_sigmask(signal.SIG_SETMASK, previous_mask)
    with pool:  # leaving it on an error terminates the workers
        try:
            executor = PoolExecutor(pool, workers, ready, local)
            result = drive(local, budget, executor, 2 * workers, progress, should_stop,
                           f"x{workers}", started=started, preview=preview)
            startup = executor.startup_seconds
            if executor.ready == 0:  # the parent traced every batch: the workers, still starting, are ended
                ending.set()
                pool.terminate()
            else:
                # Batches still in flight are not needed, but the workers finish them (at most two each, of a
                # few hundred milliseconds) rather than be terminated mid-batch: Pool.terminate() can hang in
                # CPython's task handler (waiting for the inqueue's lock, never released).
                pool.close()
                pool.join()
        except BaseException:  # an error, or a second Ctrl-C (abort), at any point of the pool's life
            ending.set()  # the workers' SIGTERM ends them again: the pool's terminate follows
            raise
    result.extra["workers"] = workers
    result.extra["startup_seconds"] = startup
    return result


