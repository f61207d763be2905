"""What a Dask worker runs for a render's batch, whatever name the tracer has in the process that renders.

A Dask worker is a plain Python process in which the tracer is the top package ``tracer``
(docs/user/cluster.md). The process that renders may know it by another name: inside Blender it is a
subpackage of the add-on (``bl_ext.<repository>.hud_tracer.tracer``), which no worker can import. What
crosses between them therefore names no module of the tracer:

- the task is :func:`run`, which imports nothing of the tracer by its own name; where the renderer's
  tracer is not ``tracer``, it travels by value (:func:`task`), so the worker needs only the standard
  library to load it;
- the batch's arguments travel as pickle bytes, loaded on the worker with the renderer's package name
  read as ``tracer``; the batch's result comes back as pickle bytes, loaded by :func:`result` with
  ``tracer`` read as the renderer's name;
- a worker's error comes back as a RuntimeError with the worker's message (an exception of the tracer's
  own classes could not be loaded by the renderer).

This module imports nothing of the tracer (it is pickled by value).
"""

from __future__ import annotations

import io
import pickle
import sys

#: The tracer's name on a Dask worker.
WORKER_PACKAGE = "tracer"


def _renaming_loads(data: bytes, old: str, new: str):
    """``pickle.loads(data)``, with the classes and functions of package ``old`` taken from ``new``."""

    class Renaming(pickle.Unpickler):
        def find_class(self, module, name):
            if module == old or module.startswith(old + "."):
                module = new + module[len(old):]
            return super().find_class(module, name)

    return Renaming(io.BytesIO(data)).load()


def run(package: str, blob: bytes, arguments: bytes, index: int) -> bytes:
    """Runs on a Dask worker: batch ``index`` of the render whose other arguments (tracer.runtime.distributed.
    _batch_on_worker's, but the scene's zip ``blob``) are pickled in ``arguments`` by a renderer that
    knows the tracer as ``package``; returns the batch's result, pickled."""
    import importlib

    try:
        args = _renaming_loads(arguments, package, WORKER_PACKAGE)
        batch = importlib.import_module(f"{WORKER_PACKAGE}.runtime.distributed")._batch_on_worker
        return pickle.dumps(batch(blob, *args, index), protocol=5)
    except Exception as e:
        if package == WORKER_PACKAGE:
            raise
        raise RuntimeError(f"on the Dask worker: {type(e).__name__}: {e}") from None


def result(data: bytes, package: str):
    """A batch's result as :func:`run` returned it, for a renderer that knows the tracer as ``package``."""
    if package == WORKER_PACKAGE:
        return pickle.loads(data)
    return _renaming_loads(data, WORKER_PACKAGE, package)


def task(package: str):
    """The function to submit: :func:`run` where the renderer's tracer is the workers' ``tracer``; else a
    local function that calls it, with this module registered to be pickled by value. Dask pickles a task
    with the standard pickle where it can, which would name this module by the renderer's name, one no
    worker can import; a local function it cannot pickle that way, so it takes cloudpickle, which copies
    the function and this module's functions it calls."""
    if package == WORKER_PACKAGE:
        return run
    import cloudpickle

    cloudpickle.register_pickle_by_value(sys.modules[__name__])

    def batch(*args):
        return run(*args)

    return batch
