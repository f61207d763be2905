"""A sweep's runs and what is made of them: each run's requirements judged, the recommendation (where
every requirement holds, with interpolated edges), sweep.json's summary, sweep.csv and the chart's
data (tracer.scans.sweep writes them).
"""

from __future__ import annotations

import csv
import io
import math
import re
from dataclasses import dataclass, field

import numpy as np

from .. import __version__
from ..core.jsonpath import lookup, parse_field, path_text
from ..products import charts
from ..products.report import report_unit
from .fields import SweepField, field_unit
from .plan import MAX_PANELS, SweepPlan
from .requirements import run_figures

RUNS = "runs"


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
        """The render found light; a run of the optical analysis, that it found the image."""
        if self.report["method"] == "optics":
            return "error" not in self.report["optics"]
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
            stopped = len(self.runs) - len(self.judged)
            n = len(self.judged)
            return (f"{n} run{'' if n == 1 else 's'} rendered to their budget"
                    + (f" ({stopped} stopped early)" if stopped else "") + "; no requirements given")
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
                lo = f"{iv['from']:.4g}" + (" or less" if iv["low"].get("open") else "")
                hi = f"{iv['to']:.4g}" + (" or more" if iv["high"].get("open") else "")
                parts.append(f"from {lo} to {hi}" if iv["from"] != iv["to"] else f"{iv['from']:.4g}")
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
    if result.method == "optics":
        how = "the optical analysis"
    else:
        budget = f"{result.budget['rays']:,} rays" if result.budget["rays"] else f"{result.budget['seconds']:g} s"
        how = f"{result.method}, {budget} per run, seed {result.seed}"
    caption = [f"{plan.scene_name}: sweep of {len(plan.grid)} runs, {how}"
               + (f", stopped after {len(result.runs)}" if result.partial else ""),
               result.describe()]
    rgb, geometry = charts.sweep_chart(panels, x, series, caption)
    return rgb, geometry | {"x_field": plan.x.text, "series": [s["label"] for s in series]}
