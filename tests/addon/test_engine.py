"""The render engine (hud_addon/engine.py): cancelling within one batch or before the first, output settings
it cannot honour refused in one line, every core used with progress shown, no light and a misaimed source
reported, an animated camera rendering each frame from its own eye, and the hybrid method's passes, also
for a study preset.

Each scenario (a ``scenario_*`` function: the scene set up, rendered or exported inside the bpy module)
sits before the tests that assert on its result, and runs in a process of its own through
tests/addon/blender_runner.py (tests.support.addon.in_blender)."""

from __future__ import annotations

import json
import math
import os
import sys
import tempfile
from pathlib import Path

import numpy as np
import pytest

from tests.support.addon import in_blender, needs_bpy, read_multilayer

pytestmark = [needs_bpy, pytest.mark.slow]


def scenario_cancel(threads, when):
    """A 600 s render on ``threads`` processes cancelled at the first test_break after the first batch
    was merged (``when`` "after_first_batch") or at the very first one ("at_once")."""
    import time

    import bpy

    from tests.support.blender import StubEngine, disable, enable_from_source

    module = enable_from_source(bpy, Path(tempfile.mkdtemp()))
    bpy.ops.hud.add_preset(preset="hud-direct")
    scene = bpy.context.scene
    scene.hud.method, scene.hud.budget, scene.hud.seconds = "forward", "SECONDS", 600.0
    scene.render.threads_mode, scene.render.threads = "FIXED", int(threads)
    engine_mod = sys.modules[f"{module}.hud_addon.engine"]
    engine_mod.REPORTS[scene.name] = {"blender": {"frame": scene.frame_current}}  # an earlier render's
    stub = StubEngine(stop_after={"after_first_batch": None, "at_once": 0}[when])
    t0 = time.perf_counter()
    figures = engine_mod.render_final(stub, bpy.context.evaluated_depsgraph_get())
    seconds = time.perf_counter() - t0
    passes = stub.result.layers[0].passes if stub.result is not None else {}
    out = {"figures": figures, "test_break_calls": stub.calls, "seconds": seconds, "reports": stub.reports,
           "samples": {k: passes[k].values for k in ("Combined", "Y", "Y_noise") if k in passes},
           "kept_report": scene.name in engine_mod.REPORTS, "last_render": dict(engine_mod.LAST_RENDER)}
    disable(module)
    return out


@pytest.mark.parametrize("threads", [1, 2])
def test_cancel_stops_within_one_batch_and_writes_a_clean_result(threads):
    """Esc in a 600 s render, at the first check of test_break after the first batch was merged: the
    render stops there, with a clean partial result (every pass finite). One process has merged that
    batch alone; on a pool the batches that had ended when the parent took the first are merged with it
    (at most the two per worker in flight: a worker can end its second while the parent merges) and
    nothing that came later."""
    res, _ = in_blender(scenario_cancel, threads, "after_first_batch")
    f = res["figures"]
    assert f["partial"] is True and 1 <= f["batches"] <= 2 * threads and f["workers"] == threads
    if threads == 1:
        assert f["batches"] == 1 and res["test_break_calls"] == 2  # one batch ran, the second check stopped it
    assert res["seconds"] < 30 and res["kept_report"]
    for name, values in res["samples"].items():
        assert values and all(math.isfinite(v) for v in values), name


@pytest.mark.parametrize("threads", [1, 2])
def test_cancel_before_the_first_batch_says_so_and_keeps_no_figures(threads):
    """Esc before any batch ended: no estimate, so no report and no "no light path found" diagnosis of a
    scene that has light; an information line says what happened, and the scene's earlier report is
    dropped (a file Blender writes now must not get an earlier render's report beside it)."""
    res, _ = in_blender(scenario_cancel, threads, "at_once")
    (message,) = res["reports"]
    assert res["figures"] == res["last_render"] == {"stopped": message[len("HUD Tracer: "):]}
    assert "before the first batch ended: nothing rendered" in message and "light" not in message
    assert res["test_break_calls"] == 1 and not res["kept_report"] and res["seconds"] < 30


def scenario_unsupported_output(out):
    """F12 (bpy.ops.render.render, write_still) of analytic-mirror with each output setting the engine
    cannot honour, and with more processes than the memory holds (the add-on's tracer told the machine
    has 1 GiB): the error Blender reports, and the files written."""
    import bpy

    from tests.support.blender import disable, enable_from_source

    module = enable_from_source(bpy, Path(tempfile.mkdtemp()))
    engine_mod = sys.modules[f"{module}.hud_addon.engine"]
    validate = sys.modules[f"{module}.tracer.core.validate"]
    cases = {"region, cropped": {"use_border": True, "use_crop_to_border": True},
             "region": {"use_border": True, "use_crop_to_border": False},
             "stereoscopy": {"use_multiview": True},
             "pixel aspect": {"pixel_aspect_x": 2.0},
             "threads": {"threads_mode": "FIXED", "threads": 16}}
    result = {}
    for name, settings in cases.items():
        bpy.ops.hud.add_preset(preset="analytic-mirror")
        scene = bpy.context.scene
        scene.hud.budget, scene.hud.rays = "RAYS", 100_000
        scene.render.resolution_x, scene.render.resolution_y = 32, 24
        scene.render.border_min_x, scene.render.border_max_x = 0.25, 0.75
        for key, value in settings.items():
            setattr(scene.render, key, value)
        folder = Path(out) / name.replace(", ", "_").replace(" ", "_")
        folder.mkdir(parents=True)
        scene.render.image_settings.file_format = "OPEN_EXR_MULTILAYER"
        scene.render.filepath, scene.render.use_file_extension = str(folder / "img.exr"), False
        memory = validate.physical_memory_bytes
        validate.physical_memory_bytes = lambda: 2**30
        try:
            bpy.ops.render.render(write_still=True)
            raised = None
        except RuntimeError as e:
            raised = str(e)
        finally:
            validate.physical_memory_bytes = memory
        for key in settings:  # back to the defaults for the next case
            setattr(scene.render, key, {"threads_mode": "AUTO", "threads": 1, "pixel_aspect_x": 1.0}.get(key, False))
        result[name] = {"raised": raised, "error": engine_mod.LAST_RENDER.get("error"),
                        "files": sorted(p.name for p in folder.iterdir())}
    disable(module)
    return result


def test_output_settings_the_engine_cannot_honour_are_refused_in_one_line(tmp_path):
    """A Render Region made the passes' sizes disagree with the frame (a TypeError, then Blender crashed),
    Stereoscopy's second eye and a pixel aspect were rendered as if not set, and more processes than the
    memory holds ended in a WorkersError traceback and a crash. Now each is refused before the first ray,
    naming Blender's panel and field, and nothing is written."""
    res, proc = in_blender(scenario_unsupported_output, tmp_path)
    assert "Traceback" not in proc.stdout + proc.stderr
    where = {"region, cropped": "Render Region", "region": "Render Region", "stereoscopy": "Stereoscopy",
             "pixel aspect": "Aspect X / Y", "threads": "Performance > Threads"}
    for name, words in where.items():
        case = res[name]
        assert case["error"] and words in case["error"] and words in (case["raised"] or ""), (name, case)
        assert case["files"] == [], (name, case)
    assert "at most" in res["threads"]["error"]


def scenario_progressive(seconds):
    """A render of ``seconds`` with Blender's default Performance > Threads (auto-detect): the number of
    processes, and how often the Render Result was updated while it ran."""
    import bpy

    from tests.support.blender import StubEngine, disable, enable_from_source

    module = enable_from_source(bpy, Path(tempfile.mkdtemp()))
    bpy.ops.hud.add_preset(preset="hud-direct")
    scene = bpy.context.scene
    scene.hud.method, scene.hud.budget, scene.hud.seconds = "backward", "SECONDS", float(seconds)
    stub = StubEngine(stop_after=10**9)
    report = sys.modules[f"{module}.hud_addon.engine"].render_final(stub, bpy.context.evaluated_depsgraph_get())
    disable(module)
    return {"workers": report["workers"], "batches": report["batches"], "seconds": report["seconds"],
            "updates": stub.updates, "threads_mode": scene.render.threads_mode, "cpus": os.cpu_count()}


@pytest.mark.serial
def test_a_render_in_blender_uses_every_core_and_shows_its_progress():
    """With Blender's default threads (auto-detect) a render runs on one process per
    core, and the Render Result is updated while it runs (at most once a second, after merged batches)."""
    res, _ = in_blender(scenario_progressive, 6)
    assert res["threads_mode"] == "AUTO" and res["workers"] == res["cpus"]
    assert res["batches"] > 3
    assert 2 <= res["updates"] <= res["seconds"] + 1


def scenario_no_light():
    import bpy

    from tests.support.blender import StubEngine, disable, enable_from_source

    module = enable_from_source(bpy, Path(tempfile.mkdtemp()))
    bpy.ops.hud.add_preset(preset="analytic-mirror")
    scene = bpy.context.scene
    bpy.data.objects["panel"].hud.emission_luminance = 0.0
    scene.hud.method, scene.hud.budget, scene.hud.rays = "backward", "RAYS", 200_000
    stub = StubEngine(stop_after=10**9)
    figures = sys.modules[f"{module}.hud_addon.engine"].render_final(stub, bpy.context.evaluated_depsgraph_get())
    disable(module)
    return {"figures": figures, "reports": stub.reports}


def test_render_reports_no_light_to_the_user():
    res, _ = in_blender(scenario_no_light)
    assert res["figures"]["efficiency"] == 0
    assert any("the scene has no light source" in r for r in res["reports"])  # its one emitter is at 0 cd/m^2


def scenario_misaimed():
    """analytic-mirror with its pupil image (the panel's aim target) shrunk to half its size, rendered
    forward: what the engine reports, before the first ray and after the render."""
    import bpy

    from tests.support.blender import StubEngine, disable, enable_from_source

    module = enable_from_source(bpy, Path(tempfile.mkdtemp()))
    bpy.ops.hud.add_preset(preset="analytic-mirror")
    scene = bpy.context.scene
    bpy.data.objects["pupil_image"].scale = (0.5, 0.5, 0.5)
    scene.hud.method, scene.hud.budget, scene.hud.rays = "forward", "RAYS", 200_000
    stub = StubEngine(stop_after=10**9)
    engine_mod = sys.modules[f"{module}.hud_addon.engine"]
    figures = engine_mod.render_final(stub, bpy.context.evaluated_depsgraph_get())
    pending = engine_mod.REPORTS[scene.name]["analysis"]
    engine_mod.finish_analysis(scene.name)  # the analysis follows the image (a thread)
    analysed = engine_mod.REPORTS[scene.name]
    disable(module)
    return {"figures": figures, "reports": stub.reports, "pending": pending, "analysis": analysed["analysis"],
            "warnings": analysed["warnings"], "hud": analysed["hud"] is not None}


def test_an_aim_that_misses_light_is_reported_when_the_render_starts():
    """The panel's aim target shrunk to half its size covers about a quarter of the light that reaches
    the eye: the engine reports it before the first ray (first of its reports), and the report's own
    analysis, which follows the image into the scene's report (HUD Readouts), says it again."""
    res, _ = in_blender(scenario_misaimed)
    early = [i for i, r in enumerate(res["reports"])
             if r.startswith("HUD Tracer: before the first ray: the aim of panel toward pupil_image covers")]
    late = [w for w in res["warnings"] if w.startswith("the aim of panel toward pupil_image covers")]
    assert early == [0] and len(late) == 1, res
    assert res["pending"] == "pending" and res["analysis"] == "done" and res["hud"]


def scenario_animation(out):
    """A camera keyframed at x = -50, 0, +50 mm over frames 1-3: Blender's own
    animation render (``render(animation=True)``, as ``blender -b file.blend -a``) writes one EXR per
    frame, each exported from the depsgraph at its frame."""
    import bpy

    from tests.support.blender import disable, enable_from_source

    module = enable_from_source(bpy, Path(tempfile.mkdtemp()))
    bpy.ops.hud.add_preset(preset="analytic-mirror")
    scene = bpy.context.scene
    unit_mm = 1000.0 * scene.unit_settings.scale_length
    cam = scene.camera
    x0 = cam.location.x
    for frame, dx_mm in ((1, -50.0), (2, 0.0), (3, 50.0)):
        cam.location.x = x0 + dx_mm / unit_mm
        cam.keyframe_insert("location", index=0, frame=frame)
    scene.frame_start, scene.frame_end = 1, 3
    scene.hud.method, scene.hud.budget, scene.hud.rays, scene.hud.seed = "backward", "RAYS", 300_000, 3
    s = scene.render.image_settings
    s.file_format, s.color_depth = "OPEN_EXR_MULTILAYER", "32"
    scene.render.filepath = str(Path(out) / "frame_####")
    engine_mod = sys.modules[f"{module}.hud_addon.engine"]
    eyes = {}

    def remember(scene_, depsgraph=None):
        eyes[scene_.frame_current] = dict(engine_mod.LAST_RENDER).get("run_id")

    bpy.app.handlers.render_post.append(remember)
    bpy.ops.render.render(animation=True)
    bpy.app.handlers.render_post.remove(remember)
    exported = {}
    for frame in (1, 2, 3):  # the export operator at each frame (the viewport's depsgraph)
        scene.frame_set(frame)
        bpy.ops.hud.export_scene(directory=str(Path(out) / f"scene_{frame}"))
        exported[frame] = json.loads((Path(out) / f"scene_{frame}" / "scene.json").read_text())["eye"]["position"]
    disable(module)
    return {"x0_mm": x0 * unit_mm, "run_ids": eyes, "exported_eye_mm": exported,
            "files": sorted(p.name for p in Path(out).glob("frame_*.exr"))}


def test_an_animated_camera_renders_each_frame_from_its_own_eye(tmp_path):
    """With the camera keyframed at x = -50, 0, +50 mm, Blender's animation render
    gives three different frames, each the tracer's render from that frame's eye: the mirror image
    of the panel moves across the retina, and the export operator writes that frame's eye."""
    res, _ = in_blender(scenario_animation, tmp_path)
    assert res["files"] == ["frame_0001.exr", "frame_0002.exr", "frame_0003.exr"]
    x0 = res["x0_mm"]
    for frame, dx in (("1", -50.0), ("2", 0.0), ("3", 50.0)):
        assert res["exported_eye_mm"][frame][0] == pytest.approx(x0 + dx, abs=1e-3)
    assert len(set(res["run_ids"].values())) == 3  # three renders, one per frame
    for k, name in enumerate(res["files"], start=1):  # each frame's report and false colour beside it
        beside = json.loads((tmp_path / f"{name}.report.json").read_text())
        assert beside["blender"]["frame"] == k and beside["run_id"] == res["run_ids"][str(k)]
        assert (tmp_path / f"{name}.falsecolour.png").is_file()
    centroids = []
    for name in res["files"]:
        y = read_multilayer(tmp_path / name)["ViewLayer.Y.X"]
        lit = y > 0.5 * y.max()
        centroids.append(np.nonzero(lit)[1].mean())
    # The eye moves right: the panel's edge, seen in the mirror, moves across the image, each frame
    # by the same number of pixels (the same 50 mm step), well beyond a pixel.
    steps = np.diff(centroids)
    assert abs(steps[0]) > 1 and np.sign(steps[0]) == np.sign(steps[1])
    assert steps[1] == pytest.approx(steps[0], rel=0.2)


def scenario_hybrid_passes(out):
    """hud-direct against a uniform 1000 cd/m^2 World, rendered with the hybrid method into a
    multilayer EXR: one pass per channel."""
    import bpy

    from tests.support.blender import disable, enable_from_source

    module = enable_from_source(bpy, Path(tempfile.mkdtemp()))
    bpy.ops.hud.add_preset(preset="hud-direct")
    scene = bpy.context.scene
    scene.world.hud.kind, scene.world.hud.luminance = "uniform", 1000.0
    scene.hud.method, scene.hud.budget, scene.hud.rays, scene.hud.seed = "hybrid", "RAYS", 3_000_000, 2
    scene.render.resolution_percentage = 50
    s = scene.render.image_settings
    s.file_format, s.color_depth = "OPEN_EXR_MULTILAYER", "32"
    scene.render.filepath = str(Path(out) / "hybrid.exr")
    scene.render.use_file_extension = False
    bpy.ops.render.render(write_still=True)
    report = dict(sys.modules[f"{module}.hud_addon.engine"].LAST_RENDER)
    disable(module)
    return {"channels": {k: v.get("method") for k, v in report["method_details"]["channels"].items()}}


def test_the_hybrid_method_gives_one_render_pass_per_channel(tmp_path):
    """Rendered with the hybrid method in Blender, the
    Render Result has a HUD pass and an Environment pass, and Combined is their sum."""
    res, _ = in_blender(scenario_hybrid_passes, tmp_path)
    assert res["channels"] == {"hud": "backward", "environment": "backward"}
    ch = read_multilayer(tmp_path / "hybrid.exr")
    for c in "RGB":
        hud, env = ch[f"ViewLayer.HUD.{c}"], ch[f"ViewLayer.Environment.{c}"]
        np.testing.assert_allclose(ch[f"ViewLayer.Combined.{c}"], hud + env, rtol=1e-5, atol=1e-3)
    assert ch["ViewLayer.Environment.G"].max() > 500 and ch["ViewLayer.HUD.G"].max() > 5000


def scenario_study_preset(out, preset):
    """A study preset (a HUD against a real panorama) added in Blender and rendered as built (its
    method, its eye): the passes and what the report says of the pupil and the channels."""
    import bpy

    from tests.support.blender import disable, enable_from_source

    module = enable_from_source(bpy, Path(tempfile.mkdtemp()))
    bpy.ops.hud.add_preset(preset=preset)
    scene = bpy.context.scene
    method, pupil = scene.hud.method, scene.camera.data.hud.pupil
    scene.hud.budget, scene.hud.rays, scene.hud.seed = "RAYS", 4_000_000, 1
    s = scene.render.image_settings
    s.file_format, s.color_depth = "OPEN_EXR_MULTILAYER", "32"
    scene.render.filepath = str(Path(out) / "study.exr")
    scene.render.use_file_extension = False
    bpy.ops.render.render(write_still=True)
    report = dict(sys.modules[f"{module}.hud_addon.engine"].LAST_RENDER)
    disable(module)
    return {"method": method, "pupil": pupil, "pupil_report": report["method_details"].get("pupil"),
            "channels": {k: v.get("method") for k, v in report["method_details"]["channels"].items()},
            "adaptation_mode": report["adaptation_mode"]}


def test_a_study_preset_renders_in_blender_with_its_channels_and_its_eye(tmp_path):
    """hud-direct-env added with Add HUD Preset renders with the hybrid method (the
    preset has a lit panorama), the pupil following the image and the mean adaptation, one pass per
    channel in the Render Result."""
    res, _ = in_blender(scenario_study_preset, tmp_path, "hud-direct-env")
    assert res["method"] == "hybrid" and res["pupil"] == "IMAGE" and res["adaptation_mode"] == "mean"
    assert res["channels"] == {"hud": "backward", "environment": "backward"}
    assert res["pupil_report"]["pupil_diameter_mm"] < 3.0  # a day: a small pupil
    ch = read_multilayer(tmp_path / "study.exr")
    np.testing.assert_allclose(ch["ViewLayer.Combined.G"], ch["ViewLayer.HUD.G"] + ch["ViewLayer.Environment.G"],
                               rtol=1e-5, atol=1e-2)


def scenario_refused():
    """analytic-mirror rendered (F12), then F12 without a camera (Blender refuses it), then with the camera
    again: the scene's figures after each, and what the HUD Readouts panel says after the refusal."""
    import bpy

    from tests.support.blender import Layout, disable, enable_from_source

    module = enable_from_source(bpy, Path(tempfile.mkdtemp()))
    bpy.ops.hud.add_preset(preset="analytic-mirror")
    scene = bpy.context.scene
    scene.hud.method, scene.hud.budget, scene.hud.rays = "backward", "RAYS", 200_000
    engine_mod = sys.modules[f"{module}.hud_addon.engine"]
    ui_mod = sys.modules[f"{module}.hud_addon.ui"]
    bpy.ops.render.render()
    first = scene.name in engine_mod.REPORTS
    camera, scene.camera = scene.camera, None
    try:
        bpy.ops.render.render()
        refused = ""
    except RuntimeError as e:
        refused = str(e)
    labels = []

    class Panel:
        layout = Layout(labels)

    ui_mod.HUD_PT_readouts.draw(Panel(), bpy.context)
    after_refusal = scene.name in engine_mod.REPORTS
    scene.camera = camera
    bpy.ops.render.render()
    again = scene.name in engine_mod.REPORTS and scene.name not in engine_mod.REFUSED
    disable(module)
    return {"first": first, "refused": refused, "after_refusal": after_refusal, "labels": labels, "again": again}


def test_readouts_are_cleared_when_blender_refuses_to_render():
    """Issue 31's walk-through: when Blender refused to render (no camera), HUD Readouts kept the previous
    render's figures, as if they were this F12's. The render handlers run even for a refused F12, the
    engine does not: the scene's figures are dropped and the panel says the render was refused; the next
    F12 that renders shows its own figures."""
    res, _ = in_blender(scenario_refused)
    assert res["first"] and "camera" in res["refused"], res
    assert not res["after_refusal"] and any("refused the last render" in str(x) for x in res["labels"]), res
    assert res["again"]
