"""Parameter sweeps: one scene rendered over a grid of scene.json values and judged by requirements.

The paper's practical question (Potemin, Zhdanov et al., Proc. SPIE 10690, 106900I (2018), sec. 4.1):
the LED luminance at which the symbols stay legible while the rear-projection spot stays invisible
against the environment. A sweep renders a scene once per point of a grid of scene.json values,
reads each run's report (:func:`tracer.products.report.build_report`, its HUD figures from
:mod:`tracer.analysis.hud`) and says where every requirement holds.

- **Fields** (:func:`parse_field`): a dotted path into scene.json, ``eye.pupil_diameter_mm``,
  ``environment.calibration.value``, ``methods.backward.max_depth``, ``eye.position[2]`` (a list's
  element by its index), and objects by name with a glob (:func:`fnmatch.fnmatchcase`):
  ``objects[led_*].emission.luminance`` sets the field on every object whose name matches (an
  integer in the brackets is the index into the list, as the loader's messages write it). Every
  block on the path must exist (a sweep never gives an object an emission it lacks), except a
  method's options under ``methods``, whose defaults apply when they are absent; the last field
  may be absent, and the loader judges whether its block has it. Setting one of an emission's
  alternatives (``luminance``) removes the other (``flux``).
- **Grid**: each ``--set FIELD=START:STOP:N`` gives N values from START to STOP, evenly spaced, or
  geometrically for a field named by ``--log``; several make the cartesian product of their values
  (every combination; the first field varies slowest), at most :data:`MAX_RUNS` runs. Every grid
  point's scene is loaded through :func:`tracer.scene.load_scene` before the first ray, so that a
  value out of its field's range is refused with the field named, before any run.
- **Runs**: the scene folder is copied once into a temporary folder (hard links where the file system
  allows); for each run its scene.json is rewritten there and rendered with
  :func:`tracer.products.render.render_scene` (worker processes load the same folder). Every run has the same
  seed, so that runs differ by the parameter and not by the pattern of their noise: with a budget in
  rays, a luminance swept on the only light source scales the image exactly.
- **Requirements** (:func:`parse_requirement`): ``"KEY OP VALUE"``, KEY a dotted path into a run's
  report (``hud.contrast_ratio``, ``hud.spot.peak_over_median_background``, ``luminance.mean``), OP
  one of ``>= <= > <``, VALUE a number. A run whose report lacks KEY, or holds no number there,
  fails it, and sweep.json says why.
- **Recommendation** (:meth:`SweepResult.recommendation`): for a one-field sweep the runs that meet
  every requirement, grouped into intervals of the parameter between consecutive runs; an edge
  next to a failing run is where the failing requirements' figures cross their thresholds,
  interpolated linearly between the two runs (in log of the parameter for a ``--log`` field), so
  it is exact for a figure linear in the parameter (in its log) and within one step elsewhere; an
  edge at the first or last value of the sweep is open (the range may go on). For a grid, the runs
  that meet every requirement. When none does, "none" and the closest run: the one that fails the
  fewest requirements (then the fewest for want of the figure), then the one whose figures fall
  shortest of them (the sum of |figure - VALUE| / |VALUE| over those it fails).

Outputs (:func:`run_sweep`), in the output folder: ``runs/<k>/`` (each run's image.exr, preview.png
and report.json), ``sweep.csv`` (:func:`csv_text`), ``sweep.json`` (:meth:`SweepResult.summary`) and
``sweep.png`` (:func:`sweep_chart`). The runs are rendered into a hidden staging folder and moved into
``runs/`` with the three files after the last run, as one set (:mod:`tracer.products.outputs`): an earlier
sweep's runs and files are replaced together, and kept if writing fails.
"""

from __future__ import annotations

import copy
import csv
import io
import itertools
import json
import math
import os
import re
import shutil
import uuid
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from .. import __version__
from ..core.errors import SceneError, StoppedBeforeFirstBatch
from ..products import charts
from ..products.outputs import STAGING_PREFIX, OutputFile, OutputFolderError, OutputSet, OutputWriteError, png_file
from ..products.render import render_scene
from ..products.report import finite_json, report_unit
from ..scene import SCENE_FILE, Scene, load_scene
from .fields import MAX_RUNS, SweepArgumentError, SweepField, field_unit, lookup, parse_field, parse_set, path_text
from .requirements import Requirement, check_report_key, parse_requirement, run_figures

#: Most panels of the chart (``--y`` keys, or the required figures' keys: the first ones are drawn).
MAX_PANELS = 8
#: The sweep's files in the output folder, beside the runs folder.
OUTPUT_NAMES = ("sweep.csv", "sweep.json", "sweep.png")
RUNS = "runs"
#: The chart's panels when neither ``--y`` nor ``--require`` names any: the symbols' luminance and the
#: contrast ratio (tracer.analysis.hud).
DEFAULT_Y = ("hud.symbol_cd_m2", "hud.contrast_ratio")


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
                    y: list[str]) -> tuple[list[SweepField], list[Requirement]]:
    """Every argument's syntax and the number of runs, before the scene is read: (fields, requirements).
    Raises :class:`SweepArgumentError`."""
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
        check_report_key(f"--y {key}", steps)
    runs = math.prod(f.n for f in fields)
    if runs > MAX_RUNS:
        sizes = " x ".join(str(f.n) for f in fields)
        raise SweepArgumentError("--set", f"{sizes} = {runs} runs (every combination of the fields' values), more "
                                          f"than {MAX_RUNS}")
    return fields, [parse_requirement(r) for r in requires]


def _link_or_copy(src, dst):
    try:
        os.link(src, dst)
    except OSError:
        shutil.copy2(src, dst)


def plan_sweep(folder, fields: list[SweepField], requirements: list[Requirement], work_root, x: str | None = None,
               y: list[str] = (), progress=None) -> SweepPlan:
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
    y_keys = list(dict.fromkeys(y or [r.key for r in requirements] or DEFAULT_Y))
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


# -- running ------------------------------------------------------------------------------------------
@dataclass
class Run:
    """One rendered grid point: its index, values (one per field), report and where it was written."""

    index: int
    values: tuple
    report: dict

    @property
    def folder(self) -> str:
        return f"{RUNS}/{self.index}"

    @property
    def partial(self) -> bool:
        return bool(self.report["partial"])

    @property
    def found_light(self) -> bool:
        return self.report["paths_found_light"] > 0


@dataclass
class SweepResult:
    """A sweep (:func:`run_sweep`): its plan, how each run was rendered, and the runs done (all of the
    grid unless ``stopped``)."""

    plan: SweepPlan
    method: str
    seed: int
    budget: dict
    workers: int
    batch_size: int | None
    runs: list[Run] = field(default_factory=list)
    stopped: bool = False

    @property
    def partial(self) -> bool:
        return self.stopped or len(self.runs) < len(self.plan.grid)

    @property
    def judged(self) -> list[Run]:
        """The runs the recommendation judges: every run rendered to its budget (a run stopped early
        has no HUD figures: a stopped render skips the analysis)."""
        return [r for r in self.runs if not r.partial]

    def judge(self, run: Run) -> list[dict]:
        return [q.judge(run.report) for q in self.plan.requirements]

    def meets(self, run: Run) -> bool:
        return not run.partial and all(j["met"] for j in self.judge(run))

    def recommendation(self) -> dict:
        """See the module docstring. {"none": whether no judged run meets every requirement, "runs":
        those that do, "intervals" (one-field sweeps: [{"from", "to", "runs", "low", "high"}], each
        edge {"value", "interpolated", "between_runs", "limited_by"} or {"value", "open"}), "closest"
        (when none does), "note"}."""
        plan = self.plan
        judged = self.judged
        if not plan.requirements:
            return {"none": False, "runs": [r.index for r in judged], "intervals": [],
                    "note": "no requirements (--require): every run is listed, none is recommended over another"}
        meeting = [r for r in judged if self.meets(r)]
        out: dict = {"none": not meeting, "runs": [r.index for r in meeting]}
        if len(plan.fields) == 1:
            out["field"] = plan.fields[0].text
            out["intervals"] = self._intervals(judged)
        if not meeting and judged:
            out["closest"] = self._closest(judged)
        if not judged:
            out["note"] = "no run was rendered to its budget"
        return out

    def _intervals(self, judged: list[Run]) -> list[dict]:
        """The one-field sweep's intervals of runs that meet every requirement, with interpolated edges."""
        f = self.plan.fields[0]
        order = sorted(judged, key=lambda r: r.values[0])
        ok = [self.meets(r) for r in order]
        intervals = []
        i = 0
        while i < len(order):
            if not ok[i]:
                i += 1
                continue
            j = i
            while j + 1 < len(order) and ok[j + 1]:
                j += 1
            low = self._edge(order[i - 1], order[i], f) if i > 0 else \
                {"value": order[i].values[0], "open": True, "interpolated": False,
                 "why": "the lowest value judged meets every requirement: the range may extend below it"}
            high = self._edge(order[j + 1], order[j], f) if j + 1 < len(order) else \
                {"value": order[j].values[0], "open": True, "interpolated": False,
                 "why": "the highest value judged meets every requirement: the range may extend above it"}
            intervals.append({"from": low["value"], "to": high["value"], "runs": [r.index for r in order[i:j + 1]],
                              "low": low, "high": high})
            i = j + 1
        return intervals

    def _edge(self, failing: Run, passing: Run, f: SweepField) -> dict:
        """Where, between a failing run and its passing neighbour, the last of the requirements the
        failing run misses comes to hold: each figure interpolated linearly in the parameter (in its
        log for a --log field) at its threshold."""
        xa, xb = failing.values[0], passing.values[0]
        edge = {"between_runs": [failing.index, passing.index]}
        best, limited = 0.0, None
        for q, ja, jb in zip(self.plan.requirements, self.judge(failing), self.judge(passing), strict=True):
            if ja["met"]:
                continue
            if ja["value"] is None:  # nothing to interpolate from: the edge stays at the passing run
                return edge | {"value": xb, "interpolated": False, "limited_by": q.text,
                               "why": f"not interpolated: run {failing.index}: {ja['why']}"}
            va, vb = ja["value"], jb["value"]
            t = (q.value - va) / (vb - va)  # in [0, 1]: va misses the threshold, vb meets it
            if limited is None or t > best:
                best, limited = t, q.text
        if f.log:
            x = math.exp(math.log(xa) + best * (math.log(xb) - math.log(xa)))
        else:
            x = xa + best * (xb - xa)
        return edge | {"value": x, "interpolated": True, "limited_by": limited}

    def _closest(self, judged: list[Run]) -> dict:
        """The run that fails the fewest requirements, then the fewest for want of the figure, then the
        one whose figures fall shortest of the thresholds: the sum of |figure - VALUE| / |VALUE| over the
        requirements it fails and has the figure of (``relative_shortfall``)."""
        def score(run):
            failed = [(q, j) for q, j in zip(self.plan.requirements, self.judge(run), strict=True) if not j["met"]]
            absent = sum(j["value"] is None for _, j in failed)
            short = sum(abs(j["value"] - q.value) / max(abs(q.value), 1e-300) for q, j in failed
                        if j["value"] is not None)
            return len(failed), absent, short

        run = min(judged, key=score)
        return {"run": run.index, "values": self.plan.values(run.index),
                "fails": [j for j in self.judge(run) if not j["met"]], "relative_shortfall": score(run)[2]}

    def describe(self) -> str:
        """The recommendation in one line (stderr and the chart)."""
        rec = self.recommendation()
        if not self.plan.requirements:
            return f"{len(self.judged)} runs; no requirements given"
        if rec["none"]:
            if "closest" not in rec:
                return "no run was rendered to its budget"
            c = rec["closest"]
            return (f"no run meets every requirement; closest: run {c['run']} ("
                    + ", ".join(f"{k}={v:.4g}" for k, v in c["values"].items()) + "), which fails "
                    + "; ".join(j["requirement"] for j in c["fails"]))
        if "intervals" in rec:
            parts = []
            for iv in rec["intervals"]:
                lo = ("<= " if iv["low"].get("open") else "") + f"{iv['from']:.4g}"
                hi = f"{iv['to']:.4g}" + (" or more" if iv["high"].get("open") else "")
                parts.append(f"{lo} to {hi}" if iv["from"] != iv["to"] else f"{iv['from']:.4g}")
            return f"every requirement met for {rec['field']} " + " and ".join(parts)
        return f"{len(rec['runs'])} of {len(self.judged)} runs meet every requirement: runs " + \
            ", ".join(str(k) for k in rec["runs"])

    def run_line(self, run: Run) -> str:
        """One line on a run: its values, the chart's figures, and whether it meets the requirements."""
        plan = self.plan
        values = ", ".join(f"{name}={v:.4g}" for name, v in plan.values(run.index).items())
        figures = []
        for key in plan.y_keys:
            v, why = lookup(run.report, parse_field(key, globs=False))
            ok = why is None and not isinstance(v, bool) and isinstance(v, (int, float))
            figures.append(f"{key} {v:.4g}" if ok else f"{key} absent")
        line = f"run {run.index} ({run.index + 1} of {len(plan.grid)}): {values}: {', '.join(figures)}"
        if run.partial:
            return line + "; stopped early, not judged"
        if plan.requirements:
            failed = [j["requirement"] for j in self.judge(run) if not j["met"]]
            line += "; fails " + "; ".join(failed) if failed else "; meets every requirement"
        return line

    def summary(self) -> dict:
        """sweep.json."""
        plan = self.plan
        runs = []
        for r in self.runs:
            entry = {"run": r.index, "folder": r.folder, "run_id": r.report.get("run_id"),
                     "values": plan.values(r.index), "partial": r.partial, "found_light": r.found_light,
                     "figures": run_figures(r.report), "requirements": self.judge(r),
                     "meets_requirements": self.meets(r), "warnings": r.report.get("warnings", [])}
            runs.append(entry)
        return {
            "tracer": f"hud-tracer {__version__}",
            "scene": {"name": plan.scene_name, "folder": str(plan.folder),
                      "note": "each run's report.json names the temporary working copy it was rendered from"},
            "method": self.method, "seed": self.seed,
            "same_seed": "every run uses the same seed, so that runs differ by their values, not by the pattern "
                         "of their noise",
            "budget_per_run": self.budget, "workers": self.workers, "batch_size": self.batch_size,
            "grid": {"fields": [{"field": f.text, "scale": "log" if f.log else "linear", "start": f.start,
                                 "stop": f.stop, "n": f.n, "values": f.values,
                                 "targets": [path_text(p) for p, _ in f.targets],
                                 "replaces": sorted({path_text((*p[:-1], k)) for p, rm in f.targets for k in rm})}
                                for f in plan.fields],
                     "product": "cartesian: every combination of the fields' values, the first field varying slowest",
                     "runs": len(plan.grid)},
            "requirements": [{"requirement": q.text, "key": q.key, "op": q.op, "value": q.value}
                             for q in plan.requirements],
            "partial": self.partial,
            "runs_done": len(self.runs),
            "runs": runs,
            "recommendation": self.recommendation(),
            "recommendation_text": self.describe(),
        }


def open_outputs(out_dir, scene=None) -> OutputSet:
    """The sweep's output folder, checked and locked before anything is read or traced
    (:meth:`tracer.products.outputs.OutputSet.open` for its three files, outside the folder of ``scene`` (a scene
    folder or its scene.json) where given; its ``runs``, where it exists, must be a folder):
    :class:`~tracer.products.outputs.OutputFolderError` if it cannot take the sweep. Close it when done."""
    root = None if scene is None else (Path(scene).parent if Path(scene).name == SCENE_FILE else Path(scene))
    outputs = OutputSet(out_dir, OUTPUT_NAMES, scene_root=root).open()
    runs_dir = outputs.folder / RUNS
    if runs_dir.is_symlink() or (runs_dir.exists() and not runs_dir.is_dir()):
        outputs.close()
        raise OutputFolderError(runs_dir, "exists and is not a folder; the sweep would write its runs there")
    return outputs


def run_sweep(plan: SweepPlan, method: str, budget, seed: int, outputs: OutputSet, workers: int = 1,
              batch_size: int | None = None, progress=None, should_stop=None, on_run=None) -> SweepResult:
    """Render every grid point of ``plan`` with ``method``, ``budget`` (tracer.methods.Budget, per run)
    and ``seed`` (the same for every run) on ``workers`` processes, and write the sweep into the folder
    of ``outputs`` (:func:`open_outputs`; see the module docstring). ``progress(fraction, message)``
    follows the whole sweep; ``should_stop()`` true stops the current run as a render stops (its
    batches so far, marked partial) and starts no other: what was done is written, marked partial.
    ``on_run(result, run)`` is called after each run.

    Raises :class:`~tracer.products.outputs.OutputWriteError` if writing fails (the folder keeps its earlier
    sweep); KeyboardInterrupt (a second Ctrl-C) leaves the folder as it was."""
    folder = outputs.folder
    staging = folder / f"{STAGING_PREFIX}runs-{uuid.uuid4().hex}"
    staging.mkdir()
    try:
        result = SweepResult(plan, method, seed, {"rays": budget.rays, "seconds": budget.seconds}, workers,
                             batch_size)
        n = len(plan.grid)
        for k in range(n):
            if should_stop is not None and should_stop():
                result.stopped = True
                break
            scene = plan.load(k)
            try:
                report, rendered = render_scene(scene, method, budget, seed, staging / RUNS / str(k),
                                                progress=_run_progress(progress, k, n), should_stop=should_stop,
                                                batch_size=batch_size, workers=workers)
            except StoppedBeforeFirstBatch:  # the run has no estimate: the sweep ends with the runs before it
                result.stopped = True
                break
            run = Run(k, plan.grid[k], report)
            result.runs.append(run)
            if on_run is not None:
                on_run(result, run)
            if rendered.partial:
                result.stopped = True
                break
        _commit(outputs, output_files(result), staging / RUNS, folder / RUNS)
        outputs.keep()
    finally:
        shutil.rmtree(staging, ignore_errors=True)
    return result


def _run_progress(progress, k: int, n: int):
    if progress is None:
        return None
    return lambda fraction, message: progress((k + fraction) / n, f"run {k} ({k + 1} of {n}): {message}")


def _commit(outputs: OutputSet, files: list[OutputFile], new_runs: Path, runs_dir: Path):
    """Move the runs into place and write the sweep's files as one set: the earlier runs folder is
    renamed aside, the new one into its place, the files committed (:meth:`OutputSet.commit`); if
    that fails, the earlier runs are put back."""
    folder = runs_dir.parent
    old = folder / f"{STAGING_PREFIX}old-runs-{uuid.uuid4().hex}"
    new_runs.mkdir(parents=True, exist_ok=True)  # a sweep stopped before its first run has none
    moved_old = moved_new = False
    try:
        if runs_dir.exists():
            os.rename(runs_dir, old)
            moved_old = True
        os.rename(new_runs, runs_dir)
        moved_new = True
        outputs.commit(files)
    except BaseException as e:
        try:
            if moved_new:
                os.rename(runs_dir, new_runs)
            if moved_old:
                os.rename(old, runs_dir)
        except OSError:
            pass
        if isinstance(e, OSError):
            raise OutputWriteError(folder, f"moving the runs into place failed ({e}); the earlier outputs are "
                                           "kept") from None
        raise
    shutil.rmtree(old, ignore_errors=True)


# -- sweep.csv ----------------------------------------------------------------------------------------
def csv_columns(result: SweepResult) -> list[str]:
    """sweep.csv's header: run, the fields, every figure any run has (first seen first), partial,
    meets_requirements."""
    figures: dict[str, None] = {}
    for r in result.runs:
        figures |= dict.fromkeys(run_figures(r.report))
    return ["run", *(f.text for f in result.plan.fields), *figures, "partial", "meets_requirements"]


def csv_rows(result: SweepResult) -> list[dict]:
    """One dict per run, by column; a figure the run lacks is None (an empty cell)."""
    cols = csv_columns(result)
    rows = []
    for r in result.runs:
        row = dict.fromkeys(cols)
        row |= {"run": r.index, **result.plan.values(r.index), **run_figures(r.report),
                "partial": int(r.partial), "meets_requirements": int(result.meets(r))}
        rows.append(row)
    return rows


def _cell(v) -> str:
    if v is None:
        return ""
    return str(v) if isinstance(v, int) else repr(float(v))


def csv_text(result: SweepResult) -> str:
    """sweep.csv: the header of :func:`csv_columns`, then one row per run; numbers in their shortest
    form that reads back exactly (integers as integers), empty cells for figures a run lacks."""
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    cols = csv_columns(result)
    w.writerow(cols)
    for row in csv_rows(result):
        w.writerow([_cell(row[c]) for c in cols])
    return buf.getvalue()


def read_csv(path) -> list[dict]:
    """sweep.csv read back: one dict per row by column, integers as int, other numbers as float, empty
    cells as None."""
    with open(path, newline="") as fh:
        rows = list(csv.reader(fh))
    head = rows[0]
    if not head or head[0] != "run" or head[-1] != "meets_requirements":
        raise ValueError(f"{path}: not a sweep.csv (header {head[:3]} ...)")

    def number(s):
        if s == "":
            return None
        return int(s) if re.fullmatch(r"-?\d+", s) else float(s)

    return [dict(zip(head, map(number, row), strict=True)) for row in rows[1:]]


def _series(result: SweepResult) -> list[tuple[str, list[Run]]]:
    """(label, runs in order of x) for each combination of the fields other than x."""
    plan = result.plan
    xi = plan.fields.index(plan.x)
    groups: dict[tuple, list[Run]] = {}
    for r in result.runs:
        groups.setdefault(tuple(v for i, v in enumerate(r.values) if i != xi), []).append(r)
    others = [f.text for i, f in enumerate(plan.fields) if i != xi]
    out = []
    for key, runs in groups.items():
        label = ", ".join(f"{name}={v:.4g}" for name, v in zip(others, key, strict=True))
        out.append((label, sorted(runs, key=lambda r: r.values[xi])))
    return out


def sweep_chart(result: SweepResult) -> tuple[np.ndarray, dict]:
    """sweep.png (:func:`tracer.products.charts.sweep_chart`): one panel per key of ``plan.y_keys`` (at
    most :data:`MAX_PANELS`), the runs' figure against the x field (``plan.x``), one line per
    combination of the other fields' values, drawn between runs as the recommendation interpolates
    (linear in the parameter, in its log for a --log field, so that a line crosses a threshold at the
    interval's edge); log axes where the values span more than a decade (and for a --log field); each
    requirement on the panel's key a dashed red line, the one-field recommendation's intervals shaded,
    the runs that meet every requirement filled. Returns (rgb, geometry) with the sweep's own keys
    ("x_field", "series") added to the geometry."""
    plan = result.plan
    xi = plan.fields.index(plan.x)
    rec = result.recommendation()
    shaded = [[iv["from"], iv["to"]] for iv in rec.get("intervals", [])] if plan.requirements else []
    panels = []
    for key in plan.y_keys[:MAX_PANELS]:
        steps = parse_field(key, globs=False)
        points = {}
        for r in result.runs:
            v, why = lookup(r.report, steps)
            if why is None and not isinstance(v, bool) and isinstance(v, (int, float)) and math.isfinite(v):
                points[r.index] = float(v)
        panels.append({"key": key, "unit": report_unit(key), "points": points, "shaded": shaded,
                       "thresholds": [{"requirement": q.text, "value": q.value}
                                      for q in plan.requirements if q.key == key]})
    series = []
    for label, runs in _series(result):
        curves = {}
        for a, b in zip(runs[:-1], runs[1:], strict=True):
            for panel in panels:
                pts = panel["points"]
                if a.index in pts and b.index in pts:  # a run without the figure breaks the line
                    t = np.linspace(0.0, 1.0, 64)
                    xa, xb = a.values[xi], b.values[xi]
                    xs = np.exp(np.log(xa) + t * np.log(xb / xa)) if plan.x.log else xa + t * (xb - xa)
                    curves.setdefault(panel["key"], {})[a.index] = (xs, pts[a.index] + t * (pts[b.index]
                                                                                         - pts[a.index]))
        series.append({"label": label, "runs": [r.index for r in runs], "meets": {r.index: result.meets(r)
                                                                               for r in runs}, "curves": curves})
    xs = {r.index: float(r.values[xi]) for r in result.runs}
    x = {"field": plan.x.text, "unit": field_unit(plan.x.steps), "values": xs,
         "log": plan.x.log or charts.is_log(list(xs.values()) or [1.0])}
    budget = f"{result.budget['rays']:,} rays" if result.budget["rays"] else f"{result.budget['seconds']:g} s"
    caption = [f"{plan.scene_name}: sweep of {len(plan.grid)} runs, {result.method}, {budget} per run, seed "
               f"{result.seed}" + (f", stopped after {len(result.runs)}" if result.partial else ""),
               result.describe()]
    rgb, geometry = charts.sweep_chart(panels, x, series, caption)
    return rgb, geometry | {"x_field": plan.x.text, "series": [s["label"] for s in series]}


# -- the output set -----------------------------------------------------------------------------------
def output_files(result: SweepResult) -> list[OutputFile]:
    """sweep.csv, sweep.json (with the chart's geometry) and sweep.png, each with its read-back check."""
    rgb, geometry = sweep_chart(result)
    summary = result.summary() | {"chart": geometry}
    text = finite_json(summary, "sweep.json")
    table = csv_text(result)
    rows = csv_rows(result)

    def check_json(p):
        if json.loads(Path(p).read_text()) != json.loads(text):
            raise ValueError("the JSON read back differs from what was written")

    def check_csv(p):
        if read_csv(p) != rows:
            raise ValueError("the table read back differs from what was written")

    def write_csv(p):
        with open(p, "w", newline="") as fh:
            fh.write(table)

    return [OutputFile("sweep.csv", write_csv, check_csv),
            OutputFile("sweep.json", lambda p: Path(p).write_text(text), check_json),
            png_file("sweep.png", rgb)]
