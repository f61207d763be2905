"""The seed-addressed batches of :mod:`tracer.runtime.parallel` on a Dask distributed cluster.

    from dask.distributed import Client
    client = Client("tcp://scheduler:8786")          # or a LocalCluster
    result = render_dask(integrator, Budget(rays=10**9), client)

The scene folder travels once to the cluster, zipped in memory (no shared file system is needed);
each worker unpacks it once, builds its own integrator and Embree scene, and traces the batches it
is given. The parent merges films in batch order with the same rule as a local render, so the same
seeds give the same image as one process. Dask is optional: ``pip install "dask[distributed]"``.
The command line's ``--scheduler ADDRESS`` (render, sweep, hud-render) and Blender's Performance >
Dask Scheduler connect through :func:`connect`.
"""

from __future__ import annotations

import dataclasses
import hashlib
import io
import pickle
import re
import shutil
import tempfile
import time
import zipfile
from pathlib import Path

from ..core.errors import TracerError
from ..methods import INTEGRATORS, Budget, RenderResult
from ..methods.base import drive
from ..scene import EyeSpec, load_scene
from ..transport.eye import ThinLensEye
from ..transport.world import World
from . import dask_task
from .allocator import keep_freed_memory
from .parallel import _WORKER, _run_batch  # noqa: F401  (the workers' cache is shared)

#: The tracer's import name in this process ("tracer"; inside Blender a subpackage of the add-on, which
#: Dask workers know as "tracer": tracer.runtime.dask_task carries the batches between the two names).
PACKAGE = __name__.rsplit(".", 2)[0]

#: Scene folders unpacked on this worker, by the zip's digest, least recently used first.
_UNPACKED: dict[str, str] = {}
#: How many unpacked scenes a worker keeps: a long-lived worker that renders a sweep's runs had kept a
#: copy of every run's scene in the temp folder.
KEEP_UNPACKED = 2


def pack_scene(folder) -> bytes:
    """The scene folder as zip bytes."""
    buf = io.BytesIO()
    root = Path(folder)
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED) as z:
        for p in sorted(root.rglob("*")):
            if p.is_file():
                z.write(p, p.relative_to(root).as_posix())
    return buf.getvalue()


def _batch_on_worker(blob: bytes, digest: str, method: str, seed: int, batch_size: int, options: dict, eye,
                     index: int):
    """Runs on a Dask worker: unpack the scene once, keep one integrator per render, trace a batch."""
    key = (digest, method, seed, batch_size, repr(options), repr(eye))
    if _WORKER.get("key") != key:
        keep_freed_memory()  # Dask's nanny sets MALLOC_TRIM_THRESHOLD_=65536: a batch took 4x as long
        world = World(load_scene(unpacked(blob, digest)), ThinLensEye(EyeSpec(**eye)))
        _WORKER["integrator"] = INTEGRATORS[method](world, seed, batch_size, options)
        _WORKER["key"] = key
    return _run_batch(index)


def unpacked(blob: bytes, digest: str) -> str:
    """The folder of the scene zipped in ``blob``: unpacked once into the Dask worker's local directory
    (which the worker removes when it closes; the temp folder outside a worker), and removed again when
    more than :data:`KEEP_UNPACKED` newer scenes have come since it was last used. The world built from
    it has read what it needs (a batch reads no scene file), so an older folder goes safely."""
    if digest in _UNPACKED:
        _UNPACKED[digest] = _UNPACKED.pop(digest)  # used again: the newest
        return _UNPACKED[digest]
    folder = Path(tempfile.mkdtemp(prefix="hud-dask-", dir=_local_directory()))
    with zipfile.ZipFile(io.BytesIO(blob)) as z:
        z.extractall(folder)
    _UNPACKED[digest] = str(folder)
    while len(_UNPACKED) > KEEP_UNPACKED:
        shutil.rmtree(_UNPACKED.pop(next(iter(_UNPACKED))), ignore_errors=True)
    return str(folder)


def _local_directory() -> str | None:
    """The Dask worker's own local directory, or None (the temp folder) outside a worker."""
    try:
        from distributed import get_worker

        return get_worker().local_directory
    except (ImportError, ValueError):
        return None


class DaskExecutor:
    """The driver's executor over a Dask client: futures, waited for with FIRST_COMPLETED, each a
    batch's result pickled by tracer.runtime.dask_task.run."""

    def __init__(self, client, submit, workers: int):
        self.client, self._submit, self.workers = client, submit, workers

    def submit(self, index: int):
        return self._submit(index)

    def wait(self, handles: dict, timeout: float | None) -> list[int]:
        from distributed import wait

        futures = {f: k for k, f in handles.items()}
        try:
            done, _ = wait(list(futures), timeout=timeout, return_when="FIRST_COMPLETED")
        except TimeoutError:
            return []
        return [futures[f] for f in done]

    def result(self, handle):
        return dask_task.result(handle.result(), PACKAGE)


#: Seconds to wait for a scheduler to answer.
CONNECT_TIMEOUT_S = 10.0
_CLIENTS: dict[str, object] = {}


class SchedulerError(TracerError):
    """The Dask scheduler named cannot be used: Dask is not installed, or the address does not answer."""


#: A scheduler's address: an optional protocol, a host (a name, an IPv4 or a bracketed IPv6 address) and a port.
ADDRESS = re.compile(r"(?:(?:tcp|tls|ws|wss|ucx)://)?(?:[^\s:/\[\]]+|\[[0-9A-Fa-f:.]+\]):(\d{1,5})")


def connect(address: str):
    """A client of the Dask scheduler at ``address`` ("tcp://host:8786"), kept for the session's next
    renders; :class:`SchedulerError` (naming the address) when it is not an address (:data:`ADDRESS`,
    a port up to 65535: Dask had said no scheduler answered there), when Dask is missing or the
    scheduler does not answer within :data:`CONNECT_TIMEOUT_S`, and when it has no worker."""
    if address in _CLIENTS:
        return _CLIENTS[address]
    m = ADDRESS.fullmatch(address)
    if m is None or not 0 < int(m.group(1)) < 65536:
        raise SchedulerError(f"{address}: not a scheduler's address; give HOST:PORT or tcp://HOST:PORT (a scheduler "
                             "started with `dask scheduler` listens on port 8786: tcp://HOST:8786)")
    try:
        from distributed import Client
    except ImportError:
        raise SchedulerError(f"{address}: rendering on a Dask cluster needs Dask in this environment "
                             "(pip install \"dask[distributed]\")") from None
    try:
        client = Client(address, timeout=CONNECT_TIMEOUT_S)
    except (OSError, TimeoutError, ValueError) as e:
        raise SchedulerError(f"{address}: no Dask scheduler answers there within {CONNECT_TIMEOUT_S:g} s "
                             f"({type(e).__name__}: {e}); start one with `dask scheduler` and workers with "
                             f"`dask worker {address}`") from None
    if not client.scheduler_info().get("workers"):
        try:
            client.wait_for_workers(1, timeout=CONNECT_TIMEOUT_S)
        except (OSError, TimeoutError) as e:
            client.close()
            raise SchedulerError(f"{address}: the scheduler has no worker ({type(e).__name__}); start them with "
                                 f"`dask worker {address}`") from None
    _CLIENTS[address] = client
    return client


def close_clients():
    """Close the session's clients (the command line does when its command ends)."""
    while _CLIENTS:
        _CLIENTS.popitem()[1].close()


def render_dask(local, budget: Budget, client, in_flight: int | None = None, progress=None,
                should_stop=None, preview=None) -> RenderResult:
    """Render on the cluster of ``client`` what the integrator ``local`` would render alone."""
    # a time budget counts the pilot and the upload of the scene
    started = time.perf_counter() if budget.since is None else budget.since
    budget = local.prepare(budget)  # before the batch size and the options travel to the workers
    blob = pack_scene(local.scene.root)
    digest = hashlib.sha256(blob).hexdigest()
    [blob_future] = client.scatter([blob], broadcast=True)
    workers = max(1, len(client.scheduler_info().get("workers", {})))
    arguments = pickle.dumps((digest, local.name, local.seed, local.batch_size, local.worker_options(),
                              dataclasses.asdict(local.eye.spec)), protocol=5)
    task = dask_task.task(PACKAGE)

    def submit(k):
        return client.submit(task, PACKAGE, blob_future, arguments, k, pure=False,
                             key=f"hud-batch-{digest[:12]}-{local.name}-{local.seed}-{local.batch_size}-{k}")

    result = drive(local, budget, DaskExecutor(client, submit, workers), in_flight or 2 * workers, progress,
                   should_stop, f"dask x{workers}", started=started, preview=preview)
    result.extra["dask_workers"] = workers
    result.extra["workers"] = workers
    result.extra["scheduler"] = client.scheduler.address
    return result
