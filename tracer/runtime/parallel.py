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

import atexit
import contextlib
import dataclasses
import hashlib
import importlib.machinery
import multiprocessing as mp
import os
import pickle
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
from ..transport.path import BatchAbandoned, abandon_when
from ..transport.world import World
from .allocator import keep_freed_memory

_WORKER: dict = {}
#: In a worker: the pool's count of renders ended (:attr:`WorkerPool.ended`); a batch handed out before
#: the count passed it belongs to a render that has ended, and is abandoned.
_ENDED = None
#: What a worker puts on the start-up queue once its world is built (otherwise: what went wrong).
READY = "ready"
#: Seconds the parent waits for its workers to start.
STARTUP_TIMEOUT = 600.0
#: Seconds a closed pool's workers have to exit once their batches are back (:meth:`WorkerPool.join`).
JOIN_GRACE = 5.0


def _init_worker(ready, ending, ended):
    """A worker's start: its signals (below), then the tracer's modules imported (what takes a fresh
    process most of its start-up), then READY on ``ready``. Scenes come with the batches
    (:func:`_job_integrator`), so that one pool serves every render of a session. Arguments are plain
    data: inside Blender nothing of the tracer can be unpickled before tracer/runtime/worker_bootstrap.py
    ran."""
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
    global _ENDED
    _ENDED = ended
    parent = mp.parent_process()
    if parent is not None:
        threading.Thread(target=_exit_with_parent, args=(parent.sentinel,), name="hud-parent-watch",
                         daemon=True).start()
    ready.put(READY)


def _exit_with_parent(sentinel: int):
    """A worker's watch on its parent: it ends the worker as soon as the parent process is gone, however it
    ended (its exit, SIGKILL). A worker outlived its parent otherwise: inside a batch until the batch was done,
    and for ever when the parent died holding the task queue's lock (CPython's Pool.terminate takes it and never
    gives it back): blocked on that lock, whose wait no signal handler interrupts when the signal lands on
    another of its threads. The orphan held the parent's stdout, so whoever read it waited too (Blender's exit
    in the add-on's tests, 1 in 2 runs of one scenario)."""
    from multiprocessing.connection import wait

    wait([sentinel])
    os._exit(0)


def job_of(local) -> tuple:
    """The job of a render by the integrator ``local`` (after its prepare), as :func:`_job_integrator` takes
    it. Its key, by which the workers keep its integrator, is what the batches trace; the scene's folder is
    left out (Blender exports each F12's scene into a folder of its own: the workers built the same world
    and integrator again), the scene's hash in."""
    job = (str(Path(local.scene.root)), local.name, local.seed, local.batch_size, local.worker_options(),
           dataclasses.asdict(local.eye.spec), local.scene.scene_hash, local.scene.allow_external)
    return hashlib.sha256(pickle.dumps(job[1:])).hexdigest(), *job


def _job_integrator(job: tuple):
    """The integrator of a render's ``job`` (a key that names it, scene folder, method, seed, batch size,
    options, eye, scene hash, external files allowed), built when a worker first traces one of its
    batches and kept until another render's batch comes: its own world (the scene folder's, seen by
    the parent's eye, the fields of an EyeSpec: a pupil that follows the image was chosen there), the
    integrator with the parent's options (what its prepare decided), and the roulette's pilot. The
    folder must still hold the parent's scene (``scene_hash``): one edited since, on disk or in the
    parent's memory, would render another scene in the workers. A scene that cannot be built raises
    RuntimeError "a worker process could not start: ...", which ends the render."""
    key, scene_dir, method, seed, batch_size, options, eye, scene_hash, allow_external = job
    if _WORKER.get("job") != key:
        _WORKER.pop("integrator", None)
        _WORKER.pop("job", None)
        try:
            scene = load_scene(scene_dir, allow_external=allow_external)
            if scene.scene_hash != scene_hash:
                raise RuntimeError(f"{scene_dir} holds another scene than the one the render began with (changed on "
                                   "disk since, or edited in memory: workers load the folder)")
            integrator = INTEGRATORS[method](World(scene, ThinLensEye(EyeSpec(**eye))), seed, batch_size, options)
            integrator.reference_luminance  # noqa: B018  (the pilot)
        except BatchAbandoned:  # its render ended during the pilot (_run_job_batch)
            raise
        except Exception as e:  # noqa: BLE001 - said to the parent in one line
            raise RuntimeError(f"a worker process could not start: {type(e).__name__}: {e}") from None
        _WORKER["integrator"], _WORKER["job"] = integrator, key
    return _WORKER["integrator"]


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


def _run_job_batch(job: tuple, index: int, render: int):
    """Batch ``index`` of render number ``render`` of the pool, or None where that render has ended
    before the batch began or while it ran: its batches are no longer merged, and a worker that went on
    took a core from the parent writing the outputs (docs/results/speed.md, a budget at any size)."""
    over = (lambda: _ENDED.value > render) if _ENDED is not None else (lambda: False)
    if over():
        return None
    try:
        with abandon_when(over):  # the world's pilot too, on the worker's first batch of the render
            return _job_integrator(job).trace_batch(index)
    except BatchAbandoned:
        return None


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


class WorkerPool:
    """``workers`` worker processes (spawned, with the stop signals blocked until their handlers are set)
    that serve every render of a session: the command line's sweep, Blender's F12 after F12. Each
    render hands its scene with its batches (:func:`_job_integrator`). Raises RuntimeError when no
    Python interpreter for the workers is found (:func:`python_executable`)."""

    def __init__(self, workers: int):
        executable = python_executable()
        if executable is None:
            raise RuntimeError(f"no Python interpreter to run worker processes (sys.executable is {sys.executable})")
        ctx = mp.get_context("spawn")
        ctx.set_executable(executable)
        quiet_resource_tracker()  # before the first semaphore: the queue's registers with it
        self.workers = workers
        self.ready_queue, self.ending = ctx.Queue(), ctx.Event()
        #: Renders ended on this pool (shared with the workers, read without a lock: one writer).
        self.ended = ctx.RawValue("q", 0)
        initializer, initargs = _worker_init((self.ready_queue, self.ending, self.ended))
        # The workers start with the stop signals blocked (a blocked mask survives fork and exec), so that a
        # Ctrl-C to the process group while they import does not end them with a traceback; _init_worker
        # unblocks them once its handlers are set. Blocked here, a signal to this process waits (it is not
        # lost) and lands when the mask is restored; the pool's own threads keep the mask and never take one.
        masked = hasattr(signal, "pthread_sigmask")
        previous_mask = signal.pthread_sigmask(signal.SIG_BLOCK, STOP_SIGNALS) if masked else None
        try:
            with _main_hidden():
                self.pool = ctx.Pool(workers, initializer=initializer, initargs=initargs)
        finally:
            if masked:
                signal.pthread_sigmask(signal.SIG_SETMASK, previous_mask)
        self.pids = {p.pid for p in self.pool._pool}  # the pool's processes (a private attribute, stable since 3.2)
        self.ready = 0
        self.t0 = time.perf_counter()
        self.startup_seconds: float | None = None
        self.used = False  # whether a batch was ever handed to it
        self._terminating: threading.Thread | None = None

    def poll_ready(self) -> int:
        """The workers that have started; RuntimeError when one could not, or a worker process exited
        while starting (the pool would start another in its place, forever)."""
        while self.ready < self.workers:
            try:
                msg = self.ready_queue.get_nowait()
            except queue.Empty:
                if {p.pid for p in self.pool._pool} - self.pids or any(p.exitcode is not None for p in self.pool._pool):
                    raise RuntimeError("a worker process exited while starting (see its message above)") from None
                if time.perf_counter() - self.t0 > STARTUP_TIMEOUT:
                    raise RuntimeError(f"the worker processes did not start within {STARTUP_TIMEOUT:.0f} s") from None
                break
            if msg != READY:
                raise RuntimeError(f"a worker process could not start: {msg}")
            self.ready += 1
            if self.ready == self.workers:
                self.startup_seconds = time.perf_counter() - self.t0
        return self.ready

    def alive(self) -> bool:
        return self.pool._state == "RUN" and all(p.exitcode is None for p in self.pool._pool)  # noqa: SLF001

    def close(self, terminate: bool = False, wait: bool = True):
        """End the workers: let them finish what they hold (at most two batches each) and exit, or (an
        error, an abort; a pool never used that nothing waits for) terminate them. Pool.terminate() can
        hang: in CPython's task handler after batches were handed out (waiting for the inqueue's lock,
        never released), and in its join of a worker blocked on the task queue's lock that a sibling
        ended by the terminate held (seen at Blender's unregister, with a pool never used). So a pool
        is closed and joined where something waits, and a terminate runs in a thread of its own that
        :meth:`join` waits for a bounded time. ``wait`` false: the workers exit on their own while this
        process goes on (:func:`close_shared_pool` joins them later).

        ``ending`` (the workers' SIGTERM ends them again) is set only to terminate: a closed pool's
        workers end on the pool's own sentinel after their batches. Set on close too, a stop signal
        to the process group that reached a worker inside a long C call (Embree, numpy) ran its handler
        after the parent had closed the pool: the worker exited mid-batch, the pool started another,
        and the join waited forever for the lost batch (3 in 25 group SIGTERMs mid-render).

        Pool.terminate() also waits for workers still starting to come up (a short render whose batches
        the parent traced itself waited for them before its outputs)."""
        if terminate or (not self.used and not wait):
            self.ending.set()
            self._terminating = threading.Thread(target=self.pool.terminate, name="hud-pool-terminate",
                                                 daemon=True)
            self._terminating.start()
        else:
            self.pool.close()
        if wait:
            self.join()

    def join(self):
        """Wait for a closed pool's workers: until every batch handed out has come back, then JOIN_GRACE
        seconds for the workers to take their sentinels and exit. A worker has been seen blocked for good
        on the task queue's lock after its sibling ended (the add-on's tests, Blender's exit: 600 s), and
        a plain join waited for it forever. One still there after the grace is killed (its work is done);
        the pool's threads are then left to end with the process (daemons), and its exit-time terminate
        is called off: a killed worker may hold one of the queues' locks, which both would wait for."""
        if self._terminating is not None:  # terminated in a thread of its own (:meth:`close`)
            self._terminating.join(JOIN_GRACE)
            if self._terminating.is_alive():  # a worker blocked where its SIGTERM handler never runs
                for p in list(self.pool._pool):  # noqa: SLF001
                    if p.exitcode is None:
                        p.kill()
                self._terminating.join(JOIN_GRACE)
            return
        pool = self.pool
        workers = list(pool._pool)  # noqa: SLF001  (the pool's processes: a private attribute, stable)
        while pool._cache and any(p.exitcode is None for p in workers):  # noqa: SLF001  (batches still out)
            time.sleep(0.05)
        deadline = time.monotonic() + JOIN_GRACE
        for p in workers:
            p.join(max(0.0, deadline - time.monotonic()))
        stuck = [p for p in workers if p.exitcode is None]
        if not stuck:
            pool.join()
            return
        for p in stuck:
            p.kill()
            p.join(JOIN_GRACE)
        pool._terminate.cancel()  # noqa: SLF001  (multiprocessing.util.Finalize of Pool._terminate_pool)


#: The session's pool (:func:`shared_pool`), and pools closed without waiting for their workers' exit.
_SHARED: list[WorkerPool] = []
_CLOSING: list[WorkerPool] = []
#: Whether the exit handler that ends the pool is registered (:func:`shared_pool`). At the interpreter's
#: exit the pool is terminated, not closed: closing and joining there can wait forever on a worker (the
#: command line and Blender close the pool before, when their work ends).
_EXIT_HOOK: list[bool] = []


def shared_pool(workers: int) -> WorkerPool:
    """The session's pool of ``workers`` processes: the one already running, or a new one (one of another
    size is closed first). :func:`close_shared_pool` ends it; so does the interpreter's exit."""
    if _SHARED and (_SHARED[0].workers != workers or not _SHARED[0].alive()):
        close_shared_pool()
    if not _SHARED:
        _SHARED.append(WorkerPool(workers))
        if not _EXIT_HOOK:
            # Registered after the first pool, and so after multiprocessing's own exit handler (registered
            # as the pool imports multiprocessing.util): handlers run in reverse, so ours ends the pool
            # first, with the workers told (``ending``) that their SIGTERM is the end. The other way
            # round, multiprocessing terminated the workers, which ignored a SIGTERM nobody had
            # announced, and joined them forever (hud-render, whose process exits with the pool open).
            atexit.register(close_shared_pool, terminate=True)
            _EXIT_HOOK.append(True)
    return _SHARED[0]


def close_shared_pool(terminate: bool = False, wait: bool = True):
    """End the session's pool, if any (Blender's unregister, the interpreter's exit, an error); with
    ``wait`` false its workers exit on their own while this process goes on (a render that no other
    follows: their memory is free for its outputs), and a later call joins them."""
    if _SHARED:
        pool = _SHARED.pop()
        pool.close(terminate, wait)
        if not wait:
            _CLOSING.append(pool)
    while wait and _CLOSING:
        _CLOSING.pop().join()




class PoolExecutor:
    """The driver's executor over a :class:`WorkerPool`: completions arrive on a queue. Until the first
    worker has started, the parent traces the batches it hands out itself (with ``local``, the
    render's own integrator), so that a short budget is not spent waiting for the workers to import
    the tracer; a batch is seed-addressed, so the image is the same whoever traced it. ``job``: the
    render's scene and integrator as the workers build them (:func:`_job_integrator`)."""

    def __init__(self, pool: WorkerPool, job: tuple, local):
        self.pool = pool
        self.workers = pool.workers
        self.job = job
        self.local = local
        self.done: queue.Queue = queue.Queue()
        self.render = pool.ended.value  # this render's number: the batches of earlier ones are abandoned

    def submit(self, index: int):
        if self.pool.poll_ready() == 0:
            return _Local(index)
        self.pool.used = True
        return self.pool.pool.apply_async(_run_job_batch, (self.job, index, self.render),
                                          callback=lambda _r, k=index: self.done.put(k),
                                          error_callback=lambda _e, k=index: self.done.put(k))

    def wait(self, handles: dict, timeout: float | None) -> list[int]:
        self.pool.poll_ready()
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
                    preview=None, keep_pool: bool = True) -> RenderResult:
    """Render with ``workers`` processes what the integrator ``local`` would render alone (its scene
    folder, method, seed and batch size; see the module docstring), on the session's pool
    (:func:`shared_pool`: started by the first render, kept for the next unless ``keep_pool`` is false:
    then it ends with this render, so that its workers' memory is free for the outputs). Raises RuntimeError when no
    Python interpreter for the workers is found (:func:`python_executable`), and
    :class:`tracer.core.validate.WorkersError` when the machine's memory does not hold ``workers``
    processes."""
    check_workers(workers, local.scene.eye.resolution)  # WorkersError before the pilot and any process
    # a time budget counts the pilot and the workers' start-up
    started = time.perf_counter() if budget.since is None else budget.since
    budget = local.prepare(budget)  # before the workers take the batch size and the options
    pool = shared_pool(workers)
    warm = pool.poll_ready() == workers
    try:
        result = drive(local, budget, PoolExecutor(pool, job_of(local), local), 2 * workers, progress, should_stop,
                       f"x{workers}", started=started, preview=preview)
    except BaseException:  # an error, or a second Ctrl-C (abort), at any point of the pool's life
        close_shared_pool(terminate=True)
        raise
    finally:
        pool.ended.value += 1  # the batches still out are dropped: the workers abandon them at their next bounce
    if not keep_pool:  # no render follows: the workers exit while the image is written
        close_shared_pool(wait=False)
    result.extra["workers"] = workers
    result.extra["startup_seconds"] = 0.0 if warm else pool.startup_seconds
    result.extra["pool"] = "reused" if warm else "started"
    return result
