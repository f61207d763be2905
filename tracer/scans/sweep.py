"""Parameter sweeps: one scene rendered over a grid of scene.json values and judged by requirements.

The paper's practical question (Potemin, Zhdanov et al., Proc. SPIE 10690, 106900I (2018), sec. 4.1):
the LED luminance at which the symbols stay legible while the rear-projection spot stays invisible
against the environment. A sweep renders a scene once per point of a grid of scene.json values,
reads each run's report (:func:`tracer.products.report.build_report`, its HUD figures from
:mod:`tracer.analysis.hud`) and says where every requirement holds.

- **Fields** (:mod:`.fields`): a dotted path into scene.json, ``eye.pupil_diameter_mm``,
  ``environment.calibration.value``, ``methods.backward.max_depth``, ``eye.position[2]`` (a list's
  element by its index), and objects by name with a glob (:func:`fnmatch.fnmatchcase`):
  ``objects[led_*].emission.luminance`` sets the field on every object whose name matches (an
  integer in the brackets is the index into the list, as the loader's messages write it). Every
  block on the path must exist (a sweep never gives an object an emission it lacks), except a
  method's options under ``methods``, whose defaults apply when they are absent; the last field
  may be absent, and the loader judges whether its block has it. Setting one of an emission's
  alternatives (``luminance``) removes the other (``flux``).
- **Grid** (:mod:`.plan`): each ``--set FIELD=START:STOP:N`` gives N values from START to STOP, evenly spaced, or
  geometrically for a field named by ``--log``; several make the cartesian product of their values
  (every combination; the first field varies slowest), at most :data:`.fields.MAX_RUNS` runs. Every grid
  point's scene is loaded through :func:`tracer.scene.load_scene` before the first ray, so that a
  value out of its field's range is refused with the field named, before any run.
- **Runs**: the scene folder is copied once into a temporary folder (hard links where the file system
  allows); for each run its scene.json is rewritten there and rendered with
  :func:`tracer.products.render.render_scene` (worker processes load the same folder). Every run has the same
  seed, so that runs differ by the parameter and not by the pattern of their noise: with a budget in
  rays, a luminance swept on the only light source scales the image exactly.
- **Requirements** (:mod:`.requirements`): ``"KEY OP VALUE"``, KEY a dotted path into a run's
  report (``hud.contrast_ratio``, ``hud.spot.peak_over_median_background``, ``luminance.mean``), OP
  one of ``>= <= > <``, VALUE a number. A run whose report lacks KEY, or holds no number there,
  fails it, and sweep.json says why.
- **Recommendation** (:meth:`.results.SweepResult.recommendation`): for a one-field sweep the runs that meet
  every requirement, grouped into intervals of the parameter between consecutive runs; an edge
  next to a failing run is where the failing requirements' figures cross their thresholds,
  interpolated linearly between the two runs (in log of the parameter for a ``--log`` field), so
  it is exact for a figure linear in the parameter (in its log) and within one step elsewhere; an
  edge at the first or last value of the sweep is open (the range may go on). For a grid, the runs
  that meet every requirement. When none does, "none" and the closest run: the one that fails the
  fewest requirements (then the fewest for want of the figure), then the one whose figures fall
  shortest of them (the sum of |figure - VALUE| / |VALUE| over those it fails).

Outputs (:func:`run_sweep`), in the output folder: ``runs/<k>/`` (each run's image.exr, preview.png
and report.json), ``sweep.csv`` (:func:`.results.csv_text`), ``sweep.json`` (:meth:`.results.SweepResult.summary`)
and ``sweep.png`` (:func:`.results.sweep_chart`). The runs are rendered into a hidden staging folder and moved into
``runs/`` with the three files after the last run, as one set (:mod:`tracer.products.outputs`): an earlier
sweep's runs and files are replaced together, and kept if writing fails.
"""

from __future__ import annotations

import json
import os
import shutil
import time
import uuid
from pathlib import Path

from ..core.errors import StoppedBeforeFirstBatch
from ..products.outputs import STAGING_PREFIX, OutputFile, OutputFolderError, OutputSet, OutputWriteError, png_file
from ..products.render import render_scene
from ..products.report import finite_json
from ..scene import SCENE_FILE
from .plan import SweepPlan
from .results import RUNS, Run, SweepResult, csv_rows, csv_text, read_csv, sweep_chart

#: The sweep's files in the output folder, beside the runs folder.
OUTPUT_NAMES = ("sweep.csv", "sweep.json", "sweep.png")


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


def optics_run(scene, folder: Path) -> dict:
    """The optical analysis of one grid point (``method`` "optics"): optics.json, optics.csv and its pictures
    (tracer.products.optics) and a report.json holding its ``optics`` block (report_block, or {"error"}
    where the scene shows no image) written into ``folder``; returns that report."""
    from .. import __version__
    from ..analysis.optics import OpticsError, analyse, report_block
    from ..products import optics as products
    from ..transport.sequential import ChainError

    t0 = time.perf_counter()
    try:
        doc = analyse(scene, compare_mesh=False)
        block, files = products.clean(report_block(doc)), products.output_files(doc)
    except (OpticsError, ChainError) as e:
        block, files = {"error": str(e)}, []
    report = {"run_id": uuid.uuid4().hex, "tracer": f"hud-tracer {__version__}",
              "scene": {"name": scene.name, "folder": str(scene.root), "hash": scene.scene_hash}, "method": "optics",
              "partial": False, "seconds": time.perf_counter() - t0, "optics": block,
              "warnings": [block["error"]] if "error" in block else []}
    text = finite_json(report)
    outputs = OutputSet(folder, (*products.OUTPUT_NAMES, "report.json")).open()
    try:
        outputs.commit([*files, OutputFile("report.json", lambda p: p.write_text(text),
                                           lambda p: json.loads(p.read_text()))])
        outputs.keep()
    finally:
        outputs.close()
    return report


def run_sweep(plan: SweepPlan, method: str, budget, seed: int, outputs: OutputSet, workers: int = 1,
              batch_size: int | None = None, progress=None, should_stop=None, on_run=None,
              scheduler: str | None = None) -> SweepResult:
    """Render every grid point of ``plan`` with ``method``, ``budget`` (tracer.methods.Budget, per run)
    and ``seed`` (the same for every run) on ``workers`` processes, and write the sweep into the folder
    of ``outputs`` (:func:`open_outputs`; see the module docstring). ``progress(fraction, message)``
    follows the whole sweep; ``should_stop()`` true stops the current run as a render stops (its
    batches so far, marked partial) and starts no other: what was done is written, marked partial.
    ``on_run(result, run)`` is called after each run. ``method`` "optics" runs the optical analysis
    (:func:`optics_run`) in place of a render. ``scheduler``: every run on that Dask cluster.

    Raises :class:`~tracer.products.outputs.OutputWriteError` if writing fails (the folder keeps its earlier
    sweep); KeyboardInterrupt (a second Ctrl-C) leaves the folder as it was."""
    folder = outputs.folder
    staging = folder / f"{STAGING_PREFIX}runs-{uuid.uuid4().hex}"
    staging.mkdir()
    try:
        result = SweepResult(plan, method, seed, {"rays": None, "seconds": None} if budget is None else
                             {"rays": budget.rays, "seconds": budget.seconds}, workers,
                             batch_size)
        n = len(plan.grid)
        for k in range(n):
            if should_stop is not None and should_stop():
                result.stopped = True
                break
            scene = plan.load(k)
            if method == "optics":
                if progress is not None:
                    progress(k / n, f"run {k} ({k + 1} of {n}): optical analysis")
                run = Run(k, plan.grid[k], optics_run(scene, staging / RUNS / str(k)))
                result.runs.append(run)
                if on_run is not None:
                    on_run(result, run)
                continue
            try:
                report, rendered = render_scene(scene, method, budget, seed, staging / RUNS / str(k),
                                                progress=_run_progress(progress, k, n, staging / RUNS / str(k),
                                                                       folder / RUNS / str(k)),
                                                should_stop=should_stop,
                                                batch_size=batch_size, workers=workers, scheduler=scheduler)
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


def _run_progress(progress, k: int, n: int, staged: Path, final: Path):
    """Run ``k``'s progress as the sweep's, its messages naming the run's folder where it will be, not the
    hidden staging folder it is written into."""
    if progress is None:
        return None
    return lambda fraction, message: progress((k + fraction) / n,
                                              f"run {k} ({k + 1} of {n}): {message.replace(str(staged), str(final))}")


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
