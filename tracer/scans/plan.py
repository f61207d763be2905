"""A sweep's plan: its arguments checked, its fields resolved in the scene, the grid of their values,
and every grid point's scene loaded before the first ray (tracer.scans.sweep).

Each ``--set FIELD=START:STOP:N`` gives N values from START to STOP, evenly spaced, or geometrically for a
field named by ``--log``; several make the cartesian product of their values (every combination; the first
field varies slowest), at most :data:`tracer.scans.fields.MAX_RUNS` runs. Every grid point's scene is
loaded through :func:`tracer.scene.load_scene` before the first ray, so that a value out of its field's
range is refused with the field named, before any run. The scene folder is copied once into a temporary
folder (hard links where the file system allows), whose scene.json each run rewrites.
"""

from __future__ import annotations

import copy
import itertools
import json
import math
import os
import shutil
import uuid
from dataclasses import dataclass, replace
from pathlib import Path

from ..core.errors import SceneError
from ..scene import SCENE_FILE, Scene, load_scene
from .fields import MAX_RUNS, SweepArgumentError, SweepField, parse_field, parse_set, path_text
from .requirements import Requirement, check_report_key, parse_requirement

#: Most panels of the chart (``--y`` keys, or the required figures' keys: the first ones are drawn).
MAX_PANELS = 8


#: The chart's panels when neither ``--y`` nor ``--require`` names any: the symbols' luminance and the
#: contrast ratio (tracer.analysis.hud).
DEFAULT_Y = ("hud.symbol_cd_m2", "hud.contrast_ratio")
#: The same for a sweep of the optical analysis (--optics).
OPTICS_Y = ("optics.design_eye.ghost_separation_centre_arcmin", "optics.design_eye.static_distortion_mrad")


# -- the plan: fields resolved, every grid point validated ----------------------------------------------
@dataclass
class SweepPlan:
    """What a sweep will render: the scene (``folder``, as given; ``work``, the private copy whose
    scene.json is rewritten for each run), its parsed scene.json ``base``, the fields, the grid
    (``grid[k]``: run k's value of each field, the cartesian product in the fields' order), the
    requirements, the field on the chart's x axis and the keys of its panels."""

    folder: Path
    scene_name: str
    work: Path
    base: dict
    fields: list[SweepField]
    grid: list[tuple]
    requirements: list[Requirement]
    x: SweepField
    y_keys: list[str]

    def scene_text(self, k: int) -> str:
        """scene.json of run ``k``: the base scene with the run's values set."""
        raw = copy.deepcopy(self.base)
        for f, v in zip(self.fields, self.grid[k], strict=True):
            for path, removed in f.targets:
                node = raw
                for step in path[:-1]:
                    if isinstance(step, str) and step not in node:
                        node[step] = {}  # a method's options block (SweepField.resolve allows no other)
                    node = node[step]
                node[path[-1]] = v
                for key in removed:
                    node.pop(key, None)
        return json.dumps(raw, indent=2) + "\n"

    def load(self, k: int) -> Scene:
        """Run ``k``'s scene, written into the working copy and loaded from there (the loader's checks,
        and the same folder that worker processes load). Raises :class:`~tracer.core.errors.SceneError`."""
        target = self.work / SCENE_FILE
        staged = self.work / f".{SCENE_FILE}.{uuid.uuid4().hex}"
        staged.write_text(self.scene_text(k), encoding="utf-8")
        os.replace(staged, target)  # a new file: never written through a hard link to the original
        return load_scene(self.work)

    def values(self, k: int) -> dict[str, int | float]:
        return {f.text: v for f, v in zip(self.fields, self.grid[k], strict=True)}


def check_arguments(sets: list[str], log: list[str], requires: list[str], x: str | None,
                    y: list[str], optics: bool = False) -> tuple[list[SweepField], list[Requirement]]:
    """Every argument's syntax and the number of runs, before the scene is read: (fields, requirements).
    ``optics``: a sweep of the optical analysis, whose keys lie in ``optics``. Raises
    :class:`SweepArgumentError`."""
    if not sets:
        raise SweepArgumentError("--set", "give at least one FIELD=START:STOP:N")
    fields = [parse_set(s) for s in sets]
    names = [f.text for f in fields]
    for i, name in enumerate(names):
        if name in names[:i]:
            raise SweepArgumentError(fields[i].argument, f"{name} is set twice")
    for name in log:
        if name not in names:
            raise SweepArgumentError(f"--log {name}", f"names no --set field (they are: {', '.join(names)})")
    for i, f in enumerate(fields):
        if f.text in log:
            if f.start <= 0 or f.stop <= 0:
                raise SweepArgumentError(f.argument, f"--log makes the values geometric: START and STOP must be > 0, "
                                                     f"got {f.start:g} and {f.stop:g}")
            fields[i] = replace(f, log=True)
    if x is not None and x not in names:
        raise SweepArgumentError(f"--x {x}", f"names no --set field (they are: {', '.join(names)})")
    if len(y) > MAX_PANELS:
        raise SweepArgumentError("--y", f"{len(y)} panels, more than {MAX_PANELS}")
    for key in y:
        try:
            steps = parse_field(key, globs=False)
        except ValueError as e:
            raise SweepArgumentError(f"--y {key}", str(e)) from None
        check_report_key(f"--y {key}", steps, optics)
    runs = math.prod(f.n for f in fields)
    if runs > MAX_RUNS:
        sizes = " x ".join(str(f.n) for f in fields)
        raise SweepArgumentError("--set", f"{sizes} = {runs} runs (every combination of the fields' values), more "
                                          f"than {MAX_RUNS}")
    return fields, [parse_requirement(r, optics) for r in requires]


def _link_or_copy(src, dst):
    try:
        os.link(src, dst)
    except OSError:
        shutil.copy2(src, dst)


def plan_sweep(folder, fields: list[SweepField], requirements: list[Requirement], work_root, x: str | None = None,
               y: list[str] = (), progress=None, default_y: tuple[str, ...] = DEFAULT_Y) -> SweepPlan:
    """Resolve ``fields`` in the scene at ``folder`` and load every grid point's scene once (see the
    module docstring), all before any ray. ``work_root``: an empty temporary folder for the working
    copy. Raises :class:`~tracer.core.errors.SceneError` for the scene as given, and
    :class:`SweepArgumentError` naming the argument for everything the sweep makes of it."""
    folder = Path(folder)
    folder = folder.parent if folder.name == SCENE_FILE and folder.is_file() else folder
    base_scene = load_scene(folder)
    base = base_scene.raw
    fields = [f.resolve(base) for f in fields]
    seen: dict[tuple, SweepField] = {}
    for f in fields:
        for path, _removed in f.targets:
            if path in seen:
                raise SweepArgumentError(f.argument, f"{path_text(path)} is set by {seen[path].argument} too")
            seen[path] = f
    for f in fields:
        for path, removed in f.targets:
            for key in removed:
                other = seen.get((*path[:-1], key))
                if other is not None:
                    raise SweepArgumentError(f.argument, f"{path_text(path)} replaces {key!r}, which {other.argument} "
                                                         "sets: an emission is given by one of the two")
    work = Path(work_root) / folder.resolve().name
    shutil.copytree(folder, work, symlinks=False, copy_function=_link_or_copy,
                    ignore=lambda d, names: [SCENE_FILE] if Path(d) == folder else [])
    grid = list(itertools.product(*(f.values for f in fields)))
    x_field = next(f for f in fields if f.text == x) if x is not None else fields[0]
    y_keys = list(dict.fromkeys(y or [r.key for r in requirements] or default_y))
    plan = SweepPlan(folder, base_scene.name, work, base, fields, grid, requirements, x_field, y_keys)
    for k in range(len(grid)):
        try:
            plan.load(k)
        except SceneError as e:
            raise _grid_point_error(plan, k, e) from None
        if progress is not None:
            progress((k + 1) / len(grid), f"checked the scene of grid point {k + 1} of {len(grid)}")
    return plan


def _grid_point_error(plan: SweepPlan, k: int, e: SceneError) -> SweepArgumentError:
    """The loader's refusal of run ``k``'s scene, named by the --set whose value it is."""
    file = SCENE_FILE if Path(e.file).resolve() == (plan.work / SCENE_FILE).resolve() else e.file
    where = f"{file}: {e.field}" if e.field else file
    values = plan.values(k)
    for f in plan.fields:
        for path, _ in f.targets:
            p = path_text(path)
            if e.field == p or e.field.startswith((f"{p}.", f"{p}[")):
                return SweepArgumentError(f.argument, f"the value {values[f.text]:g} (grid point {k + 1} of "
                                                      f"{len(plan.grid)}): "
                                                      f"{where}: {e.message}")
    point = ", ".join(f"{name}={v:g}" for name, v in values.items())
    return SweepArgumentError("--set", f"grid point {k + 1} of {len(plan.grid)} ({point}): {where}: {e.message}")
