"""Command line: ``hud-trace render | presets | export | methods | readouts | false-colour | eyebox | sweep``.

Exit status of ``render`` (each states what is on disk afterwards):

- 0: success; image.exr, preview.png and report.json written as one set.
- 2: bad input (one line naming the file or argument and the field); nothing traced, nothing written,
  the output folder keeps what it held.
- 3: the method found no light path (or the scene has no light); the outputs are written and say so.
- 4: the outputs could not be written (a full disk, a folder that changed under the render); the
  output folder keeps its earlier outputs.
- 5: aborted by a second interrupt; nothing written, the output folder keeps its earlier outputs.
- 130: interrupted (Ctrl-C, SIGTERM or SIGHUP): the batches merged so far are written as a set,
  marked ``"partial": true``.

``readouts`` prints the figures of a render's report.json (tracer.products.report.readouts, what the Blender
add-on's HUD Readouts panel shows): 0, or 2 when the file is not a report (one line).

``false-colour`` writes the false-colour view of an image.exr (tracer.products.falsecolour) to one PNG file:
0 written, 2 bad input (nothing written), 3 written, but no pixel is lit, 4 the file could not be written
(it keeps what it held).

``eyebox`` writes eyebox.csv, eyebox.png and eyebox.json (tracer.scans.eyebox) into a folder as one set: 0
written; 2 bad input, before the scan (nothing written); 3 written, but the analysis cannot predict
the scene (eyebox.json's ``valid`` is false and stderr says why); 4 the outputs could not be written
(the folder keeps its earlier ones); 130 stopped by Ctrl-C, SIGTERM or SIGHUP (nothing written).

``sweep`` renders a scene over a grid of scene.json values (tracer.scans.sweep) into a folder: runs/<k>/ and
sweep.csv, sweep.json and sweep.png, as one set: 0 written; 2 bad input, before any ray (nothing
written); 3 written, but no run meets the requirements (``--require``); 4 the outputs could not be
written (the folder keeps its earlier sweep); 130 stopped by Ctrl-C, SIGTERM or SIGHUP: the current
run stops as ``render`` does and the runs done are written, marked partial (nothing, where the stop came
before the first run began); 5 aborted by a second Ctrl-C (nothing written).
"""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import os
import shutil
import signal
import sys
import tempfile
import time
from pathlib import Path

from .core.errors import STOP_SIGNALS, EstimateOverflowError, SceneError, StoppedBeforeFirstBatch


def _process_start() -> float:
    """``time.perf_counter()`` at this process's start (Linux: its start time in /proc/self/stat against
    the system's uptime), else now: the interpreter's own start and the imports count toward --seconds."""
    now = time.perf_counter()
    try:
        ticks = int(Path("/proc/self/stat").read_text().rsplit(")", 1)[1].split()[19])
        uptime = float(Path("/proc/uptime").read_text().split()[0])
        age = uptime - ticks / os.sysconf("SC_CLK_TCK")
    except (OSError, ValueError, IndexError):
        return now
    return now - age if 0.0 <= age < 60.0 else now


#: When this process began (:func:`_process_start`), and when this module was imported.
STARTED, _IMPORTED = _process_start(), time.perf_counter()
#: Commands run by :func:`main` in this process so far.
_commands = 0


def _command_start() -> float:
    """When the command that :func:`main` begins started, for a render's --seconds: the process's start
    where it is the process's first command, begun as this module was imported (the console script:
    the interpreter's start and the imports count), else now (a host program or a test calling
    :func:`main`: a budget had counted from the process's start, and was spent before such a render began)."""
    global _commands
    now = time.perf_counter()
    _commands += 1
    return STARTED if _commands == 1 and now - _IMPORTED < 1.0 else now
EXIT_INPUT, EXIT_NO_LIGHT, EXIT_WRITE, EXIT_ABORTED, EXIT_INTERRUPTED = 2, 3, 4, 5, 130
#: Limits of the render arguments (beyond them a render cannot be meant).
MAX_SECONDS = 1e7
MAX_RAYS = 10**15
MAX_WORKERS = 1024
SCHEDULER_HELP = ("render on the Dask cluster of this scheduler (tcp://host:8786; `dask scheduler`, `dask worker "
                  "ADDRESS` on each machine) instead of --workers local processes: the same outputs, and with --rays "
                  "the same image (docs/user/cluster.md)")


class ProgressBar:
    """A one-line progress bar on stderr (rewritten in place on a terminal)."""

    def __init__(self, stream=sys.stderr, width: int = 30):
        self.stream, self.width = stream, width
        self.tty = stream.isatty()
        self._last = 0.0

    def __call__(self, fraction: float, message: str):
        now = time.monotonic()
        if not self.tty and now - self._last < 5 and fraction < 1:
            return
        self._last = now
        filled = int(self.width * fraction)
        line = f"[{'#' * filled}{'.' * (self.width - filled)}] {100 * fraction:5.1f}%  {message}"
        self.stream.write(("\r" + line) if self.tty else line + "\n")
        self.stream.flush()

    def close(self):
        if self.tty:
            self.stream.write("\n")


class StopFlag:
    """The first stop signal asks the render to stop after the batches being merged and to write a
    partial result; a second one aborts (KeyboardInterrupt: nothing is written), unless the outputs
    are already being written: that takes a fraction of a second and is let finish, so that the set
    is whole."""

    def __init__(self):
        from .products.outputs import committed

        self.stop = False
        self._committed = committed()

    def __call__(self) -> bool:
        return self.stop

    def written(self) -> bool:
        """Whether an output set has been moved into place since this flag was made (by its command)."""
        from .products.outputs import committed

        return committed() > self._committed

    def handler(self, signum, frame):
        from .products.outputs import writing

        name = signal.Signals(signum).name
        if self.stop and writing():
            sys.stderr.write(f"\n{name}: the partial result is being written and will be complete in a moment\n")
            return
        if self.stop:
            raise KeyboardInterrupt
        self.stop = True
        sys.stderr.write(f"\n{name}: stopping and writing a partial result (Ctrl-C again to abort)\n")


class Stopped(Exception):
    """A stop signal during a command that stops by leaving nothing written (the eyebox scan)."""


def _raise_stopped(signum, frame):
    raise Stopped(signal.Signals(signum).name)


class ArgumentError(Exception):
    """A command-line argument out of its range (the message names the argument)."""


def check_render_args(args):
    """Every render argument in its range, before anything is loaded or traced."""
    from .methods.base import MAX_BATCH, SMALLEST_BATCH

    def bad(flag, msg):
        raise ArgumentError(f"{flag}: {msg}")

    if args.rays is not None and not 1 <= args.rays <= MAX_RAYS:
        bad("--rays", f"must lie in [1, {MAX_RAYS:.0e}], got {args.rays}")
    if getattr(args, "scheduler", None) is not None:  # reached before anything is loaded or traced
        from .runtime.distributed import SchedulerError, connect

        try:
            connect(args.scheduler)
        except SchedulerError as e:
            bad("--scheduler", str(e))
    if args.seconds is not None and not (math.isfinite(args.seconds) and 0 < args.seconds <= MAX_SECONDS):
        bad("--seconds", f"must be a finite number in (0, {MAX_SECONDS:.0e}], got {args.seconds}")
    if not 0 <= args.seed < 2**63:
        bad("--seed", f"must lie in [0, 2^63), got {args.seed}")
    if args.batch_size is not None and not SMALLEST_BATCH <= args.batch_size <= MAX_BATCH:
        bad("--batch-size", f"must lie in [{SMALLEST_BATCH}, {MAX_BATCH}], got {args.batch_size}")
    if not 1 <= args.workers <= MAX_WORKERS:
        bad("--workers", f"must lie in [1, {MAX_WORKERS}], got {args.workers}")


def check_workers(workers: int, resolution: tuple[int, int]) -> str | None:
    """:func:`tracer.core.validate.check_workers`, its refusal as an :class:`ArgumentError` of --workers."""
    from .core.validate import WorkersError
    from .core.validate import check_workers as check

    try:
        return check(workers, resolution)
    except WorkersError as e:
        raise ArgumentError(f"--workers: {e}") from None


def _resolve_scene(arg: str, tmp: Path) -> Path:
    """A scene folder as given, or a preset name exported into ``tmp``."""
    from presets import PRESETS

    p = Path(arg)
    if p.is_dir() or p.name == "scene.json":
        return p
    if arg in PRESETS:
        folder = tmp / arg
        PRESETS[arg].write(folder)
        return folder
    raise SceneError(arg, "", f"neither a scene folder nor a preset (presets: {', '.join(PRESETS)})")


def _write_errors(e: BaseException, out, written: bool = False) -> int:
    """One line on stderr and the exit status of a command that writes an output set into ``out``, for
    the errors it ends with: the folder cannot take the set, or a value overflows (2); the writing
    failed (4: the folder keeps its earlier set); a second Ctrl-C (5), or 130 where it came once the
    command's set was in place (``written``: its analysis is what stopped); other I/O, such as a
    preset's temporary scene folder on a full disk (4)."""
    from .products.outputs import OutputFolderError

    if isinstance(e, OutputFolderError | EstimateOverflowError):
        print(f"error: {e}", file=sys.stderr)
        return EXIT_INPUT
    if isinstance(e, KeyboardInterrupt) and written:
        print(f"aborted after the outputs were written: {out} holds them (report.json says whether its analysis "
              "was done)", file=sys.stderr)
        return EXIT_INTERRUPTED
    if isinstance(e, KeyboardInterrupt):
        print(f"aborted: nothing written; {out} keeps what it held", file=sys.stderr)
        return EXIT_ABORTED
    print(f"error: {e}", file=sys.stderr)
    return EXIT_WRITE


#: What :func:`_write_errors` handles.
WRITE_ERRORS = (KeyboardInterrupt, OSError, EstimateOverflowError)


def cmd_render(args) -> int:
    from .methods import Budget
    from .products.outputs import OutputError
    from .products.render import render_scene
    from .runtime.allocator import keep_freed_memory
    from .scene import load_scene

    try:
        check_render_args(args)
    except ArgumentError as e:
        print(f"error: {e}", file=sys.stderr)
        return EXIT_INPUT
    keep_freed_memory()
    # --seconds count from the command's start (loading the scene included); each eye of a pair has its own
    budget = Budget(rays=args.rays, seconds=args.seconds, since=args.started if args.eye != "both" else None)
    flag = StopFlag()
    previous = {s: signal.signal(s, flag.handler) for s in STOP_SIGNALS}
    bar = None if args.quiet else ProgressBar()
    try:
        with tempfile.TemporaryDirectory(prefix="hud-trace-") as tmp:
            scene = load_scene(_resolve_scene(args.scene, Path(tmp)), allow_external=args.allow_external_files)
            crowded = check_workers(args.workers, scene.eye.resolution)
            if crowded:
                print(f"warning: {crowded}", file=sys.stderr)
            sides = ("left", "right") if args.eye == "both" else (args.eye,)
            done = []
            for side in sides:
                out = args.out if len(sides) == 1 else str(Path(args.out) / side)
                report, result = render_scene(scene, args.method, budget, args.seed, out, progress=bar,
                                              should_stop=flag, batch_size=args.batch_size, workers=args.workers,
                                              scheduler=args.scheduler, keep_pool=side != sides[-1],
                                              analyse=not args.no_analysis, eye=side,
                                              notice=lambda w: print(f"warning: {w}", file=sys.stderr, flush=True))
                done.append((side, out, report))
                if result.partial:
                    break
            if len(sides) == 2 and not result.partial:
                from .products.render import side_by_side

                side_by_side(Path(args.out) / "left" / "preview.png", Path(args.out) / "right" / "preview.png",
                             Path(args.out) / "both.png")
    except StoppedBeforeFirstBatch as e:
        if bar:
            bar.close()
            bar = None
        print(f"{e}: nothing written; {args.out} keeps what it held", file=sys.stderr)
        return EXIT_INTERRUPTED
    except (*WRITE_ERRORS, OutputError) as e:
        return _write_errors(e, args.out, flag.written())
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)
        if bar:
            bar.close()
    for side, out, report in done:
        lum = report["luminance"]
        eye = f" ({side} eye)" if side != "centre" else ""
        print(f"{_method_said(report)}{eye}: {report['rays']:,} rays, {report['paths']:,} paths in "
              f"{report['seconds']:.1f} s "
              f"({report['rays_per_second']:,.0f} rays/s); efficiency {report['efficiency']:.3e}; "
              f"luminance mean {lum['mean']:.4g}, max {lum['max']:.4g} cd/m^2 -> {out}", file=sys.stderr)
        for w in report["warnings"]:  # the report's list: the method's own and the noise check
            print(f"warning: {w}", file=sys.stderr)
    if result.partial:
        return EXIT_INTERRUPTED
    if result.found == 0:
        return EXIT_NO_LIGHT
    return 0


def _method_said(report: dict) -> str:
    """The method as a render's summary line names it: ``auto`` with the method it chose for each channel
    (``auto (chose backward)``, ``hybrid (hud: backward, environment: photon)``)."""
    channels = (report.get("method_details") or {}).get("channels") or {}
    chosen = {name: ch.get("method") or "skipped" for name, ch in channels.items()}
    if not chosen:
        return report["method"]
    if list(chosen) == ["scene"]:
        return f"{report['method']} (chose {chosen['scene']})"
    return f"{report['method']} (" + ", ".join(f"{k}: {v}" for k, v in chosen.items()) + ")"


def cmd_presets(args) -> int:
    from presets import PRESETS

    width = max(map(len, PRESETS))
    for name, mod in PRESETS.items():
        print(f"{name:{width}s}  {mod.SUMMARY}")
    return 0


def cmd_export(args) -> int:
    """Write a preset's scene folder into an absent or empty folder, as a unit: staged beside it, then
    renamed into place (exit 2 for a target that cannot take it, 4 when writing fails; nothing is
    left behind either way)."""
    from presets import PRESETS

    from .products.outputs import replace_folder

    if args.preset not in PRESETS:
        raise SceneError(args.preset, "", f"unknown preset (presets: {', '.join(PRESETS)})")
    out = Path(os.path.abspath(args.dir))
    try:
        if out.exists() and not out.is_dir():
            raise SceneError(str(out), "", "exists and is not a folder")
        if out.is_dir() and any(out.iterdir()):
            raise SceneError(str(out), "", "the target folder exists and is not empty")
        parent = next(p for p in out.parents if p.exists())
        if not parent.is_dir():
            raise SceneError(str(out), "", f"cannot be made: {parent} is not a folder")
        out.parent.mkdir(parents=True, exist_ok=True)
        tmp = tempfile.mkdtemp(prefix=f".{out.name}.staging-", dir=out.parent)
    except OSError as e:
        raise SceneError(str(out), "", f"cannot be made ({e.strerror or e})") from None
    try:
        staged = Path(tmp) / "scene"
        PRESETS[args.preset].write(staged)
        replace_folder(staged, out)  # an empty target's backup is removed at once
    except OSError as e:
        print(f"error: {out}: writing the scene failed ({e.strerror or e}); nothing was written", file=sys.stderr)
        return EXIT_WRITE
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    print(f"wrote {args.preset} to {out}", file=sys.stderr)
    return 0


def cmd_methods(args) -> int:
    from .methods import INTEGRATORS

    for name, cls in INTEGRATORS.items():
        print(f"{name:10s} {cls.summary}")
    return 0


def cmd_readouts(args) -> int:
    import json

    from .products.report import readouts

    path = Path(args.report)
    if path.is_dir():
        path = path / "report.json"
    try:
        report = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, ValueError) as e:
        print(f"error: {path}: cannot be read as a report: {getattr(e, 'strerror', None) or e}", file=sys.stderr)
        return EXIT_INPUT
    if not isinstance(report, dict):
        print(f"error: {path}: not a hud-trace report (a JSON {type(report).__name__}, not an object)", file=sys.stderr)
        return EXIT_INPUT
    try:
        rows = readouts(report)
    except KeyError as e:
        print(f"error: {path}: not a hud-trace report (no field {e})", file=sys.stderr)
        return EXIT_INPUT
    except (TypeError, ValueError, AttributeError, IndexError):
        print(f"error: {path}: not a hud-trace report (a field of the wrong type or shape)", file=sys.stderr)
        return EXIT_INPUT
    width = max(len(label) for label, _ in rows)
    for label, text in rows:
        print(f"{label:<{width}}  {text}")
    return 0


def check_false_colour_args(args):
    """--min and --max finite and positive, --min below --max, --out a .png file."""
    for flag, v in (("--min", args.min), ("--max", args.max)):
        if v is not None and not (math.isfinite(v) and v > 0):
            raise ArgumentError(f"{flag}: must be a finite luminance > 0 cd/m^2, got {v}")
    if args.min is not None and args.max is not None and args.min >= args.max:
        raise ArgumentError(f"--min: {args.min:g} cd/m^2 must be below --max {args.max:g} cd/m^2")
    if Path(args.out).suffix.lower() != ".png":
        raise ArgumentError(f"--out: must name a .png file, got {args.out}")


def cmd_false_colour(args) -> int:
    from .core.errors import ImageReadError
    from .core.imageio import read_luminance
    from .products.falsecolour import luminance_range, save_false_colour
    from .products.outputs import OutputFolderError, OutputWriteError

    try:
        check_false_colour_args(args)
        y = read_luminance(args.image)
        # One bound given: it must fit the default of the other.
        lo, hi, _ = luminance_range(y)
        if args.min is not None and args.max is None and args.min >= hi:
            raise ArgumentError(f"--min: {args.min:g} cd/m^2 is not below the top of the default range, {hi:g} "
                                "cd/m^2; give --max too")
        if args.max is not None and args.min is None and args.max <= lo:
            raise ArgumentError(f"--max: {args.max:g} cd/m^2 is not above the bottom of the default range, {lo:g} "
                                "cd/m^2; give --min too")
        info = save_false_colour(args.out, y, args.min, args.max)
    except (ArgumentError, ImageReadError, OutputFolderError) as e:
        print(f"error: {e}", file=sys.stderr)
        return EXIT_INPUT
    except OutputWriteError as e:
        print(f"error: {e}", file=sys.stderr)
        return EXIT_WRITE
    clamped = "".join(f"; {100 * info[k]:.3g} % of the pixels {k} the range" for k in ("below", "above") if info[k])
    print(f"false colour: {info['lo']:g} to {info['hi']:g} cd/m^2 ({info['decades']:g} decades, {info['colour_map']})"
          f"{clamped} -> {args.out}", file=sys.stderr)
    if not (y > 0).any():  # a silent black picture would read as a dark scene shown
        print("warning: no pixel of the image is lit (every Y is 0 cd/m^2): the view is the no-light colour "
              "throughout, and its range is a placeholder", file=sys.stderr)
        return EXIT_NO_LIGHT
    return 0


#: The eyebox scan's arguments and the command line's flags for them.
EYEBOX_FLAGS = {"half_mm": "--half", "step_mm": "--step", "field_deg": "--field", "threshold": "--threshold",
                "photons": "--photons", "seed": "--seed"}


def cmd_eyebox(args) -> int:
    from .products.outputs import OutputError, OutputSet
    from .runtime.allocator import keep_freed_memory
    from .scans.eyebox import OUTPUT_NAMES, FieldNotFound, ScanArgumentError, check_scan, eyebox_scan, output_files
    from .scene import load_scene
    from .transport.world import World

    try:
        check_scan(args.half, args.step, args.field, args.threshold, args.photons, args.seed)
    except ScanArgumentError as e:
        print(f"error: {EYEBOX_FLAGS[e.argument]}: {e.message}", file=sys.stderr)
        return EXIT_INPUT
    keep_freed_memory()
    bar = None if args.quiet else ProgressBar()
    # A scan takes seconds and is deterministic: a stop signal ends it with nothing written (not the
    # default death of SIGTERM and SIGHUP, which left no word and a locked folder's temporary files).
    previous = {s: signal.signal(s, _raise_stopped) for s in STOP_SIGNALS}
    try:
        with tempfile.TemporaryDirectory(prefix="hud-trace-") as tmp:
            scene = load_scene(_resolve_scene(args.scene, Path(tmp)), allow_external=args.allow_external_files)
            outputs = OutputSet(args.out, OUTPUT_NAMES, scene_root=scene.root).open()  # before the first ray
            try:
                result = eyebox_scan(World(scene), args.half, args.step, args.field, args.threshold, progress=bar,
                                     photons=args.photons, seed=args.seed)
                outputs.commit(output_files(result))
                outputs.keep()
            finally:
                outputs.close()
    except Stopped as e:
        if bar:
            bar.close()
            bar = None
        print(f"\n{e}: the eyebox scan stopped, nothing written; {args.out} keeps what it held", file=sys.stderr)
        return EXIT_INTERRUPTED
    except FieldNotFound as e:
        print(f"error: --field: {e}", file=sys.stderr)
        return EXIT_INPUT
    except (*WRITE_ERRORS, OutputError) as e:
        return _write_errors(e, args.out)
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)
        if bar:
            bar.close()
    d = result.design_cd_m2
    corners = ", ".join(f"{v:.4g}" for v in d[1:])
    print(f"eyebox of {result.scene}: design eye {d[0]:.4g} cd/m^2 at the centre, {corners} toward the corners -> "
          f"{args.out}", file=sys.stderr)
    if not result.valid:
        for reason in result.reasons:
            print(f"warning: not valid: {reason}", file=sys.stderr)
        return EXIT_NO_LIGHT
    f = result.figures()
    print(f"eyebox {f['width_mm']:.1f} x {f['height_mm']:.1f} mm (every field point >= {100 * args.threshold:g} % of "
          f"design); uniformity {f['uniformity']['design_eye']:.3f} at the design eye, {f['uniformity']['eyebox']:.3f} "
          "over the eyebox", file=sys.stderr)
    if f["reaches_scan_edge"]:
        print("warning: the eyebox reaches the edge of the scan: widen --half to see all of it", file=sys.stderr)
    return 0


#: The grids' ranges (tracer.scene.format.TARGET): --field-grid, --eye-grid.
GRID_RANGES = {"--field-grid": (2, 41), "--eye-grid": (1, 41)}


def cmd_optics(args) -> int:
    from .analysis.optics import OpticsError, analyse
    from .products.optics import OUTPUT_NAMES, output_files, readouts
    from .products.outputs import OutputError, OutputSet
    from .scene import load_scene

    for flag, value in (("--field-grid", args.field_grid), ("--eye-grid", args.eye_grid)):
        lo, hi = GRID_RANGES[flag]
        if value is not None and not all(lo <= v <= hi for v in value):
            print(f"error: {flag}: each count must lie in [{lo}, {hi}], got {value[0]} {value[1]}", file=sys.stderr)
            return EXIT_INPUT
    try:
        with tempfile.TemporaryDirectory(prefix="hud-trace-") as tmp:
            scene = load_scene(_resolve_scene(args.scene, Path(tmp)), allow_external=args.allow_external_files)
            if args.field_grid is not None:
                scene.target["field_grid"] = tuple(args.field_grid)
            if args.eye_grid is not None:
                scene.target["eye_grid"] = tuple(args.eye_grid)
            outputs = OutputSet(args.out, OUTPUT_NAMES, scene_root=scene.root).open()  # before the first ray
            try:
                doc = analyse(scene, eyebox=not args.no_eyebox, compare_mesh=not args.no_mesh_comparison)
                outputs.commit(output_files(doc))
                outputs.keep()
            finally:
                outputs.close()
    except OpticsError as e:
        print(f"error: {e}", file=sys.stderr)
        return EXIT_NO_LIGHT
    except (*WRITE_ERRORS, OutputError) as e:
        return _write_errors(e, args.out)
    print(f"optics of {doc['scene']} in {doc['seconds']['total']:.2f} s -> {args.out}", file=sys.stderr)
    for label, text in readouts(doc):
        print(f"  {label}: {text}", file=sys.stderr)
    for w in doc["warnings"]:
        print(f"warning: {w}", file=sys.stderr)
    return 0 if doc["requirements_met"] else EXIT_NO_LIGHT


#: Seconds of checking a sweep's grid (loading every grid point's scene) before the progress bar shows it.
SHOW_CHECKS_AFTER_S = 2.0


def cmd_sweep(args) -> int:
    from .methods import Budget
    from .products.outputs import OutputError
    from .products.report import NOISY
    from .runtime.allocator import keep_freed_memory
    from .scans.fields import SweepArgumentError
    from .scans.plan import DEFAULT_Y, OPTICS_Y, check_arguments, plan_sweep
    from .scans.sweep import open_outputs, run_sweep

    try:
        if not args.optics and args.rays is None and args.seconds is None:
            raise ArgumentError("give a budget for each run, --rays or --seconds (or --optics: the optical analysis "
                                "alone)")
        check_render_args(args)
        fields, requirements = check_arguments(args.set, args.log, args.require, args.x, args.y, args.optics)
    except ArgumentError as e:
        print(f"error: {e}", file=sys.stderr)
        return EXIT_INPUT
    except SweepArgumentError as e:
        print(f"error: {e.argument}: {e.message}", file=sys.stderr)
        return EXIT_INPUT
    keep_freed_memory()
    budget = None if args.optics else Budget(rays=args.rays, seconds=args.seconds)
    flag = StopFlag()
    began = written = False  # the runs began, with the sweep's own stop handlers; the sweep's set is in place
    bar = None if args.quiet else ProgressBar()
    absent: set[str] = set()

    def on_run(result, run):
        if bar is not None and bar.tty:
            sys.stderr.write("\n")
        print(result.run_line(run), file=sys.stderr)
        if not run.found_light:
            print(f"warning: run {run.index}: the method found no light path", file=sys.stderr)
        noise = (run.report.get("noise") or {}).get("median_relative_standard_error_lit_pixels")
        if noise is not None and noise > NOISY and not run.partial:
            print(f"warning: run {run.index}: judged on a noisy image (the lit pixels' median relative standard "
                  f"error is {noise:.2f}): its figures may be off by that much; give each run more rays or time",
                  file=sys.stderr)
        for q, j in zip(result.plan.requirements, result.judge(run), strict=True):
            if j["value"] is None and not run.partial and q.text not in absent:
                absent.add(q.text)  # said once: a mistyped KEY fails every run
                print(f"warning: --require {q.text}: run {run.index}: {j['why']}; a run without the figure fails "
                      "the requirement", file=sys.stderr)

    started = time.monotonic()

    def checking(fraction, message):  # the grid's scenes: shown only when loading them takes a while
        if bar is not None and time.monotonic() - started > SHOW_CHECKS_AFTER_S:
            bar(fraction, message)

    try:
        with tempfile.TemporaryDirectory(prefix="hud-trace-") as tmp:
            scene_dir = _resolve_scene(args.scene, Path(tmp))
            outputs = open_outputs(args.out, scene_dir)  # checked and locked before the grid is loaded
            try:
                plan = plan_sweep(scene_dir, fields, requirements, tempfile.mkdtemp(dir=tmp), args.x, args.y,
                                  progress=checking, default_y=OPTICS_Y if args.optics else DEFAULT_Y)
                crowded = None if args.optics else \
                    check_workers(args.workers, max((json.loads(plan.scene_text(k))["eye"]["resolution"]
                                                     for k in range(len(plan.grid))), key=math.prod))
                if crowded:
                    print(f"warning: {crowded}", file=sys.stderr)
                with _signals_to(flag.handler):
                    began = True
                    result = run_sweep(plan, "optics" if args.optics else args.method, budget, args.seed, outputs,
                                       workers=args.workers, scheduler=args.scheduler,
                                       batch_size=args.batch_size, progress=bar, should_stop=flag, on_run=on_run)
                    written = True  # run_sweep returns once its set is in place
            finally:
                outputs.close()
    except SweepArgumentError as e:
        print(f"error: {e.argument}: {e.message}", file=sys.stderr)
        return EXIT_INPUT
    except KeyboardInterrupt as e:
        if flag.stop or began:  # a second stop signal (its runs' own sets are in the staging folder, not --out),
            return _write_errors(e, args.out, written)  # or one once the sweep's set was in place
        print("interrupted before the first run began: nothing written", file=sys.stderr)
        return EXIT_INTERRUPTED
    except (*WRITE_ERRORS, OutputError) as e:
        return _write_errors(e, args.out)
    finally:
        if bar:
            bar.close()
    done = f"{len(result.runs)} of {len(plan.grid)} runs" if result.partial else f"{len(result.runs)} runs"
    print(f"sweep of {done} -> {args.out}: {result.describe()}", file=sys.stderr)
    if result.partial:
        return EXIT_INTERRUPTED
    if requirements and result.recommendation()["none"]:
        return EXIT_NO_LIGHT  # 3: written, but no run meets the requirements
    return 0


def ray_count(text: str) -> int:
    """A --rays value: an integer, also written as 5e6 or 5_000_000 (a whole number)."""
    try:
        return int(text)
    except ValueError:
        pass
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number of rays, got {text!r}") from None
    if not math.isfinite(value) or value != math.floor(value):
        raise argparse.ArgumentTypeError(f"expected a whole number of rays, got {text!r}")
    return int(value)


class Parser(argparse.ArgumentParser):
    """argparse with the one-line errors of the rest of the command line: "error: <what>", exit 2. A
    misspelt option is named even where a required one is missing (argparse checks those first, so
    `render --secs 3` said only that --rays or --seconds is required)."""

    #: The arguments of the parse_args call running (a subcommand's parser is called inside it).
    argv: list[str] = []

    def parse_args(self, args=None, namespace=None):
        Parser.argv = list(sys.argv[1:] if args is None else args)
        return super().parse_args(Parser.argv, namespace)

    def error(self, message):
        if "required" in message:
            known = self._option_string_actions  # an abbreviation of one of them is one of them
            unknown = [a for a in Parser.argv if a.startswith("--")
                       and not any(o.startswith(a.split("=")[0]) for o in known)]
            if unknown:
                message = f"unrecognized arguments: {' '.join(unknown)}"
        self.exit(EXIT_INPUT, f"error: {message} (see {self.prog} --help)\n")


def build_parser() -> argparse.ArgumentParser:
    from . import __version__
    from .core.validate import available_cpus
    from .methods import DEFAULT_METHOD, INTEGRATORS

    ap = Parser(prog="hud-trace", description="Render what an eye sees through a HUD, in cd/m^2.")
    ap.add_argument("--version", action="version", version=f"hud-trace {__version__}")
    sub = ap.add_subparsers(dest="command", required=True)
    r = sub.add_parser("render", help="render a preset or a scene folder")
    r.add_argument("scene", help="preset name (see `hud-trace presets`) or scene folder")
    r.add_argument("--method", choices=sorted(INTEGRATORS), default=DEFAULT_METHOD,
                   help=f"light-transport method (default {DEFAULT_METHOD})")
    b = r.add_mutually_exclusive_group(required=True)
    b.add_argument("--rays", type=ray_count, help="budget in traced ray segments (5000000 or 5e6)")
    b.add_argument("--seconds", type=float,
                   help="budget in wall-clock seconds from the command's start (loading the scene included; writing "
                        "the image set and then the analysis follow it)")
    r.add_argument("--seed", type=int, default=0,
                   help="the seed of the random streams, 0 to 2^63 - 1 (default 0): with --rays the same seed gives "
                        "the same image on any number of workers")
    r.add_argument("--eye", choices=("centre", "left", "right", "both"), default="centre",
                   help="the eye that sees: the scene's own (centre, the design eye point), or the left or right eye "
                        "of a binocular pair, IPD / 2 to that side (target.ipd_mm, default 65 mm); both: each into "
                        "OUT/left and OUT/right, and their previews side by side in OUT/both.png")
    r.add_argument("--out", required=True, help="output folder (image.exr, preview.png, report.json)")
    r.add_argument("--batch-size", type=int, default=None,
                   help="paths per batch, 1024 to 2^24 (default: 131072 with --rays; with --seconds sized so that a "
                        "batch takes about 2 %% of the budget)")
    r.add_argument("--workers", type=int, default=available_cpus(),
                   help="processes (default: one per core); with --rays the image does not depend on it")
    r.add_argument("--scheduler", metavar="ADDRESS", default=None, help=SCHEDULER_HELP)
    r.add_argument("--quiet", action="store_true", help="no progress bar")
    r.add_argument("--no-analysis", action="store_true",
                   help="leave the HUD figures, the brightness-theorem comparison and the optical analysis out of "
                        "report.json (they follow the image into report.json and take a few seconds)")
    r.add_argument("--allow-external-files", action="store_true",
                   help="let the scene name meshes and images outside its folder (absolute paths, \"..\", links "
                        "out of it); the folder is then no longer self-contained")
    r.set_defaults(func=cmd_render)
    p = sub.add_parser("presets", help="list the presets")
    p.set_defaults(func=cmd_presets)
    e = sub.add_parser("export", help="write a preset's scene folder")
    e.add_argument("preset")
    e.add_argument("dir")
    e.set_defaults(func=cmd_export)
    m = sub.add_parser("methods", help="list the light-transport methods")
    m.set_defaults(func=cmd_methods)
    o = sub.add_parser("readouts", help="print the HUD figures of a render's report.json")
    o.add_argument("report", help="a report.json, or the folder of a render")
    o.set_defaults(func=cmd_readouts)
    f = sub.add_parser("false-colour", help="write the false-colour luminance view of an image.exr")
    f.add_argument("image", help="an image.exr written by `hud-trace render` (its Y channel, or R, G, B)")
    f.add_argument("--out", required=True, help="the PNG file to write")
    f.add_argument("--min", type=float, default=None, metavar="CD_M2",
                   help="bottom of the scale, cd/m^2 (default: the decade at or below the 1st percentile of the lit "
                        "pixels)")
    f.add_argument("--max", type=float, default=None, metavar="CD_M2",
                   help="top of the scale, cd/m^2 (default: the decade at or above the maximum; at most 8 decades "
                        "in all)")
    f.set_defaults(func=cmd_false_colour)
    y = sub.add_parser("eyebox", help="scan the eyebox with the brightness-theorem analysis")
    y.add_argument("scene", help="preset name (see `hud-trace presets`) or scene folder")
    y.add_argument("--out", required=True, help="output folder (eyebox.csv, eyebox.png, eyebox.json)")
    y.add_argument("--half", type=float, nargs=2, default=(60.0, 30.0), metavar=("W", "H"),
                   help="half-widths of the grid of eye offsets, right and up, mm (default 60 30)")
    y.add_argument("--step", type=float, default=5.0, metavar="S", help="grid step, mm (default 5)")
    y.add_argument("--field", type=float, nargs=2, default=None, metavar=("FX", "FY"),
                   help="display field, full width and height, deg, centred on the gaze (default: found from the "
                        "scene, where the eye sees an LCD through the optics, or a lit screen)")
    y.add_argument("--threshold", type=float, default=0.5, metavar="T",
                   help="share of its design-eye luminance every field point keeps inside the eyebox (default 0.5)")
    y.add_argument("--photons", type=int, default=1_000_000, metavar="N",
                   help="particles of the photon map that lights a screen seen through optics (a rear-projection "
                        "HUD; about 5 s per million), used only where a scattering surface is lit through a lens "
                        "or mirror (default 1000000; 0: leave that light out)")
    y.add_argument("--seed", type=int, default=0, help="random seed of the photon map (default 0)")
    y.add_argument("--quiet", action="store_true", help="no progress bar")
    y.add_argument("--allow-external-files", action="store_true",
                   help="let the scene name meshes and images outside its folder")
    y.set_defaults(func=cmd_eyebox)
    q = sub.add_parser("optics", help="the optical analysis: VID, distortion, disparity and ghost over the eyebox",
                       description="Trace chief rays and thin bundles through the specular chain from the eye to the "
                                   "PGU, for the primary image and the ghost, from the design eye point and a grid of "
                                   "eye points over the eyebox, and report the metrics of a HUD design review against "
                                   "the scene's target block (docs/user/optics.md). Exit 3 where a requirement of "
                                   "target.requirements is not met or the scene shows no image.")
    q.add_argument("scene", help="preset name (see `hud-trace presets`) or scene folder")
    q.add_argument("--out", required=True, help="output folder (" + ", ".join(
        ("optics.json", "optics.csv", "optics-distortion.png", "optics-eyebox.png", "optics-vid.png")) + ")")
    q.add_argument("--field-grid", type=int, nargs=2, default=None, metavar=("NX", "NY"),
                   help="PGU field points across and up (default: the scene's target.field_grid, else 5 3)")
    q.add_argument("--eye-grid", type=int, nargs=2, default=None, metavar=("NX", "NY"),
                   help="eye points across and up the eyebox (default: the scene's target.eye_grid, else 9 5)")
    q.add_argument("--no-eyebox", action="store_true", help="the design eye point only")
    q.add_argument("--no-mesh-comparison", action="store_true",
                   help="skip tracing the optics with exact surfaces again on their meshes alone")
    q.add_argument("--allow-external-files", action="store_true",
                   help="let the scene name meshes and images outside its folder")
    q.set_defaults(func=cmd_optics)
    w = sub.add_parser("sweep", help="render a scene over a grid of scene.json values and judge each run",
                       description="Render a scene once per point of a grid of scene.json values (the cartesian "
                                   "product of every --set), with the same seed for every run, and say for which "
                                   "values every --require holds.")
    w.add_argument("scene", help="preset name (see `hud-trace presets`) or scene folder")
    w.add_argument("--set", action="append", default=[], metavar="FIELD=START:STOP:N", required=True,
                   help="a scene.json field and its N values from START to STOP: eye.pupil_diameter_mm, "
                        "methods.backward.max_depth, objects[led_*].emission.luminance (every object whose name "
                        "matches the glob); repeat for a grid of every combination (at most 500 runs)")
    w.add_argument("--log", action="append", default=[], metavar="FIELD",
                   help="make this --set field's values geometric (START and STOP > 0)")
    w.add_argument("--method", choices=sorted(INTEGRATORS), default=DEFAULT_METHOD,
                   help=f"light-transport method (default {DEFAULT_METHOD})")
    b = w.add_mutually_exclusive_group()
    b.add_argument("--rays", type=ray_count, help="budget of each run in traced ray segments (5000000 or 5e6)")
    b.add_argument("--seconds", type=float, help="budget of each run in wall-clock seconds")
    b.add_argument("--optics", action="store_true",
                   help="run the optical analysis (hud-trace optics) in place of a render: no budget; the keys of "
                        "--require and --y lie in optics (optics.design_eye.ghost_separation_arcmin, "
                        "optics.eyebox.dipvergence_mrad)")
    w.add_argument("--seed", type=int, default=0, help="the seed of every run (default 0)")
    w.add_argument("--workers", type=int, default=available_cpus(),
                   help="processes per run (default: one per core)")
    w.add_argument("--batch-size", type=int, default=None, help="paths per batch, as for render")
    w.add_argument("--scheduler", metavar="ADDRESS", default=None, help=SCHEDULER_HELP)
    w.add_argument("--out", required=True, help="output folder (runs/<k>/, sweep.csv, sweep.json, sweep.png)")
    w.add_argument("--require", action="append", default=[], metavar="\"KEY OP VALUE\"",
                   help="a requirement on each run's report: KEY a dotted path into it (hud.contrast_ratio, "
                        "hud.spot.peak_cd_m2, luminance.mean), OP one of >= <= > <, VALUE a number; repeatable")
    w.add_argument("--x", default=None, metavar="FIELD", help="the --set field on the chart's x axis (default: the "
                                                               "first)")
    w.add_argument("--y", action="append", default=[], metavar="KEY",
                   help="a report key to chart, one panel each (default: the required figures, or hud.symbol_cd_m2 "
                        "and hud.contrast_ratio)")
    w.add_argument("--quiet", action="store_true", help="no progress bar")
    w.set_defaults(func=cmd_sweep)
    return ap


@contextlib.contextmanager
def _signals_to(handler, signals=STOP_SIGNALS):
    """Within the block, ``signals`` go to ``handler`` (a function, or signal.SIG_IGN); the handlers they had
    come back after it. Outside the main thread (main called by a host program), where no handler can be
    set, nothing changes."""
    try:
        previous = {s: signal.signal(s, handler) for s in signals}
    except ValueError:
        previous = {}
    try:
        yield
    finally:
        for s, h in previous.items():
            signal.signal(s, h)


def _import_holding_interrupts() -> bool:
    """Import the modules the commands need with the stop signals held back; returns whether one came. A
    compiled module (numpy's, OpenImageIO's) turns an interrupt during its initialisation into an
    ImportError with a misleading message, so an interrupt must not land there."""
    came = []
    with _signals_to(lambda *_: came.append(True)):
        import presets  # noqa: F401

        from .products import falsecolour, render  # noqa: F401
        from .scans import eyebox, sweep  # noqa: F401
    return bool(came)


def _interrupt(signum, frame):
    """SIGTERM and SIGHUP before a command has its own handlers: as Ctrl-C, "interrupted before the work
    began" (exit 130, the output folder released) instead of the default death (exit 143, no word, a
    folder made for the outputs left behind)."""
    raise KeyboardInterrupt(signal.Signals(signum).name)


def _sets_committed() -> int:
    """Output sets moved into place by this process so far (tracer.products.outputs.committed; 0 before
    that module is imported)."""
    outputs = sys.modules.get(f"{__package__}.products.outputs")
    return outputs.committed() if outputs is not None else 0


def _end_session():
    """End the worker pool the command's renders shared (with the command, not at the interpreter's exit)
    and its Dask clients, with the stop signals ignored: the command's work is done or given up, and a
    signal that lands in the pool's bounded join (a second Ctrl-C just after the set was written) had
    printed a traceback."""
    with _signals_to(signal.SIG_IGN):
        parallel = sys.modules.get(f"{__package__}.runtime.parallel")
        if parallel is not None:
            parallel.close_shared_pool()
        distributed = sys.modules.get(f"{__package__}.runtime.distributed")
        if distributed is not None:
            distributed.close_clients()


def main(argv: list[str] | None = None) -> int:
    started = _command_start()
    written = _sets_committed()
    # SIGTERM and SIGHUP interrupt as Ctrl-C does until a command installs its own handlers
    with _signals_to(_interrupt, tuple(s for s in STOP_SIGNALS if s != signal.SIGINT)):
        try:
            if _import_holding_interrupts():
                raise KeyboardInterrupt
            args = build_parser().parse_args(argv)  # the parser lists the methods: it imports them
            args.started = started
            return args.func(args)
        except (SceneError, ArgumentError) as e:
            print(f"error: {e}", file=sys.stderr)
            return EXIT_INPUT
        except KeyboardInterrupt:  # before a command installs its own handlers, or after it has put them back
            if _sets_committed() > written:
                print("interrupted after the outputs were written: the output folder holds them", file=sys.stderr)
            else:
                print("interrupted before the work began: nothing written", file=sys.stderr)
            return EXIT_INTERRUPTED
        finally:
            _end_session()


if __name__ == "__main__":
    sys.exit(main())
