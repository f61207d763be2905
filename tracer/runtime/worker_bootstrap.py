"""Run in a worker process by ``runpy.run_path`` (tracer.runtime.parallel._worker_init) when the tracer is a
subpackage whose top packages a plain interpreter cannot import (inside Blender:
``bl_ext.<repository>.hud_tracer.tracer``). It imports nothing of the tracer before it has made up
those packages, as empty packages over the parent's search paths, so that the functions and results
that cross between the processes keep their names; then it builds the worker's integrator.

Globals given by run_path: ``ARGS = (packages, package, init_args)`` with ``packages`` [(name, search
path)], outermost first, ``package`` the tracer's full name and ``init_args`` those of
tracer.runtime.parallel._init_worker.
"""

import importlib
import sys
import types


def bootstrap(packages, package, init_args):
    for name, path in packages:
        if name not in sys.modules:
            module = types.ModuleType(name)
            module.__path__ = list(path)
            sys.modules[name] = module
            parent, _, child = name.rpartition(".")
            if parent:
                setattr(sys.modules[parent], child, module)
    importlib.import_module(f"{package}.parallel")._init_worker(*init_args)


if __name__ == "__hud_worker__":
    bootstrap(*ARGS)  # noqa: F821  (given in the globals of this run)
