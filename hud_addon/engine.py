"""The render engine "HUD Tracer": thin; the work is in :func:`render_final`.

F12 (and ``blender -b file.blend -a``, frame by frame): export the depsgraph's scene at its frame to a
temporary scene folder, load it with the tracer (the same validation as the command line), run the
chosen method on the worker pool (Blender's Performance > Threads processes; the same image as one
process for a budget in rays), showing the Render Result as it converges (update_result at most once
a second), with progress (update_progress, update_stats) and cancel (test_break, checked between
ray batches). The Render Result gets Combined (apparent luminance, cd/m^2, linear Rec.709), Y
(cd/m^2) and Y_noise (the standard error of Y, cd/m^2), with the hybrid method one RGB pass per
channel (HUD, Environment: Combined is their sum), and the same hud:* fields as the command
line's image.exr as stamp data (written into the EXR Blender saves). The command line's report
(tracer.products.report.build_report) is kept in :data:`LAST_RENDER` and per scene in :data:`REPORTS`, for
hud-render's report.json and the HUD Readouts panel, with the false-colour view of Y
(tracer.products.falsecolour) in :data:`FALSE_COLOUR`. When Blender writes the render to a file (F12 with
write_still, an animation, ``blender -b -a``), the false-colour view and the report are written beside
it: ``<file>.falsecolour.png`` and ``<file>.report.json`` (:func:`write_beside`).
"""

from __future__ import annotations

import json
import sys
import tempfile
import threading
import time
import traceback
from pathlib import Path

import bpy
import numpy as np

from ..tracer.analysis.aims import aim_preflight
from ..tracer.core.errors import SceneError, StoppedBeforeFirstBatch, TracerError, one_line
from ..tracer.core.units import Y_WEIGHTS
from ..tracer.core.validate import WorkersError, check_workers
from ..tracer.methods import INTEGRATORS, Budget
from ..tracer.methods.base import NO_LIGHT_SOURCE
from ..tracer.products.falsecolour import false_colour
from ..tracer.products.outputs import png_file, write_as_set
from ..tracer.products.render import add_analysis, render_products, run_render
from ..tracer.products.report import finite_json
from ..tracer.runtime.distributed import SchedulerError, connect
from ..tracer.scene import load_scene
from ..tracer.transport.world import World
from .export import export_scene
from .messages import blender_terms, dark_scene_hint, generated_image_warnings

#: Extra passes written beside Combined: name -> (channels, channel ids, Blender pass type).
PASSES = {"Y": (1, "X", "VALUE"), "Y_noise": (1, "X", "VALUE")}
#: The passes of the hybrid method's channels (tracer.methods.hybrid): film group -> pass name; each
#: an RGB pass of that channel's apparent luminance, cd/m^2 (Combined is their sum).
CHANNEL_PASSES = {"hud": "HUD", "environment": "Environment"}


def passes_of(method: str) -> dict:
    """The extra passes of a render with ``method``."""
    if method != "hybrid":
        return PASSES
    return PASSES | {name: (3, "RGB", "COLOR") for name in CHANNEL_PASSES.values()}

#: The hud:units field of Blender's EXR (its passes differ from the command line's channels).
UNITS = ("Combined (R,G,B), Y: apparent luminance cd/m^2 (Rec.709, Y=0.2126R+0.7152G+0.0722B); "
         "Y_noise: standard error of Y, cd/m^2; HUD, Environment (hybrid method): each channel's R,G,B, cd/m^2")

#: The report of the last final render (tracer.products.report.build_report, as the command line writes it),
#: or {"error": message} when it failed. Read by hud-render for its report.json.
LAST_RENDER: dict = {}
#: The last report of each scene by name: what the HUD Readouts panel shows.
REPORTS: dict[str, dict] = {}
#: The false-colour view of each scene's last render: (sRGB uint8 (H', W', 3), its info).
FALSE_COLOUR: dict[str, tuple] = {}
#: Scenes whose current F12 reached the engine (render_init clears it): an F12 that Blender refused (no
#: camera, ...) runs the render handlers without the engine, and its scene's figures are dropped.
ENGINE_RAN: set[str] = set()
#: Scenes whose last F12 Blender refused: the HUD Readouts panel says so instead of an earlier render's figures.
REFUSED: set[str] = set()


@bpy.app.handlers.persistent
def _render_begins(scene, *_):
    """render_init handler: this F12 has not reached the engine yet."""
    ENGINE_RAN.discard(scene.name)


@bpy.app.handlers.persistent
def _render_ends(scene, *_):
    """render_post and render_cancel handler: where the engine never ran (Blender refused the render), the
    scene's last figures are dropped, so that the readouts do not show them as this F12's."""
    if scene.render.engine == "HUD_TRACER" and scene.name not in ENGINE_RAN:
        finish_analysis(scene.name)
        REPORTS.pop(scene.name, None)
        FALSE_COLOUR.pop(scene.name, None)
        REFUSED.add(scene.name)


#: The analysis that follows each scene's last render into its report (a thread: see :func:`render_final`).
ANALYSES: dict[str, threading.Thread] = {}


def finish_analysis(scene_name: str | None = None):
    """Wait for the analysis of ``scene_name``'s last render (of every scene's: None) to be in its report."""
    for name, thread in list(ANALYSES.items()):
        if scene_name is None or name == scene_name:
            thread.join()
            ANALYSES.pop(name, None)


def _analyse_later(scene_name: str, products, world, integrator, result):
    """The false-colour view (FALSE_COLOUR) and the analysis (tracer.products.render.add_analysis: HUD
    figures, brightness theorem, optics) of a render whose image is already in the Render Result, in a
    thread of its own: the report in REPORTS
    (and LAST_RENDER, while it is still this render's) reads "analysis": "pending" until it is done. The
    analysis touches no Blender data."""
    run_id = products.report["run_id"]

    def run():
        FALSE_COLOUR[scene_name] = false_colour(products.y)
        if products.report["analysis"] != "pending":
            return
        try:
            add_analysis(products, world, integrator, result)
        except Exception as e:  # noqa: BLE001 - a fault of the tracer: said in the report, not lost in a thread
            traceback.print_exc()
            products.report["analysis"] = f"failed: {type(e).__name__}: {e}"
        report = products.report
        for w in report["warnings"]:
            if w not in REPORTS.get(scene_name, {}).get("warnings", []):
                print(f"HUD Tracer: {w}", file=sys.stderr)
        if REPORTS.get(scene_name, {}).get("run_id") == run_id:
            REPORTS[scene_name] = REPORTS[scene_name] | report
        if LAST_RENDER.get("run_id") == run_id:
            LAST_RENDER.update(report)

    thread = threading.Thread(target=run, name=f"hud-analysis-{scene_name}", daemon=True)
    ANALYSES[scene_name] = thread
    thread.start()


def worker_count(scene) -> int:
    """Processes for a render: Blender's Performance > Threads (auto-detect: every core)."""
    return max(1, int(scene.render.threads))


def write_passes(layer, image: np.ndarray, var_y: np.ndarray, channels: dict | None = None):
    """Apparent luminance (H, W, 3) cd/m^2 and Y's variance (H, W) into a Render Result layer:
    Combined (RGBA, alpha 1), Y and Y_noise, and each channel's image ({film group: (H, W, 3)}) in its
    pass (CHANNEL_PASSES); rows go bottom-up (Blender's row 0 is the bottom row), contiguous float32,
    one foreach_set per pass."""
    h, w = image.shape[:2]
    for group, rgb in (channels or {}).items():
        layer.passes[CHANNEL_PASSES[group]].rect.foreach_set(np.ascontiguousarray(rgb[::-1], dtype=np.float32).ravel())
    flipped = image[::-1].astype(np.float32)
    rgba = np.concatenate([flipped, np.ones((h, w, 1), np.float32)], axis=2)
    layer.passes["Combined"].rect.foreach_set(np.ascontiguousarray(rgba).ravel())
    y = flipped @ Y_WEIGHTS.astype(np.float32)
    layer.passes["Y"].rect.foreach_set(np.ascontiguousarray(y, dtype=np.float32).ravel())
    noise = np.sqrt(np.maximum(var_y[::-1], 0.0))
    layer.passes["Y_noise"].rect.foreach_set(np.ascontiguousarray(noise, dtype=np.float32).ravel())


def _fail(engine, scene, message: str, key: str = "error") -> dict:
    """A render that gives no estimate: ``key`` "error" (reported as an error) or "stopped" (cancelled
    before its first batch ended, reported as information). The scene's last report and false-colour
    view are dropped, so that neither the readouts nor a file Blender writes now shows an earlier
    render's figures as this one's."""
    engine.report({"ERROR"} if key == "error" else {"INFO"}, f"HUD Tracer: {message}")
    REPORTS.pop(scene.name, None)
    FALSE_COLOUR.pop(scene.name, None)
    LAST_RENDER.clear()
    LAST_RENDER[key] = message
    return dict(LAST_RENDER)


def unsupported_output(scene) -> str | None:
    """The output settings the engine cannot honour, in the words of Blender's panels, or None. The
    tracer renders one eye's whole frame of square pixels: a Render Region's smaller result made the
    passes' sizes disagree (a TypeError, then a crash in Blender), and Stereoscopy's second view and a
    pixel aspect were rendered as if they were not set."""
    r = scene.render
    if r.use_border:
        return ("Output Properties > Format > Render Region: not supported (the eye's whole frame is rendered); "
                "turn it off, or narrow the camera's field of view instead")
    if r.use_multiview:
        return ("Output Properties > Stereoscopy: not supported (one eye per render); turn it off and render each "
                "eye's camera on its own")
    if r.pixel_aspect_x != r.pixel_aspect_y:
        return (f"Output Properties > Format > Aspect X / Y ({r.pixel_aspect_x:g} / {r.pixel_aspect_y:g}): the "
                "retina's pixels are square; set both to the same value")
    return None


def render_final(engine, depsgraph) -> dict:
    """Render the depsgraph's scene into ``engine``'s result. Returns the report, or {"error": ...}, or
    {"stopped": ...} when test_break ended the render before its first batch (the result stays empty)."""
    scene = depsgraph.scene
    ENGINE_RAN.add(scene.name)
    REFUSED.discard(scene.name)
    s = scene.hud
    # Seconds count from F12, as the command line's from its start: the export and loading are part of them
    budget = Budget(rays=s.rays) if s.budget == "RAYS" else Budget(seconds=s.seconds, since=time.perf_counter())
    if (message := unsupported_output(scene)) is not None:
        return _fail(engine, scene, message)
    with tempfile.TemporaryDirectory(prefix="hud-blender-") as tmp:
        folder = Path(tmp) / "scene"
        try:
            export_scene(depsgraph, folder)
            tracer_scene = load_scene(folder)
        except SceneError as e:
            return _fail(engine, scene, blender_terms(e, folder, scene))
        except ValueError as e:
            return _fail(engine, scene, str(e))
        for w in generated_image_warnings(scene):
            engine.report({"WARNING"}, f"HUD Tracer: {w}")
        width, height = tracer_scene.eye.resolution
        scheduler = s.scheduler.strip() or None
        try:
            if scheduler is None:
                check_workers(worker_count(scene), (width, height))
            else:  # reached before the first ray
                connect(scheduler)
        except WorkersError as e:
            return _fail(engine, scene, f"Render Properties > Performance > Threads: {e}")
        except SchedulerError as e:
            return _fail(engine, scene, f"Render Properties > HUD Tracer > Dask Scheduler: {e}")
        world = World(tracer_scene)
        integrator = INTEGRATORS[s.method](world, s.seed)
        for w in aim_preflight(world, s.method, integrator.renders_environment):
            engine.report({"WARNING"}, f"HUD Tracer: before the first ray: {w}")
        integrator.notice = lambda w: engine.report({"WARNING"}, f"HUD Tracer: {w}")
        for name, (channels, chan_id, _) in passes_of(s.method).items():
            engine.add_pass(name, channels, chan_id)
        rr = engine.begin_result(0, 0, width, height)

        def channels_of(film) -> dict:
            return {g: film.rgb(g) for g in film.groups if g in CHANNEL_PASSES} if s.method == "hybrid" else {}

        def progress(fraction, message):
            engine.update_progress(fraction)
            engine.update_stats("HUD Tracer", message)

        def preview(film):
            write_passes(rr.layers[0], film.rgb(), film.variance_y(), channels_of(film))
            engine.update_result(rr)

        t0 = time.perf_counter()
        try:
            integrator, result = run_render(integrator, budget, worker_count(scene), progress, engine.test_break,
                                            preview, scheduler)
            products = render_products(integrator.world, integrator, result, budget, analyse=False)
        except StoppedBeforeFirstBatch as e:
            engine.end_result(rr)
            return _fail(engine, scene, f"{e}: nothing rendered", "stopped")
        except (TracerError, RuntimeError, FloatingPointError, OSError) as e:
            engine.end_result(rr)
            cluster = scheduler is not None and (str(e).startswith("on the Dask worker")
                                                 or type(e).__module__.split(".")[0] == "distributed")
            where = f"Render Properties > HUD Tracer > Dask Scheduler: {scheduler}: " if cluster else ""
            return _fail(engine, scene, where + one_line(e))
        except Exception as e:  # a fault of the tracer: the result is ended (Blender crashes on an open one)
            engine.end_result(rr)
            traceback.print_exc()
            return _fail(engine, scene, f"internal error ({type(e).__name__}: {e}); the traceback is on the console")
        write_passes(rr.layers[0], products.image, products.var_y, channels_of(result.film))
        engine.end_result(rr)
        full = engine.get_result()  # stamp data belongs to the whole result, not to the part just written
        attrs = products.attrs | {"hud:units": UNITS}
        for key, value in attrs.items():
            full.stamp_data_add_field(key, str(value))
    products.report["blender"] = {"frame": scene.frame_current, "wall_seconds": time.perf_counter() - t0}
    report = dict(products.report)
    hint = dark_scene_hint(scene) if any(w.startswith(NO_LIGHT_SOURCE) for w in report["warnings"]) else ""
    if hint:  # the dark scene's warning, with what Blender shows that the tracer does not take
        report["warnings"] = [f"{w}; {hint}" if w.startswith(NO_LIGHT_SOURCE) else w for w in report["warnings"]]
    for w in report["warnings"]:
        engine.report({"WARNING"}, f"HUD Tracer: {w}")
    LAST_RENDER.clear()
    LAST_RENDER.update(report)
    REPORTS[scene.name] = report
    FALSE_COLOUR.pop(scene.name, None)  # the false-colour view follows, with the analysis
    _analyse_later(scene.name, products, integrator.world, integrator, result)
    return dict(report)


def beside(path: Path) -> tuple[Path, Path]:
    """The false-colour view's and the report's paths beside a rendered file."""
    return path.with_name(path.name + ".falsecolour.png"), path.with_name(path.name + ".report.json")


def written_file(scene) -> Path | None:
    """The file Blender has just written for ``scene``'s frame: an animation's frame path (with the
    frame number), or a still's (without it), whichever exists and is the newer."""
    r = scene.render
    still = bpy.path.abspath(r.filepath) + (r.file_extension if r.use_file_extension else "")
    frame = bpy.path.abspath(r.frame_path(frame=scene.frame_current))
    found = [p for p in {Path(still), Path(frame)} if p.is_file()]
    return max(found, key=lambda p: p.stat().st_mtime_ns) if found else None


@bpy.app.handlers.persistent  # kept when a file is opened (hud-render opens one after enabling us)
def write_beside(scene, *_):
    """render_write handler: beside the file Blender has just written for ``scene``'s frame, the
    false-colour view and the report of that render (each written as a set: tracer.products.outputs)."""
    finish_analysis(scene.name)
    report = REPORTS.get(scene.name)
    if report is None or report.get("blender", {}).get("frame") != scene.frame_current:
        return
    written = written_file(scene)
    if written is None:
        return
    colour_path, report_path = beside(written)
    f = png_file(colour_path.name, FALSE_COLOUR[scene.name][0])
    write_as_set(colour_path, f.write, f.check)
    text = finite_json(report | {"image_file": str(written)})
    write_as_set(report_path, lambda p: Path(p).write_text(text),
                 lambda p: finite_json(json.loads(Path(p).read_text())))


class HudRenderEngine(bpy.types.RenderEngine):
    bl_idname = "HUD_TRACER"
    bl_label = "HUD Tracer"
    bl_use_preview = False
    bl_use_shading_nodes_custom = False

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)  # required since Blender 4.4

    def render(self, depsgraph):
        render_final(self, depsgraph)

    def update_render_passes(self, scene=None, renderlayer=None):
        self.register_pass(scene, renderlayer, "Combined", 4, "RGBA", "COLOR")
        for name, (channels, chan_id, kind) in passes_of(scene.hud.method if scene is not None else "").items():
            self.register_pass(scene, renderlayer, name, channels, chan_id, kind)


_register_classes, _unregister_classes = bpy.utils.register_classes_factory((HudRenderEngine,))


_HANDLERS = (("render_write", write_beside), ("render_init", _render_begins), ("render_post", _render_ends),
             ("render_cancel", _render_ends))


def register():
    _register_classes()
    for kind, handler in _HANDLERS:
        getattr(bpy.app.handlers, kind).append(handler)


def unregister():
    from ..tracer.runtime.parallel import close_shared_pool

    finish_analysis()  # no thread of ours outlives the add-on
    close_shared_pool()  # the session's worker processes, kept from F12 to F12, end with the add-on
    for kind, handler in _HANDLERS:
        if handler in getattr(bpy.app.handlers, kind):
            getattr(bpy.app.handlers, kind).remove(handler)
    _unregister_classes()
