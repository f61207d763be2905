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
import difflib
import io
import itertools
import json
import math
import operator
import os
import re
import shutil
import uuid
from dataclasses import dataclass, field, replace
from fnmatch import fnmatchcase
from pathlib import Path

import numpy as np

from .. import __version__
from ..core.errors import SceneError, StoppedBeforeFirstBatch
from ..products.falsecolour import FONT, GLYPH_H, INK, PAPER, colour_map, draw_text, png_file, text_size, value_label
from ..products.outputs import STAGING_PREFIX, OutputFile, OutputFolderError, OutputSet, OutputWriteError
from ..products.render import render_scene
from ..products.report import REPORT_SECTIONS, finite_json
from ..scene import SCENE_FILE, Scene, load_scene
from ..sources.lights import EMISSION

#: Most runs a sweep may have: a grid of about 8 x 8 x 8. Each run writes its images (1.5 MB for
#: hud-direct), and every grid point's scene is loaded before the first ray (0.2 s each for hud-direct).
MAX_RUNS = 500
#: Most panels of the chart (``--y`` keys, or the required figures' keys: the first ones are drawn).
MAX_PANELS = 8
#: The sweep's files in the output folder, beside the runs folder.
OUTPUT_NAMES = ("sweep.csv", "sweep.json", "sweep.png")
RUNS = "runs"
#: Comparison operators of a requirement.
OPS = {">=": operator.ge, "<=": operator.le, ">": operator.gt, "<": operator.lt}
#: The chart's panels when neither ``--y`` nor ``--require`` names any: the symbols' luminance and the
#: contrast ratio (tracer.analysis.hud).
DEFAULT_Y = ("hud.symbol_cd_m2", "hud.contrast_ratio")
#: The parts of a report whose numeric leaves are a run's figures (sweep.csv's columns), in order.
FIGURES = ("hud", "luminance", "adaptation_luminance", "noise", "rays", "seconds", "efficiency")
#: Relative distance to an integer within which a value of an integer field is that integer (geometric
#: values are rounded by the floating-point powers).
INTEGER_TOLERANCE = 1e-9


class SweepArgumentError(ValueError):
    """A sweep argument that cannot be run: ``argument`` names it (``--set FIELD=...``), ``message``
    says why."""

    def __init__(self, argument: str, message: str):
        self.argument, self.message = argument, message
        super().__init__(f"{argument}: {message}")


# -- paths into JSON ----------------------------------------------------------------------------------
_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")
#: Marks a block or field that the scene does not hold yet.
MISSING = object()


def parse_field(text: str, globs: bool = True) -> tuple[tuple[str, object], ...]:
    """The steps of a dotted path: ("key", name), ("index", i) or, after a top-level ``objects`` when
    ``globs``, ("glob", pattern). Raises ValueError saying what is malformed."""
    steps: list[tuple[str, object]] = []
    i, n = 0, len(text)
    if not text:
        raise ValueError("empty path")
    while True:
        m = _NAME.match(text, i)
        if not m:
            raise ValueError(f"expected a field name at character {i + 1}")
        steps.append(("key", m.group()))
        i = m.end()
        while i < n and text[i] == "[":
            depth, j = 0, i
            while j < n:
                depth += {"[": 1, "]": -1}.get(text[j], 0)
                if depth == 0:
                    break
                j += 1
            if j >= n:
                raise ValueError(f"the '[' at character {i + 1} is not closed")
            sel = text[i + 1:j]
            if re.fullmatch(r"\d+", sel):
                steps.append(("index", int(sel)))
            elif globs and steps == [("key", "objects")] and sel:
                steps.append(("glob", sel))
            else:
                where = "an object's name (a glob) or an index" if globs and steps == [("key", "objects")] else \
                    "an index (only objects[...] takes a name)"
                raise ValueError(f"[{sel}] at character {i + 1}: expected {where}")
            i = j + 1
        if i == n:
            return tuple(steps)
        if text[i] != ".":
            raise ValueError(f"unexpected {text[i]!r} at character {i + 1}")
        i += 1


def path_text(path: tuple) -> str:
    """A concrete path as the loader's messages write it: ``objects[10].emission.luminance``."""
    out = ""
    for step in path:
        out += f"[{step}]" if isinstance(step, int) else (f".{step}" if out else step)
    return out


def lookup(data, steps) -> tuple[object, str | None]:
    """(value, None) at ``steps`` (from :func:`parse_field` without globs) in ``data``, or (None, why)."""
    node, done = data, ()
    for kind, arg in steps:
        here = path_text(done) or "the report"
        if kind == "key":
            if not isinstance(node, dict):
                return None, f"{here} is not a block"
            if arg not in node:
                return None, f"{here} has no field {arg!r}"
        else:
            if not isinstance(node, list) or not 0 <= arg < len(node):
                return None, f"{here} has no element [{arg}]"
        node, done = node[arg], (*done, arg)
    return node, None


def numeric_leaves(value, prefix: str) -> dict[str, int | float]:
    """Every number in ``value`` (nested blocks and lists) by its dotted key path; booleans, strings
    and nulls are left out."""
    out: dict[str, int | float] = {}
    if isinstance(value, bool) or value is None:
        return out
    if isinstance(value, (int, float)):
        out[prefix] = value
    elif isinstance(value, dict):
        for k, v in value.items():
            out |= numeric_leaves(v, f"{prefix}.{k}" if prefix else k)
    elif isinstance(value, list):
        for i, v in enumerate(value):
            out |= numeric_leaves(v, f"{prefix}[{i}]")
    return out


def run_figures(report: dict) -> dict[str, int | float]:
    """A run's figures (the columns of sweep.csv): every numeric leaf of the report's :data:`FIGURES`."""
    out: dict[str, int | float] = {}
    for key in FIGURES:
        out |= numeric_leaves(report.get(key), key)
    return out


# -- fields and their grid ----------------------------------------------------------------------------
@dataclass(frozen=True)
class SweepField:
    """One ``--set FIELD=START:STOP:N`` (``given``): ``text`` the FIELD, ``steps`` its path, N values from
    ``start`` to ``stop`` (geometric if ``log``). ``targets`` (after :meth:`resolve`): each concrete
    path it sets, with the keys that setting it removes (an emission's other alternative);
    ``integer``: every target holds an integer, so the values are written as integers."""

    given: str
    text: str
    steps: tuple
    start: float
    stop: float
    n: int
    log: bool = False
    targets: tuple[tuple[tuple, tuple[str, ...]], ...] = ()
    integer: bool = False

    @property
    def argument(self) -> str:
        return f"--set {self.given}"

    @property
    def values(self) -> list[int | float]:
        """The N values, START first and STOP last."""
        if self.n == 1:
            v = [self.start]
        elif self.log:
            v = np.geomspace(self.start, self.stop, self.n)
        else:
            v = np.linspace(self.start, self.stop, self.n)
        out: list[int | float] = [float(x) for x in v]
        if self.integer:
            out = [int(round(x)) if abs(x - round(x)) <= INTEGER_TOLERANCE * max(1.0, abs(x)) else x for x in out]
        return out

    def resolve(self, raw: dict) -> SweepField:
        """This field with its targets in the scene ``raw`` (scene.json parsed); raises
        :class:`SweepArgumentError` for a path the scene does not have."""
        def bad(message):
            raise SweepArgumentError(self.argument, message)

        branches = [((), raw, None)]  # (path, node, the glob that chose the object)
        for depth, (kind, arg) in enumerate(self.steps):
            last = depth == len(self.steps) - 1
            nxt = []
            for path, node, glob in branches:
                where = _describe(raw, path, glob)
                if kind == "key":
                    if node is MISSING:
                        nxt.append(((*path, arg), MISSING, glob))
                    elif not isinstance(node, dict):
                        bad(f"{where} is {_what(node)}: it has no field {arg!r}")
                    elif arg in node:
                        nxt.append(((*path, arg), node[arg], glob))
                    elif last or _may_create((*path, arg)):
                        nxt.append(((*path, arg), MISSING, glob))
                    else:
                        fields = ", ".join(sorted(node)) or "none"
                        hint = f"; narrow the glob {glob!r}" if glob else ""
                        bad(f"{where} has no field {arg!r} (its fields: {fields}){hint}")
                elif kind == "index":
                    if not isinstance(node, list):
                        bad(f"{where} is {_what(node)}, not a list: [{arg}] addresses nothing")
                    if arg >= len(node):
                        bad(f"{where} has {len(node)} entries: [{arg}] is out of range")
                    nxt.append(((*path, arg), node[arg], glob))
                else:
                    if not isinstance(node, list):
                        bad(f"{where} is {_what(node)}, not a list of objects")
                    hits = [i for i, o in enumerate(node)
                            if isinstance(o, dict) and isinstance(o.get("name"), str) and fnmatchcase(o["name"], arg)]
                    if not hits:
                        names = [o.get("name") for o in node if isinstance(o, dict) and isinstance(o.get("name"), str)]
                        listed = ", ".join(names[:12]) + (f" and {len(names) - 12} more" if len(names) > 12 else "")
                        literal = [i for i, o in enumerate(node) if isinstance(o, dict) and o.get("name") == arg]
                        hint = (f"; names are globs (*, ? and [...] match), so address it by its index, "
                                f"objects[{literal[0]}]" if literal else "")
                        bad(f"no object's name matches {arg!r} (objects: {listed or 'none'}){hint}")
                    nxt += [((*path, i), node[i], arg) for i in hits]
            branches = nxt
        targets, integer = [], True
        for path, value, glob in branches:
            where = _describe(raw, path, glob)
            if isinstance(value, dict):
                bad(f"{where} is a block, not a value: name one of its fields ({', '.join(sorted(value)) or 'none'})")
            if isinstance(value, list):
                bad(f"{where} is a list of {len(value)} values: name one of them, as {path_text(path)}[0]")
            if isinstance(value, bool):
                bad(f"{where} is {json.dumps(value)}: only numbers can be swept")
            integer &= isinstance(value, int)
            targets.append((path, _replaced_alternatives(raw, path)))
        return replace(self, targets=tuple(targets), integer=integer)


def _may_create(path: tuple) -> bool:
    """A block that may be missing: ``methods`` and a method's options (their defaults apply)."""
    return path == ("methods",) or (len(path) == 2 and path[0] == "methods")


def _what(node) -> str:
    if isinstance(node, dict):
        return "a block"
    if isinstance(node, list):
        return f"a list of {len(node)}"
    return json.dumps(node)[:40]


def _describe(raw: dict, path: tuple, glob: str | None) -> str:
    """A path for a message, with the name of the object it goes through."""
    text = path_text(path) or "scene.json"
    if len(path) >= 2 and path[0] == "objects" and isinstance(path[1], int):
        name = raw["objects"][path[1]].get("name")
        if isinstance(name, str):
            text += f" (object {name!r}{f', matched by {glob!r}' if glob else ''})"
    return text


def _replaced_alternatives(raw: dict, path: tuple) -> tuple[str, ...]:
    """The keys that setting ``path`` removes from its block: the other alternatives of an emission
    (luminance or flux), in an ``emission`` block or a legacy ``emitter`` material."""
    if len(path) != 4 or path[0] != "objects" or path[2] not in ("emission", "material"):
        return ()
    block = raw["objects"][path[1]].get(path[2])
    if path[2] == "material" and not (isinstance(block, dict) and block.get("type") == "emitter"):
        return ()
    key = path[3]
    if not any(key in alt for alt in EMISSION.alternatives):
        return ()
    return tuple(k for alt in EMISSION.alternatives if key not in alt for k in alt)


def parse_set(text: str) -> SweepField:
    """``FIELD=START:STOP:N`` as a :class:`SweepField` (not yet resolved in a scene). Raises
    :class:`SweepArgumentError`."""
    argument = f"--set {text}"
    name, eq, spec = text.rpartition("=")
    if not eq:
        raise SweepArgumentError(argument, "expected FIELD=START:STOP:N")
    try:
        steps = parse_field(name)
    except ValueError as e:
        raise SweepArgumentError(argument, f"field {name!r}: {e}") from None
    parts = spec.split(":")
    if len(parts) != 3:
        raise SweepArgumentError(argument, f"expected START:STOP:N after '=', got {spec!r}")
    try:
        start, stop = float(parts[0]), float(parts[1])
    except ValueError:
        raise SweepArgumentError(argument, f"START and STOP must be numbers, got {parts[0]!r} and {parts[1]!r}") \
            from None
    if not (math.isfinite(start) and math.isfinite(stop)):
        raise SweepArgumentError(argument, "START and STOP must be finite")
    if not re.fullmatch(r"\s*[+-]?\d+\s*", parts[2]):
        raise SweepArgumentError(argument, f"N must be a whole number of values, got {parts[2]!r}")
    n = int(parts[2])
    if n < 1:
        raise SweepArgumentError(argument, f"N must be >= 1 (the number of values), got {n}")
    if n == 1 and start != stop:
        raise SweepArgumentError(argument, f"N = 1 gives one value: START and STOP must be equal, got {start:g} "
                                           f"and {stop:g}")
    if n > MAX_RUNS:
        raise SweepArgumentError(argument, f"{n} values, more than the {MAX_RUNS} runs a sweep may have")
    return SweepField(text, name, steps, start, stop, n)


# -- requirements -------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Requirement:
    """``KEY OP VALUE``: the figure at ``key`` (a dotted path into a run's report) compared with ``value``."""

    text: str
    key: str
    steps: tuple
    op: str
    value: float

    def judge(self, report: dict) -> dict:
        """{"requirement", "value" (the figure, or None), "met", and "why" where it is not met}."""
        v, why = lookup(report, self.steps)
        if why is None and (isinstance(v, bool) or not isinstance(v, (int, float))):
            why = f"{self.key} is {json.dumps(v)[:40]}, not a number"
        if why is not None:
            return {"requirement": self.text, "value": None, "met": False, "why": why}
        met = bool(OPS[self.op](v, self.value))
        out = {"requirement": self.text, "value": v, "met": met}
        if not met:
            out["why"] = f"{self.key} is {v:.6g}"
        return out


def check_report_key(argument: str, steps) -> None:
    """A report key's first name must be a section of every report (tracer.products.report.REPORT_SECTIONS), so
    that a mistyped key is refused before the runs rather than found missing in each. (What lies below
    a section depends on the scene and the method: a run whose report lacks it fails the requirement.)
    Raises :class:`SweepArgumentError`."""
    name = steps[0][1]
    if name not in REPORT_SECTIONS:
        near = difflib.get_close_matches(name, REPORT_SECTIONS, n=1)
        hint = f"did you mean {near[0]!r}? " if near else ""
        raise SweepArgumentError(argument, f"{name!r} is not a section of a run's report.json ({hint}the sections "
                                           f"are: {', '.join(REPORT_SECTIONS)})")


_REQUIREMENT = re.compile(r"\s*(?P<key>[^\s<>=!]+)\s*(?P<op>>=|<=|==|=|!=|>|<)\s*(?P<value>[^\s<>=!]\S*)\s*")


def parse_requirement(text: str) -> Requirement:
    """``"KEY OP VALUE"`` (spaces optional) as a :class:`Requirement`. Raises :class:`SweepArgumentError`."""
    argument = f"--require {text}"
    m = _REQUIREMENT.fullmatch(text)
    if not m:
        raise SweepArgumentError(argument, "expected \"KEY OP VALUE\", KEY a dotted path into the report "
                                           "(hud.contrast_ratio), OP one of >= <= > <, VALUE a number")
    key, op, value = m["key"], m["op"], m["value"]
    if op not in OPS:
        raise SweepArgumentError(argument, f"OP {op!r}: must be one of {' '.join(OPS)}")
    try:
        steps = parse_field(key, globs=False)
    except ValueError as e:
        raise SweepArgumentError(argument, f"KEY {key!r}: {e}") from None
    check_report_key(argument, steps)
    try:
        v = float(value)
    except ValueError:
        raise SweepArgumentError(argument, f"VALUE must be a number, got {value!r}") from None
    if not math.isfinite(v):
        raise SweepArgumentError(argument, f"VALUE must be finite, got {value!r}")
    return Requirement(f"{key} {op} {value}", key, steps, op, v)


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


# -- sweep.png ----------------------------------------------------------------------------------------
#: The chart's plot box per panel, px per font pixel (x 2 at the default scale: 560 x 180 px; wider where the
#: caption is).
PLOT_W, PLOT_H = 280, 90
#: Requirement thresholds (dashed), the recommended range and the grid lines.
THRESHOLD, SHADE, GRID_LINE = (230, 0, 0), (214, 238, 214), (226, 226, 226)
#: Colour map positions of the series (one per combination of the other fields' values).
SERIES_T = (0.0, 0.8)


@dataclass
class Axis:
    """A chart axis from ``lo`` to ``hi`` (data units; log10-spaced if ``log``) with ``ticks``."""

    lo: float
    hi: float
    log: bool
    ticks: list[float]

    def frac(self, v: float) -> float:
        u = (lambda t: math.log10(t)) if self.log else (lambda t: t)
        return (u(v) - u(self.lo)) / (u(self.hi) - u(self.lo))


def _nice_step(span: float, target: int = 5) -> float:
    raw = span / target
    e = math.floor(math.log10(raw))
    f = raw / 10.0**e
    return (1 if f < 1.5 else 2 if f < 3.5 else 5 if f < 7.5 else 10) * 10.0**e


def _linear_ticks(lo: float, hi: float, step: float | None = None) -> list[float]:
    """Multiples of ``step`` (default: a 1-2-5 step of about a fifth of the span) within [lo, hi]."""
    step = step or _nice_step(hi - lo)
    first = math.ceil(lo / step - 1e-9)
    return [float(f"{k * step:.12g}") for k in range(first, math.floor(hi / step + 1e-9) + 1)]


def _log_ticks(lo: float, hi: float) -> list[float]:
    """Decades within [lo, hi]; with fewer than 3, also 2 and 5 times them, then every integer multiple."""
    e0, e1 = math.floor(math.log10(lo)), math.ceil(math.log10(hi))
    for mantissas in ((1,), (1, 2, 5), tuple(range(1, 10))):
        ticks = [m * 10.0**e for e in range(e0, e1 + 1) for m in mantissas if lo * (1 - 1e-9) <= m * 10.0**e <=
                 hi * (1 + 1e-9)]
        if len(ticks) >= 3:
            break
    if len(ticks) > 10:
        k = math.ceil(len(ticks) / 8)
        ticks = ticks[::k]
    return ticks if len(ticks) >= 2 else _linear_ticks(lo, hi)


def _is_log(values: list[float]) -> bool:
    """Log axis where the values are positive and span more than a decade."""
    return bool(values) and min(values) > 0 and max(values) > 10 * min(values)


def x_axis(values: list[float], geometric: bool = False) -> Axis:
    """The x axis: the values' span padded by 4 % on each side; in log10 where they span more than a
    decade or are ``geometric`` (a --log field: evenly spaced in log, and interpolated in log)."""
    log = _is_log(values) or (geometric and min(values) > 0 and max(values) > min(values))
    lo, hi = min(values), max(values)
    if log:
        a, b = math.log10(lo), math.log10(hi)
        pad = 0.04 * (b - a)
        lo, hi = 10.0 ** (a - pad), 10.0 ** (b + pad)
        return Axis(lo, hi, True, _log_ticks(lo, hi))
    if hi == lo:
        d = 0.1 * abs(lo) or 1.0
        lo, hi = lo - d, hi + d
    pad = 0.04 * (hi - lo)
    lo, hi = lo - pad, hi + pad
    return Axis(lo, hi, False, _linear_ticks(lo, hi))


def y_axis(values: list[float]) -> Axis:
    """A panel's y axis over ``values`` (the runs' figures and the thresholds): whole decades for a log
    axis, whole tick steps for a linear one."""
    if not values:
        return Axis(0.0, 1.0, False, [0.0, 0.5, 1.0])
    lo, hi = min(values), max(values)
    if _is_log(values):
        lo, hi = 10.0 ** math.floor(math.log10(lo)), 10.0 ** math.ceil(math.log10(hi))
        return Axis(lo, hi, True, _log_ticks(lo, hi))
    if hi == lo:
        d = 0.1 * abs(lo) or 1.0
        lo, hi = lo - d, hi + d
    step = _nice_step(hi - lo)
    lo, hi = math.floor(lo / step + 1e-9) * step, math.ceil(hi / step - 1e-9) * step
    return Axis(lo, hi, False, _linear_ticks(lo, hi, step))


def tick_label(v: float) -> str:
    """A tick's label: 0, or :func:`tracer.products.falsecolour.value_label` with its sign."""
    if v == 0:
        return "0"
    return ("-" if v < 0 else "") + value_label(abs(v))


def _fit(text: str, chars: int = 120) -> str:
    """``text`` cut to ``chars`` characters, with "..." where it was cut."""
    return text if len(text) <= chars else text[:chars - 3] + "..."


def _drawable(text: str) -> str:
    """``text`` in the bitmap font's characters ("?" for any other)."""
    return "".join(c if c in FONT else "?" for c in text)


def _polyline(canvas, rows, cols, colour, width, clip):
    """The line through the pixels (``rows``, ``cols``) in order, ``width`` px thick, within ``clip``
    (top, left, bottom, right; ends exclusive)."""
    rs, cs = [], []
    for r0, c0, r1, c1 in zip(rows[:-1], cols[:-1], rows[1:], cols[1:], strict=True):
        n = max(abs(r1 - r0), abs(c1 - c0)) + 1
        rs.append(np.rint(np.linspace(r0, r1, n)).astype(int))
        cs.append(np.rint(np.linspace(c0, c1, n)).astype(int))
    if not rs:
        return
    rows, cols = np.concatenate(rs), np.concatenate(cs)
    h = width // 2
    top, left, bottom, right = clip
    for dr in range(-h, width - h):
        for dc in range(-h, width - h):
            r, c = rows + dr, cols + dc
            keep = (r >= top) & (r < bottom) & (c >= left) & (c < right)
            canvas[r[keep], c[keep]] = colour


def _marker(canvas, r, c, half, colour, filled, ring):
    block = canvas[r - half:r + half + 1, c - half:c + half + 1]
    if filled:
        block[:] = colour
    else:
        block[:ring] = colour
        block[-ring:] = colour
        block[:, :ring] = colour
        block[:, -ring:] = colour


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


def sweep_chart(result: SweepResult, scale: int = 2) -> tuple[np.ndarray, dict]:
    """The sweep's chart: (rgb (H, W, 3) uint8 sRGB, geometry).

    One panel per key of ``plan.y_keys``: the runs' figure against the x field (``plan.x``), a line and
    a marker per run (filled where the run meets every requirement, hollow where it does not), one
    line per combination of the other fields' values (in colours of the colour map, with a legend);
    log axes where the values span more than a decade; each requirement on the panel's key as a
    dashed red line at its threshold; the one-field recommendation's intervals shaded green. A
    caption says what was swept and the recommendation. ``scale``: font pixels per glyph pixel.

    The geometry: {"width", "height", "panels": [{"key", "box" (top, left, height, width of the plot
    box), "x" and "y" ({"lo", "hi", "log", "ticks": [{"value", "px"}]}: columns for x, rows for y),
    "thresholds" [{"requirement", "value", "row"}], "shaded" [[first, last column]], "points" [{"run",
    "row", "column", "meets"}]}]}; a pixel's row r shows the value at fraction (bottom - r) / (height - 1)
    of the axis from its bottom row, ``bottom`` = top + height - 1."""
    s = scale
    plan = result.plan
    text_h = text_size("0", s)[0]
    up_ = (GLYPH_H * s) // 2
    margin, tick, lw = 3 * s, 2 * s, 2 * (s // 2) + 1
    ph = PLOT_H * s
    xi = plan.fields.index(plan.x)
    xa = x_axis([float(v) for v in plan.x.values], plan.x.log)
    series = _series(result)
    positions = np.linspace(*SERIES_T, len(series)) if len(series) > 1 else [0.25] * len(series)
    colours = [tuple(int(c) for c in colour_map(t)) for t in positions]
    keys = plan.y_keys[:MAX_PANELS]
    rec = result.recommendation()
    panels = []
    for key in keys:
        steps = parse_field(key, globs=False)
        vals = {}
        for r in result.runs:
            v, why = lookup(r.report, steps)
            if why is None and not isinstance(v, bool) and isinstance(v, (int, float)) and math.isfinite(v):
                vals[r.index] = float(v)
        thresholds = [q for q in plan.requirements if q.key == key]
        ya = y_axis(list(vals.values()) + [q.value for q in thresholds])
        panels.append((key, vals, thresholds, ya))
    labels_w = max((text_size(tick_label(t), s)[1] for *_, ya in panels for t in ya.ticks), default=0)
    left = margin + labels_w + s + tick
    caption = [_drawable(f"{plan.scene_name}: sweep of {len(plan.grid)} runs, {result.method}, "
                         + (f"{result.budget['rays']:,} rays" if result.budget["rays"] else
                            f"{result.budget['seconds']:g} s") + f" per run, seed {result.seed}"
                         + (f", stopped after {len(result.runs)}" if result.partial else "")),
               _drawable(_fit(result.describe()))]
    x_title = _drawable(plan.x.text + (" (log scale)" if xa.log else ""))
    legend = [_drawable(_fit(label)) for label, _ in series] if len(series) > 1 else []
    title_h = text_h + up_ + 2 * s  # the key's title, clear of the top tick's label
    block_h = title_h + ph + tick + s
    top0 = margin + len(caption) * (text_h + s) + margin
    bottom_h = text_h + s + text_h + 2 * s + len(legend) * (text_h + s) + margin
    height = top0 + len(panels) * (block_h + margin) + bottom_h
    texts = [*caption, *legend, x_title]
    width = max(left + PLOT_W * s + 8 * s, *(margin + text_size(t, s)[1] + margin for t in texts))
    pw = width - left - 8 * s  # at least PLOT_W * s: as wide as the caption allows
    canvas = np.empty((height, width, 3), np.uint8)
    canvas[:] = PAPER
    for i, line in enumerate(caption):
        draw_text(canvas, line, margin, margin + i * (text_h + s) + up_, s)

    def col(v):
        return left + int(round(xa.frac(v) * (pw - 1)))

    geometry: dict = {"panels": []}
    for p, (key, vals, thresholds, ya) in enumerate(panels):
        top = top0 + p * (block_h + margin) + title_h
        bottom = top + ph - 1

        def row(v, ya=ya, bottom=bottom):
            return bottom - int(round(ya.frac(v) * (ph - 1)))

        clip = (top, left, top + ph, left + pw)
        draw_text(canvas, _drawable(key), left, top - title_h + up_ + s, s)
        shaded = []
        for iv in rec.get("intervals", []) if plan.requirements else []:
            c0, c1 = sorted((col(iv["from"]), col(iv["to"])))
            c0, c1 = max(c0, left), min(c1, left + pw - 1)
            canvas[top:top + ph, c0:c1 + 1] = SHADE
            shaded.append([c0, c1])
        x_ticks = [{"value": t, "px": col(t)} for t in xa.ticks]
        y_ticks = [{"value": t, "px": row(t)} for t in ya.ticks]
        for t in x_ticks:
            canvas[top:top + ph, t["px"]] = GRID_LINE
            canvas[top + ph:top + ph + tick, t["px"] - s // 2:t["px"] + (s + 1) // 2] = INK
        for t in y_ticks:
            canvas[t["px"], left:left + pw] = GRID_LINE
            canvas[t["px"] - s // 2:t["px"] + (s + 1) // 2, left - tick:left] = INK
        last_top = None
        for t in reversed(y_ticks):  # from the top down; a label that would overlap the one above is left out
            label_top = t["px"] - up_
            if last_top is None or label_top >= last_top + text_h:
                draw_text(canvas, tick_label(t["value"]), left - tick - s, t["px"], s, anchor="right")
                last_top = label_top
        canvas[top - 1, left - 1:left + pw + 1] = INK  # the plot box's frame, just outside it
        canvas[top + ph, left - 1:left + pw + 1] = INK
        canvas[top - 1:top + ph + 1, left - 1] = INK
        canvas[top - 1:top + ph + 1, left + pw] = INK
        drawn = []
        dash = 4 * s
        cols = np.arange(left, left + pw)
        on = cols[((cols - left) // dash) % 3 != 2]
        for q in thresholds:
            r = row(q.value)
            for dr in range(-(lw // 2), lw - lw // 2):
                if top <= r + dr < top + ph:
                    canvas[r + dr, on] = THRESHOLD
            label = _drawable(f"{q.op} {q.value:g}")
            draw_text(canvas, label, left + pw - s - text_size(label, s)[1], r - up_ - 2 * s if r - text_h > top
                      else r + up_ + 2 * s, s, colour=THRESHOLD)
            drawn.append({"requirement": q.text, "value": q.value, "row": r})
        points = []
        for (_, runs), colour in zip(series, colours, strict=True):
            for a, b in zip(runs[:-1], runs[1:], strict=True):
                if a.index not in vals or b.index not in vals:
                    continue  # a run without the figure breaks the line
                # Between two runs the figure is drawn as the recommendation interpolates it: linear in
                # the parameter (in its log for a --log field), so that it crosses a threshold at the edge.
                t = np.linspace(0.0, 1.0, pw // 4 + 2)
                xa_, xb_ = a.values[xi], b.values[xi]
                x = np.exp(np.log(xa_) + t * np.log(xb_ / xa_)) if plan.x.log else xa_ + t * (xb_ - xa_)
                y = vals[a.index] + t * (vals[b.index] - vals[a.index])
                _polyline(canvas, [row(v) for v in y], [col(v) for v in x], colour, lw, clip)
            for r in runs:
                if r.index in vals:
                    rr, cc = row(vals[r.index]), col(r.values[xi])
                    met = result.meets(r)
                    _marker(canvas, rr, cc, 3 * s, colour, met, s)
                    points.append({"run": r.index, "row": rr, "column": cc, "meets": met})
        if not vals:
            draw_text(canvas, "no run has this figure", left + pw // 2, top + ph // 2, s, anchor="centre")
        last_right = None
        for t in x_ticks if p == len(panels) - 1 else []:
            label = tick_label(t["value"])
            w = text_size(label, s)[1]
            if last_right is None or t["px"] - w // 2 > last_right + 2 * s:
                draw_text(canvas, label, t["px"], top + ph + tick + s + up_, s, anchor="centre")
                last_right = t["px"] - w // 2 + w
        geometry["panels"].append({"key": key, "box": [top, left, ph, pw],
                                   "x": {"lo": xa.lo, "hi": xa.hi, "log": xa.log, "ticks": x_ticks},
                                   "y": {"lo": ya.lo, "hi": ya.hi, "log": ya.log, "ticks": y_ticks},
                                   "thresholds": drawn, "shaded": shaded, "points": points})
    y0 = top0 + len(panels) * (block_h + margin) + text_h + s
    draw_text(canvas, x_title, left + pw // 2, y0 + up_, s, anchor="centre")
    for i, (label, colour) in enumerate(zip(legend, colours, strict=False)):
        r = y0 + text_h + 2 * s + i * (text_h + s) + up_
        canvas[r - s:r + s, left:left + 6 * s] = colour
        draw_text(canvas, label, left + 8 * s, r, s)
    geometry |= {"width": width, "height": height, "x_field": plan.x.text,
                 "series": [label for label, _ in series]}
    return canvas, geometry


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
