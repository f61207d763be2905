"""The Blender add-on, tested with the bpy 4.5 module headless (each scenario in its own process;
see tests/blender_scenarios.py)."""

import importlib.util
import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from conftest import ROOT, film_dof, render, t_bound, z_bound

_BPY = importlib.util.find_spec("bpy")
if _BPY is None:
    pytest.skip("the bpy 4.5 module is needed for the add-on tests", allow_module_level=True)
#: Blender's own extension tool, shipped inside the bpy package (bpy/<4.x>/scripts/..., found without importing
#: bpy here): the tool of the bpy under test, 4.5 or the oldest the manifest allows (`make test-bpy-oldest`).
(BLENDER_EXT,) = Path(_BPY.origin).parent.glob("[0-9]*/scripts/addons_core/bl_pkg/cli/blender_ext.py")


def scenario(*args, timeout=600):
    proc = subprocess.run([sys.executable, str(ROOT / "tests" / "blender_scenarios.py"), *map(str, args)],
                          capture_output=True, text=True, timeout=timeout, cwd=ROOT)
    assert proc.returncode == 0, proc.stderr[-3000:] + proc.stdout[-3000:]
    line = next(x for x in proc.stdout.splitlines() if x.startswith("HUD_RESULT "))
    return json.loads(line[len("HUD_RESULT "):]), proc


def read_multilayer(path):
    import OpenImageIO as oiio

    inp = oiio.ImageInput.open(str(path))
    spec = inp.spec()
    px = inp.read_image(oiio.FLOAT)
    inp.close()
    return {name: px[:, :, i] for i, name in enumerate(spec.channelnames)}


def _manifest() -> dict:
    import tomllib

    return tomllib.loads((ROOT / "blender_manifest.toml").read_text())


def _this_platform() -> str:
    """This machine as Blender names platforms in the manifest (linux-x64, windows-x64, macos-arm64, ...)."""
    import platform

    system = {"darwin": "macos", "win32": "windows"}.get(sys.platform, sys.platform)
    machine = {"x86_64": "x64", "amd64": "x64", "aarch64": "arm64"}.get(platform.machine().lower(),
                                                                        platform.machine().lower())
    return f"{system}-{machine}"


@pytest.fixture(scope="session")
def extension_zip(tmp_path_factory):
    """Build the extension as `make extension` does (tools/build_extension.py: the pinned wheels fetched from
    PyPI, Blender's own tool with --split-platforms, every zip validated); the zip for this machine."""
    out = tmp_path_factory.mktemp("dist")
    proc = subprocess.run([sys.executable, str(ROOT / "tools" / "build_extension.py"),
                           "--blender-ext", str(BLENDER_EXT), "--output-dir", str(out)],
                          capture_output=True, text=True, cwd=ROOT)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    m = _manifest()
    return out / f"{m['id']}-{m['version']}-{_this_platform().replace('-', '_')}.zip"


@pytest.mark.parametrize("method,rays", [("backward", 1_500_000), ("forward", 3_000_000)])
def test_installed_extension_renders_like_the_tracer(extension_zip, tmp_path, method, rays):
    """Install the zip, add a preset, F12 with write_still: the Render Result matches the tracer's own
    render of the exported scene folder within statistical error, and both match L R."""
    res, _ = scenario("install_render", extension_zip, tmp_path, "analytic-mirror", method, rays, 7)
    assert res["enabled"] and res["module"].endswith(".hud_tracer")
    assert res["left_after_disable"] == []
    # Blender's Format, Output, Frame Range, Color Management, Lens and UV Maps panels show with HUD
    # Tracer as the engine, and no longer once it is disabled.
    assert all(res["panels"].values()) and not any(res["panels_after_disable"].values()), res["panels"]
    ch = read_multilayer(tmp_path / "blender.exr")
    rgb = np.stack([ch["ViewLayer.Combined.R"], ch["ViewLayer.Combined.G"], ch["ViewLayer.Combined.B"]], -1)
    y_blender = rgb @ np.array([0.2126, 0.7152, 0.0722])
    np.testing.assert_allclose(ch["ViewLayer.Y.X"], y_blender, rtol=1e-5, atol=1e-4)
    y_tracer, var, result = render(tmp_path / "scene", method, rays, seed=7)
    assert y_blender.shape == y_tracer.shape
    # Blender renders on a pool of Performance > Threads processes; for a budget in rays that is the
    # same image as the tracer's one-process render of the exported folder (seed-addressed batches), to
    # float32 rounding, and its noise pass is the standard error the tracer reports.
    assert res["figures"]["workers"] == res["threads"] and res["figures"]["rays"] == result.rays
    np.testing.assert_allclose(y_blender, y_tracer, rtol=1e-5, atol=1e-6 * y_tracer.max())
    np.testing.assert_allclose(ch["ViewLayer.Y_noise.X"], np.sqrt(var), rtol=1e-4, atol=1e-6 * np.sqrt(var).max())
    covered = (y_tracer > 425) & (y_blender > 425)
    assert covered.sum() > 100
    sem = math.sqrt(var[covered].sum()) / covered.sum()
    assert abs(y_blender[covered].mean() - 850.0) < z_bound(1) * sem + 0.01 * 850
    # The hud:* fields of the command line's image.exr are in the header of the EXR Blender wrote.
    import OpenImageIO as oiio

    inp = oiio.ImageInput.open(str(tmp_path / "blender.exr"))
    header = {a.name: a.value for a in inp.spec().extra_attribs}
    inp.close()
    assert header["hud:method"] == method and header["hud:run_id"] == res["figures"]["run_id"]
    assert int(header["hud:rays"]) == result.rays and "Y_noise" in header["hud:units"]


def test_export_round_trip(tmp_path):
    expected, _ = scenario("roundtrip", tmp_path)
    data = json.loads((tmp_path / "scene" / "scene.json").read_text())
    objs = {o["name"]: o for o in data["objects"]}
    m = np.array(objs["mirror"]["transform"]["matrix"])
    np.testing.assert_allclose(m[:3, 3], expected["mirror_location_mm"], atol=1e-4)
    assert objs["mirror"]["material"] == {"type": "mirror", "reflectance": pytest.approx([0.8, 0.7, 0.6], abs=1e-6)}
    assert objs["mirror"]["smooth_normals"] is True
    obj_text = (tmp_path / "scene" / objs["mirror"]["mesh"]).read_text()
    assert sum(line.startswith("f ") for line in obj_text.splitlines()) == 8  # modifiers applied
    np.testing.assert_allclose(np.array(objs["glass"]["transform"]["matrix"])[:3, 3], expected["glass_location_mm"],
                               atol=1e-4)
    assert objs["glass"]["material"]["ior"] == pytest.approx(1.6)
    assert objs["led"]["material"] == {"type": "absorber"}
    led = objs["led"]["emission"]
    assert led["luminance"] == pytest.approx(1234.0) and led["aim"] == {"target": "mirror", "share": pytest.approx(0.7),
                                                                         "mode": "toward"}
    assert "flux" not in led
    assert objs["floor"]["material"]["light_aim"] == {"target": "mirror", "share": pytest.approx(0.6), "mode": "toward"}
    assert "aim" not in objs["floor"]["material"]
    assert data["methods"]["backward"]["max_depth"] == 17 and data["methods"]["backward"]["next_event"] is False
    assert "exit_pupil" not in data["methods"]["backward"]
    eye = data["eye"]
    np.testing.assert_allclose(eye["position"], expected["camera_location_mm"], atol=1e-4)
    np.testing.assert_allclose(eye["gaze"], expected["camera_gaze"], atol=1e-6)
    np.testing.assert_allclose(eye["up"], expected["camera_up"], atol=1e-6)
    fixed = json.loads((tmp_path / "fixed_pupil" / "scene.json").read_text())["eye"]
    assert fixed["pupil_diameter_mm"] == pytest.approx(3.5) and eye["accommodation_distance_mm"] == pytest.approx(2000)
    assert eye["pupil_diameter_mm"] == "auto" and eye["adaptation_luminance_cd_m2"] == pytest.approx(292.0)
    assert eye["focal_length_mm"] == pytest.approx(17.0) and eye["resolution"] == [160, 80]
    fx = 2 * math.degrees(math.atan(expected["sensor"] / (2 * expected["lens"])))
    assert eye["fov_deg"][0] == pytest.approx(fx)
    assert eye["fov_deg"][1] == pytest.approx(2 * math.degrees(math.atan(math.tan(math.radians(fx / 2)) / 2)))
    env = data["environment"]
    assert env["type"] == "hdri" and env["calibration"] == {"mode": "mean", "value": pytest.approx(500.0)}
    assert env["rotation_deg"] == pytest.approx(45.0) and (tmp_path / "scene" / env["file"]).is_file()
    # The exported folder is a valid tracer scene: the mesh positions are in mm.
    from tracer.scene import load_scene

    sc = load_scene(tmp_path / "scene")
    assert sc.method_options("backward")["max_depth"] == 17 and sc.object("led").emission.luminance == 1234.0
    np.testing.assert_allclose(sc.object("mirror").vertices.mean(axis=0), expected["mirror_location_mm"], atol=1e-3)
    assert sc.object("mirror").area_mm2 == pytest.approx(200.0 * 200.0, rel=1e-6)
    assert sc.environment.mean_luminance == pytest.approx(500.0)
    assert sc.eye.pupil_diameter_mm == pytest.approx(2.61, abs=0.006)  # Watson & Yellott at 292 cd/m^2


@pytest.mark.parametrize("threads", [1, 2])
def test_cancel_stops_within_one_batch_and_writes_a_clean_result(threads):
    """Esc in a 600 s render, at the first check of test_break after the first batch was merged: the
    render stops there, with a clean partial result (every pass finite). One process has merged that
    batch alone; on a pool the batches that ended in the same wait are merged with it (at most one per
    worker: they started together) and nothing that came later."""
    res, _ = scenario("cancel", threads, "after_first_batch")
    f = res["figures"]
    assert f["partial"] is True and 1 <= f["batches"] <= threads and f["workers"] == threads
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
    res, _ = scenario("cancel", threads, "at_once")
    (message,) = res["reports"]
    assert res["figures"] == res["last_render"] == {"stopped": message[len("HUD Tracer: "):]}
    assert "before the first batch ended: nothing rendered" in message and "light" not in message
    assert res["test_break_calls"] == 1 and not res["kept_report"] and res["seconds"] < 30


def test_unregister_leaves_nothing_behind_and_the_process_exits():
    res, proc = scenario("unregister", timeout=120)
    assert "HUD_OT_add_preset" in res["before"] and res["props_before"] == [True] * 5
    assert res["after"] == [] and res["props_after"] == [False] * 5
    assert res["engines"] == []


def test_hud_render_renders_a_saved_blend(tmp_path):
    """The .blend comes from tools/preset_blend.py, the README's headless way to make one."""
    blend = tmp_path / "mirror.blend"
    made = subprocess.run([sys.executable, str(ROOT / "tools" / "preset_blend.py"), "analytic-mirror", str(blend)],
                          capture_output=True, text=True, timeout=300, cwd=tmp_path)
    assert made.returncode == 0 and blend.is_file(), made.stderr[-3000:]
    again = subprocess.run([sys.executable, str(ROOT / "tools" / "preset_blend.py"), "analytic-mirror", str(blend)],
                           capture_output=True, text=True, timeout=300, cwd=tmp_path)
    assert again.returncode == 2 and "exists" in again.stderr and len(again.stderr.strip().splitlines()) == 1
    out = tmp_path / "out"
    proc = subprocess.run([sys.executable, "-m", "hud_addon.batch", str(blend), "--out", str(out), "--rays", "600000",
                           "--method", "backward", "--seed", "2"], capture_output=True, text=True, timeout=600,
                          cwd=ROOT)
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert sorted(p.name for p in out.iterdir()) == ["falsecolour.png", "image.exr", "report.json"]  # a set
    report = json.loads((out / "report.json").read_text())
    assert report["method"] == "backward" and report["rays"] >= 600_000 and report["seed"] == 2
    assert len(report["run_id"]) == 32 and report["blend"] == str(blend)
    # The command line's report (issue 11, finding 8): rays/s, noise, log-average, the analysis.
    assert report["rays_per_second"] > 0 and report["noise"]["median_relative_standard_error_lit_pixels"] > 0
    assert report["luminance"]["log_average"] > 0 and report["brightness_theorem"]["image"]["predicted_cd_m2"] > 0
    ch = read_multilayer(out / "image.exr")
    y = ch["ViewLayer.Y.X"]
    assert np.all(np.isfinite(y)) and abs(y.max() - 850.0) < 0.02 * 850
    from tracer.core.imageio import read_image
    from tracer.products.falsecolour import false_colour

    expected, _ = false_colour(y.astype(np.float64))
    got = np.rint(read_image(out / "falsecolour.png", linear=True) * 255).astype(np.uint8)
    assert got.shape == expected.shape and np.abs(got.astype(int) - expected).max() <= 1


def test_hud_render_names_the_world_image_that_lost_its_pixels(tmp_path):
    """Issue 11, finding 4: a .blend whose HDRI is a generated image that was never saved or packed:
    hud-render exits 2 with one line that names the World and the image (not a temporary scene.json),
    and says why its pixels are gone; nothing is written."""
    blend = tmp_path / "generated.blend"
    scenario("save_generated_hdri", blend)
    out = tmp_path / "out"
    proc = subprocess.run([sys.executable, "-m", "hud_addon.batch", str(blend), "--out", str(out), "--rays",
                           "100000"], capture_output=True, text=True, timeout=600, cwd=ROOT)
    assert proc.returncode == 2 and "Traceback" not in proc.stderr, proc.stderr
    errors = [line for line in proc.stderr.splitlines() if line.startswith("error: ")]
    assert len(errors) == 1, proc.stderr
    line = errors[0]
    assert "World 'World'" in line and "HDRI image 'sky'" in line and "generated image" in line and "Pack" in line
    assert "scene.json" not in line and "hud-blender-" not in line
    assert not out.exists() or list(out.iterdir()) == []


@pytest.mark.parametrize("case", ["--out is a file", "--seconds nan", "--method backwards"])
def test_hud_render_refuses_bad_arguments_before_blender_starts(tmp_path, case):
    """hud-render checks its arguments and locks its output folder first (issue 9): one line, exit 2,
    and the .blend is not even opened (it does not exist here: the refusal comes before). A misspelt
    method was Blender's enum traceback."""
    out = tmp_path / "out"
    args = ["--rays", "1000"]
    if case == "--out is a file":
        out.write_text("x")
    else:
        args = case.split()
    blend = tmp_path / "scene.blend"
    blend.write_bytes(b"BLENDER")
    proc = subprocess.run([sys.executable, "-m", "hud_addon.batch", str(blend), "--out", str(out), *args],
                          capture_output=True, text=True, timeout=120, cwd=ROOT)
    assert proc.returncode == 2 and "Traceback" not in proc.stderr, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: ") and (case.split()[0] in lines[0] or str(out) in lines[0])


def test_world_and_slide_errors_name_the_field_at_fault(tmp_path):
    """A uniform World's luminance was blamed on a panorama it does not use, a calibration value named no
    field, and a slide with values above 1 got the hint that a generated image loses its pixels, which
    these (in memory, filled) had not."""
    res, _ = scenario("world_and_slide_messages", tmp_path)
    assert "World 'World': HUD Environment > Luminance" in res["uniform luminance"], res
    assert "old sky" not in res["uniform luminance"]
    assert "World 'World': HUD Environment > Value" in res["calibration value"], res
    assert "'hot slide'" not in res["slide above 1"] or "regenerates" not in res["slide above 1"], res
    assert "Slide" in res["slide above 1"], res


def test_option_and_reference_errors_are_told_in_the_panels_words(tmp_path):
    """They named a bare "Object", scene.json keys (alpha, "eye", an OBJ's vt lines), no object where the
    object exists but is not exported, the field angle without its value, and command-line flags."""
    res, _ = scenario("option_messages", tmp_path)
    expect = {"exit pupil unset": ["Backward options > Exit pupil > Object", "choose an object"],
              "exit pupil at the camera": ["Exit pupil > Object", "is the camera"],
              "aim at an object without a role": ["'panel'", "'window' is an object the render does not see",
                                                  "HUD Optical Role"],
              "photon radius reduction 0": ["Photon options > Radius reduction", "must be > 0"],
              "lens too wide": ["Lens and Sensor", "got 17"],
              "eyebox without an LCD": ["Eyebox Sweep", "set Display field to Given"],
              "LCD without a UV map": ["'lcd'", "add a UV map"]}
    for case, words in expect.items():
        message = res[case] or ""
        assert all(w in message for w in words), (case, message)
        assert "--field" not in message and "vt lines" not in message and '"eye"' not in message, (case, message)


def test_output_settings_the_engine_cannot_honour_are_refused_in_one_line(tmp_path):
    """A Render Region made the passes' sizes disagree with the frame (a TypeError, then Blender crashed),
    Stereoscopy's second eye and a pixel aspect were rendered as if not set, and more processes than the
    memory holds ended in a WorkersError traceback and a crash. Now each is refused before the first ray,
    naming Blender's panel and field, and nothing is written."""
    res, proc = scenario("unsupported_output", tmp_path)
    assert "Traceback" not in proc.stdout + proc.stderr
    where = {"region, cropped": "Render Region", "region": "Render Region", "stereoscopy": "Stereoscopy",
             "pixel aspect": "Aspect X / Y", "threads": "Performance > Threads"}
    for name, words in where.items():
        case = res[name]
        assert case["error"] and words in case["error"] and words in (case["raised"] or ""), (name, case)
        assert case["files"] == [], (name, case)
    assert "at most" in res["threads"]["error"]


def test_hud_render_of_a_file_blender_cannot_render_exits_2_in_one_line(tmp_path):
    """A file that is not a .blend was a traceback from open_mainfile, and Blender's own refusals (no
    camera) exit 1 as "error: Error: ..."; both are the input's fault: exit 2, our one line naming the file."""
    not_blend = tmp_path / "notes.blend"
    not_blend.write_text("not a blend file")
    empty = tmp_path / "empty.blend"
    made = subprocess.run([sys.executable, "-c", "import bpy; bpy.ops.wm.read_factory_settings(use_empty=True); "
                           f"bpy.ops.wm.save_as_mainfile(filepath={str(empty)!r})"], capture_output=True, text=True,
                          timeout=300, cwd=tmp_path)
    assert made.returncode == 0 and empty.is_file(), made.stderr[-2000:]
    for blend, words in ((not_blend, "not a readable .blend file"), (empty, "no camera")):
        out = tmp_path / f"out-{blend.stem}"
        proc = subprocess.run([sys.executable, "-m", "hud_addon.batch", str(blend), "--out", str(out), "--rays",
                               "100000"], capture_output=True, text=True, timeout=300, cwd=ROOT)
        ours = [line for line in proc.stderr.splitlines() if line.startswith("error: ")]
        assert proc.returncode == 2 and "Traceback" not in proc.stderr, proc.stderr[-3000:]
        assert len(ours) == 1 and blend.name in ours[0] and words in ours[0], proc.stderr
        assert not out.exists() or not any(out.iterdir())


def test_a_render_in_blender_uses_every_core_and_shows_its_progress():
    """Issue 11, finding 7: with Blender's default threads (auto-detect) a render runs on one process per
    core, and the Render Result is updated while it runs (at most once a second, after merged batches)."""
    res, _ = scenario("progressive", 6)
    assert res["threads_mode"] == "AUTO" and res["workers"] == res["cpus"]
    assert res["batches"] > 3
    assert 2 <= res["updates"] <= res["seconds"] + 1


def test_show_light_paths_draws_paths_that_end_at_the_eye():
    """And a scene it cannot trace (no active camera, an open glass plate) is reported in one line in
    Blender's terms, as Export reports it; both were tracebacks naming a temporary scene.json."""
    res, proc = scenario("light_paths")
    verts = np.array(res["vertices"])
    assert res["edges"] > 0 and len(verts) > 0
    # Every drawn path ends in the pupil: the closest vertices sit at the eye (4 mm pupil).
    dist_mm = np.linalg.norm(verts - np.array(res["eye"]), axis=1) * res["mm_per_unit"]
    assert np.sort(dist_mm)[:10].max() < 2.001
    errors = res["errors"]
    assert "camera" in errors["no camera"] and "'glass plate'" in errors["open glass"], errors
    for message in errors.values():
        assert "Show Light Paths: " in message and "Traceback" not in message and "scene.json" not in message
    assert "Traceback" not in proc.stdout + proc.stderr


def test_render_reports_no_light_to_the_user():
    res, _ = scenario("no_light")
    assert res["figures"]["efficiency"] == 0
    assert any("the scene has no light source" in r for r in res["reports"])  # its one emitter is at 0 cd/m^2


def test_an_aim_that_misses_light_is_reported_when_the_render_starts():
    """The panel's aim target shrunk to half its size covers about a quarter of the light that reaches
    the eye: the engine reports it before the first ray (first of its reports), and again after the
    render from the report's own analysis."""
    res, _ = scenario("misaimed")
    early = [i for i, r in enumerate(res["reports"])
             if r.startswith("HUD Tracer: before the first ray: the aim of panel toward pupil_image covers")]
    late = [r for r in res["reports"] if r.startswith("HUD Tracer: the aim of panel toward pupil_image covers")]
    assert early == [0] and len(late) == 1, res["reports"]


def _vertex_set(v) -> np.ndarray:
    """Distinct vertex positions (n, 3) mm, sorted: meshes exported with UVs repeat corner vertices."""
    return np.unique(np.round(np.asarray(v, dtype=np.float64), 3), axis=0)


def test_objects_whose_names_clean_alike_export_their_own_geometry(tmp_path):
    """"m.a", "m_a" and "M.A" all clean to m_a (case aside): each gets its own mesh file, unique even
    case-insensitively, and loads with its own vertices; two LCDs "s.1" and "s_1" keep their own slides."""
    expected, _ = scenario("name_collision", tmp_path)
    data = json.loads((tmp_path / "scene" / "scene.json").read_text())
    meshes = {o["name"]: o["mesh"] for o in data["objects"]}
    assert sorted(meshes) == sorted(expected)
    assert len({m.casefold() for m in meshes.values()}) == len(meshes), meshes
    slides = {o["name"]: o["material"]["image"] for o in data["objects"] if o["material"]["type"] == "lcd"}
    assert len({s.casefold() for s in slides.values()}) == 2, slides
    assert meshes["m_a"] == "meshes/m_a.obj"  # a name that is already clean keeps it
    from tracer.scene import load_scene

    sc = load_scene(tmp_path / "scene")
    for name, e in expected.items():
        np.testing.assert_allclose(_vertex_set(sc.object(name).vertices), _vertex_set(e["vertices_mm"]), atol=2e-3,
                                   err_msg=name)
        if "slide" in e:
            assert sc.object(name).material.params["image"].mean() == pytest.approx(e["slide"], abs=1e-6), name


def test_a_failed_export_leaves_the_earlier_export_as_it_was(tmp_path):
    """Export into F, then fail eight ways (HDRI file missing, LCD without slide, aim object not
    chosen, no camera; a write error while staging, the staged folder failing to take F's place, the
    tracer's validation rejecting the staged folder): each says what is wrong and where, F is byte for
    byte the earlier export, and no hidden staging or backup folder is left beside it. A folder
    holding other files is not replaced. Once fixed, the export replaces F as a whole (the dropped
    object's mesh is gone)."""
    res, _ = scenario("failed_export", tmp_path)
    good, attempts = res["good"], res["attempts"]
    assert {"scene.json", "meshes/mirror.obj", "meshes/extra.obj"} <= set(good)
    assert any(k.startswith("textures/") for k in good) and len(good) >= 7
    expect = {"hdri_missing": ["World", "HDRI image 'sky'", res["missing"], "file not found"],
              "hdri_missing_operator": ["HUD export failed", "HDRI image 'sky'", res["missing"]],
              "lcd_no_image": ["'lcd panel'", "Slide", "choose an image"],
              "aim_unset": ["'led'", "aim"],
              "no_camera": ["camera"],
              "ortho_camera": ["camera 'Camera'", "Ortho", "Perspective"],
              "shifted_camera": ["camera 'Camera'", "Shift", "0.1"],
              "role_on_text": ["'label'", "Font", "not a mesh"],
              "disk_full": ["No space left on device"],
              "rename_fails": ["Permission denied"],
              "tracer_rejects": ["HUD export failed", "extra", "closed"]}
    for case, words in expect.items():
        a = attempts[case]
        assert a["message"] is not None, case
        for w in words:
            assert w in a["message"], (case, w, a["message"])
        assert a["hashes"] == good, case
        assert a["hidden"] == [], (case, a["hidden"])
    foreign = attempts["foreign_folder"]
    assert foreign["message"] is not None and "notes.txt" in foreign["message"]
    assert list(foreign["hashes"]) == ["notes.txt"] and foreign["hidden"] == []
    fixed = attempts["after_fix"]
    assert fixed["message"] is None and fixed["hidden"] == []
    assert "meshes/extra.obj" not in fixed["hashes"]
    assert fixed["hashes"]["meshes/mirror.obj"] != good["meshes/mirror.obj"]
    from tracer.scene import load_scene

    assert load_scene(tmp_path / "exports" / "F").object("mirror").vertices.shape[0] == 4
    relative = attempts["relative_unsaved"]  # "//" of a .blend not saved: refused, nothing written
    assert "not saved" in (relative["message"] or "") and not relative["written"], relative


def test_export_follows_render_visibility(tmp_path):
    """Issue 11, finding 3: hidden in the viewport only -> exported; disabled in renders, in a
    collection disabled in renders, or in a collection excluded from the view layer -> not."""
    scenario("visibility", tmp_path)
    data = json.loads((tmp_path / "scene" / "scene.json").read_text())
    assert sorted(o["name"] for o in data["objects"]) == ["shown", "viewport_hidden"]


def test_extension_zip_ships_only_what_the_add_on_uses(extension_zip):
    """Issue 11, finding 10: one zip per platform of the manifest, named by Blender's tool; each holds the
    license, the manifest (its generated table naming its platform and wheels), tracer/, hud_addon/,
    presets/, exactly one wheel of each project the manifest lists (embreex, trimesh, matplotlib and what it
    needs), each for its platform or pure Python; nothing the add-on does not use (tests, benchmarks, docs,
    README, locks, the Dask driver, Makefile, tools, .ci, .git, caches)."""
    import tomllib
    import zipfile

    from wheel_tags import fits, macos_minimum, project

    m = _manifest()
    macos = macos_minimum((ROOT / "blender_manifest.toml").read_text())
    names = {p: f"{m['id']}-{m['version']}-{p.replace('-', '_')}.zip" for p in m["platforms"]}
    dist = extension_zip.parent
    assert sorted(z.name for z in dist.iterdir()) == sorted(names.values()), "the zips made by the build"
    # Every file of the add-on's packages, as the build sees them on disk (untracked ones too).
    shipped = {p.relative_to(ROOT).as_posix() for d in ("tracer", "hud_addon", "presets")
               for p in (ROOT / d).rglob("*") if p.is_file() and "__pycache__" not in p.parts}
    shipped -= {"tracer/runtime/distributed.py"}
    for platform, name in names.items():
        z = zipfile.ZipFile(dist / name)
        entries = [n for n in z.namelist() if not n.endswith("/")]
        top = {n.split("/")[0] for n in entries}
        wanted = {"LICENSE", "blender_manifest.toml", "__init__.py", "tracer", "hud_addon", "presets", "wheels"}
        assert top == wanted, f"{name}: unused {sorted(top - wanted)}, missing {sorted(wanted - top)}"
        code = {n for n in entries if n.startswith(("tracer/", "hud_addon/", "presets/"))}
        assert code == shipped, f"{name}: unused {sorted(code - shipped)}, missing {sorted(shipped - code)}"
        for unused in ("README.md", "Makefile", "requirements.lock", "requirements-bench.lock",
                       "tracer/runtime/distributed.py", ".git", ".gitignore"):
            assert unused not in entries, (name, unused)
        assert not any(n.startswith(("tests/", "benchmarks/", "docs/", "tools/", ".ci/", ".venv")) or n.endswith(".pyc")
                       for n in entries), name
        wheels = sorted(n for n in entries if n.startswith("wheels/"))
        # One wheel of every project the manifest lists, each for this platform (or pure Python).
        assert sorted(project(w) for w in wheels) == sorted({project(w) for w in m["wheels"]}), (name, wheels)
        assert all(fits(platform, w, macos) for w in wheels), (name, wheels)
        generated = tomllib.loads(z.read("blender_manifest.toml").decode())["build"]["generated"]
        assert generated["platforms"] == [platform], (name, generated)
        assert sorted(w.removeprefix("./") for w in generated["wheels"]) == wheels, (name, generated)
        assert z.read("LICENSE") == (ROOT / "LICENSE").read_bytes(), name


def test_every_property_has_a_tooltip():
    """Issue 11, finding 9: every property of the add-on's property groups has a description."""
    res, _ = scenario("tooltips")
    assert len(res["groups"]) >= 3, res["groups"]
    assert res["missing"] == [], res["missing"]


def test_an_animated_camera_renders_each_frame_from_its_own_eye(tmp_path):
    """Issue 11, finding 2: with the camera keyframed at x = -50, 0, +50 mm, Blender's animation render
    gives three different frames, each the tracer's render from that frame's eye: the mirror image
    of the panel moves across the retina, and the export operator writes that frame's eye."""
    res, _ = scenario("animation", tmp_path)
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


def test_collection_instances_export_as_objects_and_hide_render_is_honoured(tmp_path):
    """Issue 11, finding 2: each instance of a collection becomes an object of its own at the instance's
    place, even though the collection itself is excluded; an instancer disabled in renders is not."""
    res, _ = scenario("instances", tmp_path)
    from tracer.scene import load_scene

    data = json.loads((tmp_path / "scene" / "scene.json").read_text())
    names = sorted(o["name"] for o in data["objects"])
    assert names == ["mirror @ inst_a 1", "mirror @ inst_b 1"]
    assert len({o["mesh"] for o in data["objects"]}) == 1  # instances share one mesh file
    sc = load_scene(tmp_path / "scene")
    for name, inst in (("mirror @ inst_a 1", "inst_a"), ("mirror @ inst_b 1", "inst_b")):
        np.testing.assert_allclose(sc.object(name).vertices.mean(axis=0), res["places"][inst], atol=1e-6)
        assert sc.object(name).area_mm2 == pytest.approx(400.0)


def test_add_hud_preset_builds_in_millimetres_and_replaces_the_previous_one():
    """Issue 11, finding 9: on Blender's startup scene the preset replaces the startup cube and is built
    in a collection in millimetres (1 unit = 1 mm: hud-direct's LED dies are 0.2 units wide); pressed
    again it replaces itself (no "Eye.001"); with Replace off it adds beside. Lengths show in the
    scene's unit system and are stored in mm."""
    res, _ = scenario("preset_twice")
    assert "Cube" in res["startup"] and "Cube" not in res["first"]
    assert res["second"] == res["first"] and not any(n.endswith(".001") for n in res["second"])
    assert res["units"]["length_unit"] == "MILLIMETERS" and res["units"]["scale_length"] == pytest.approx(0.001)
    assert res["led_area"] == pytest.approx(0.2 * 0.2, rel=1e-3)  # a 0.2 x 0.2 mm die, in mm^2
    assert res["shown_mm"] == {"pupil": pytest.approx(4.0), "stored": pytest.approx(4.0)}
    assert [c for c in res["collections"] if c.startswith("HUD")] == ["HUD analytic-mirror", "HUD hud-direct"]
    assert res["shown_m"] == pytest.approx(0.004) and res["stored_after"] == pytest.approx(3.0)


def test_lcd_slide_encoding_follows_the_image_color_space(tmp_path):
    """Issue 11, finding 6: an 8-bit slide in sRGB exports as sRGB-encoded, in Non-Color as linear,
    whatever the old Encoding property says; a colour space the tracer cannot read a transmittance from
    is refused, naming the image."""
    res, _ = scenario("colour_space", tmp_path)
    assert res["is_float"] is False
    assert res["spaces"]["sRGB"] == "srgb" and res["spaces"]["Non-Color"] == "linear"
    if "ACEScg" in res["spaces"]:
        msg = res["spaces"]["ACEScg"]
        assert msg.startswith("error:") and res["image"] in msg and "ACEScg" in msg


@pytest.fixture(scope="module")
def readouts_run(tmp_path_factory):
    """hud-direct rendered in Blender into frame.exr, then the HUD Readouts panel drawn, Show False
    Colour and an Eyebox Sweep (+-90 x +-30 mm, 10 mm): the scenario runs once for the three tests."""
    out = tmp_path_factory.mktemp("readouts")
    res, _ = scenario("readouts", out)
    return res, out


def test_readouts_panel_shows_the_reports_figures_on_hud_direct(readouts_run):
    """Issue 11, Build item 4: after a render of hud-direct the HUD Readouts panel lists the report's
    figures (symbols, background, contrast, ghost), every row drawn; the report is also written beside
    the rendered file."""
    res, out = readouts_run
    rows = dict(res["rows"])
    report = json.loads((out / "frame.exr.report.json").read_text())
    assert rows["Symbols"] == f"{report['hud']['symbol_cd_m2']:,.4g} cd/m²"
    assert "Ghost" in rows and "Contrast (Ls + Lb) / Lb" in rows
    assert res["panel_labels"] >= 2 * len(res["rows"])  # the panel drew every row (label and value)
    assert report["image_file"].endswith("frame.exr")


def test_false_colour_view_of_hud_direct_in_blender_and_beside_the_render(readouts_run):
    """Show False Colour makes the image "HUD False Colour", the tracer's false-colour view of the
    render's Y; a render written to a file gets it beside it."""
    res, out = readouts_run
    assert res["false_colour"]["size"] == res["false_colour"]["expected_size"]
    from tracer.core.imageio import read_image
    from tracer.products.falsecolour import false_colour

    y = read_multilayer(out / "frame.exr")["ViewLayer.Y.X"].astype(np.float64)
    got = np.rint(read_image(out / "frame.exr.falsecolour.png", linear=True) * 255).astype(np.uint8)
    assert np.abs(got.astype(int) - false_colour(y)[0]).max() <= 1


def test_eyebox_sweep_operator_finds_the_command_lines_eyebox_on_hud_direct(readouts_run):
    """The Eyebox Sweep operator writes eyebox.csv, .png and .json and finds the eyebox that
    `hud-trace eyebox hud-direct --half 90 30 --step 10` finds (README: 120 x 40 mm between grid points)."""
    res, out = readouts_run
    assert sorted(p.name for p in (out / "eyebox").iterdir()) == ["eyebox.csv", "eyebox.json", "eyebox.png"]
    f = json.loads((out / "eyebox" / "eyebox.json").read_text())["figures"]
    assert f["grid_width_mm"] == pytest.approx(120.0) and f["grid_height_mm"] == pytest.approx(40.0)
    assert res["eyebox_image"] is True


def test_a_sun_light_exports_as_the_environments_sun(tmp_path):
    """A Sun light turned 60 deg about x shines along its -Z (toward +y and down): the exported sun stands
    30 deg high toward -y (its +Z), with the light's Angle, Color and HUD Sun illuminance; keyframed to
    turn 90 deg about z, frame 2's sun stands toward +x. The folder loads in the tracer, and its floor
    (albedo 0.5) renders rho E sin(30 deg) / pi. With an HDRI World calibrated to its minimum both
    export together. Two rendered Sun lights are refused naming both (one disabled in renders is not
    counted), an Angle of 0 naming the light, a black Color (the tracer's refusal, in an F12 render)
    naming the light and its Color; the HUD Sun panel shows with the engine and gives the disk's
    luminance."""
    res, _ = scenario("sun", tmp_path)
    m = res["messages"]
    assert m["frame1"] is None and m["frame2"] is None and m["hdri_min"] is None and m["second_hidden"] is None, m
    s60, c60 = math.sin(math.radians(60.0)), math.cos(math.radians(60.0))
    env1 = json.loads((tmp_path / "frame1" / "scene.json").read_text())["environment"]
    assert env1["type"] == "none" and set(env1["sun"]) == {"direction", "illuminance_lux", "angular_diameter_deg",
                                                             "color"}
    sun1 = env1["sun"]
    np.testing.assert_allclose(sun1["direction"], [0.0, -s60, c60], atol=1e-6)
    np.testing.assert_allclose(sun1["direction"], res["directions"]["frame1"], atol=1e-6)
    assert sun1["illuminance_lux"] == pytest.approx(80_000.0) and sun1["angular_diameter_deg"] == pytest.approx(0.53)
    np.testing.assert_allclose(sun1["color"], [1.0, 0.9, 0.8], atol=1e-6)
    sun2 = json.loads((tmp_path / "frame2" / "scene.json").read_text())["environment"]["sun"]
    np.testing.assert_allclose(sun2["direction"], [s60, 0.0, c60], atol=1e-6)
    np.testing.assert_allclose(sun2["direction"], res["directions"]["frame2"], atol=1e-6)
    assert res["spec_direct"]["direction"] == pytest.approx(sun1["direction"], abs=1e-6)
    from tracer.scene import load_scene
    from tracer.sources.environment import HdriEnvironment
    from tracer.sources.sun import EnvironmentWithSun

    sc = load_scene(tmp_path / "frame1")
    assert isinstance(sc.environment, EnvironmentWithSun)
    np.testing.assert_allclose(sc.environment.sun.direction, [0.0, -s60, c60], atol=1e-6)
    y, var, rendered = render(tmp_path / "frame1", "backward", 100_000)
    expected = 0.5 * 80_000.0 * math.sin(math.radians(30.0)) / math.pi
    bound = t_bound(y.size, film_dof(rendered.film))
    assert np.all(np.abs(y - expected) < bound * np.sqrt(var)), (y.mean(), expected)
    hdri = json.loads((tmp_path / "hdri_min" / "scene.json").read_text())["environment"]
    assert hdri["type"] == "hdri" and hdri["calibration"] == {"mode": "min", "value": pytest.approx(5.0)}
    assert hdri["sun"]["illuminance_lux"] == pytest.approx(80_000.0)
    env = load_scene(tmp_path / "hdri_min").environment
    assert isinstance(env.base, HdriEnvironment) and env.base.min_luminance == pytest.approx(5.0)
    assert env.sun.luminance_cd_m2 == pytest.approx(80_000.0 / (math.pi * math.sin(math.radians(0.265)) ** 2),
                                                    rel=1e-5)
    for words in ("'Sun'", "'Sun.second'", "2 Sun lights", "disable"):
        assert words in m["two_suns"], m["two_suns"]
    assert "'Sun'" in m["angle_0"] and "Angle is 0" in m["angle_0"], m["angle_0"]
    assert m["black_f12"].startswith("light 'Sun': Color: ") and "black" in m["black_f12"], m["black_f12"]
    assert res["polls"] == {"sun": True, "other engine": False, "no light": False}
    assert f"Disk luminance {env.sun.luminance_cd_m2:.3g} cd/m²" in res["labels"]


def test_the_hybrid_method_gives_one_render_pass_per_channel(tmp_path):
    """Issue 12, item 1 (and issue 11, Build item 3): rendered with the hybrid method in Blender, the
    Render Result has a HUD pass and an Environment pass, and Combined is their sum."""
    res, _ = scenario("hybrid_passes", tmp_path)
    assert res["channels"] == {"hud": "backward", "environment": "backward"}
    ch = read_multilayer(tmp_path / "hybrid.exr")
    for c in "RGB":
        hud, env = ch[f"ViewLayer.HUD.{c}"], ch[f"ViewLayer.Environment.{c}"]
        np.testing.assert_allclose(ch[f"ViewLayer.Combined.{c}"], hud + env, rtol=1e-5, atol=1e-3)
    assert ch["ViewLayer.Environment.G"].max() > 500 and ch["ViewLayer.HUD.G"].max() > 5000


def test_a_study_preset_renders_in_blender_with_its_channels_and_its_eye(tmp_path):
    """Issue 12, Done when: hud-direct-env added with Add HUD Preset renders with the hybrid method (the
    preset has a lit panorama), the pupil following the image and the mean adaptation, one pass per
    channel in the Render Result."""
    res, _ = scenario("study_preset", tmp_path, "hud-direct-env")
    assert res["method"] == "hybrid" and res["pupil"] == "IMAGE" and res["adaptation_mode"] == "mean"
    assert res["channels"] == {"hud": "backward", "environment": "backward"}
    assert res["pupil_report"]["pupil_diameter_mm"] < 3.0  # a day: a small pupil
    ch = read_multilayer(tmp_path / "study.exr")
    np.testing.assert_allclose(ch["ViewLayer.Combined.G"], ch["ViewLayer.HUD.G"] + ch["ViewLayer.Environment.G"],
                               rtol=1e-5, atol=1e-2)


def test_polarisation_in_blender_eye_analyser_mode_and_polarising_materials(tmp_path):
    """The polarisation of scene.json in Blender: the eye's analyser (HUD Eye > Analyser, from
    tracer.scene.ANALYSER) and the scene's Polarisation mode (HUD Tracer render settings) export as
    eye.analyser and "polarisation"; the polarising materials come from their schemas by themselves (a
    retarder role, the LCD's output polariser group, a coating given for s and p light, a metal mirror,
    polarised emission): drawn, exported, loaded by the tracer and built back by Add HUD Preset. With
    Polarisation Off the export is refused in Blender's terms."""
    res, _ = scenario("polarisation", tmp_path)
    from tracer.scene import ANALYSER, POLARISATION_MODES, load_scene

    # Panels: the analyser's toggle and fields, the mode, every new material field.
    assert res["drawn"]["eye"][-4:] == ["analyser_use", "analyser_axis_deg_shown", "analyser_transmittance_along",
                                        "analyser_transmittance_across"]
    assert "polarisation" in res["drawn"]["render"]
    assert {"polariser_use", "polariser_axis_deg_shown"} <= set(res["drawn"]["lcd"])
    assert {"transmittance", "axis_deg_shown", "retardance_deg_shown"} <= set(res["drawn"]["film"])
    assert {"by", "reflectance_s", "transmittance_p"} <= set(res["drawn"]["splitter"])
    assert "reflectance" not in res["drawn"]["splitter"]  # the alternative not chosen is hidden
    assert {"metal_use", "metal_complex_ior"} <= set(res["drawn"]["metal"])
    assert [k for k, _ in res["items"]] == list(POLARISATION_MODES) and all(len(d) > 40 for _, d in res["items"])

    data = json.loads((tmp_path / "pol" / "scene.json").read_text())
    assert data["polarisation"] == "auto"
    assert data["eye"]["analyser"] == {"axis_deg": pytest.approx(90.0), "transmittance_along": pytest.approx(0.9),
                                       "transmittance_across": pytest.approx(0.01)}
    assert set(data["eye"]["analyser"]) == {f.name for f in ANALYSER.fields}
    objs = {o["name"]: o for o in data["objects"]}
    assert objs[res["lcd"]]["material"]["polariser"] == {"axis_deg": pytest.approx(45.0)}
    assert objs["film"]["material"] == {"type": "retarder", "transmittance": pytest.approx([0.95] * 3),
                                        "axis_deg": pytest.approx(22.5), "retardance_deg": pytest.approx(90.0)}
    splitter = objs["splitter"]["material"]
    assert set(splitter) == {"type", "reflectance_s", "reflectance_p", "transmittance_s", "transmittance_p"}
    assert objs["metal"]["material"]["metal"] == {"complex_ior": pytest.approx([1.2, 7.0])}
    polarised = [o["emission"]["polarisation"] for o in data["objects"] if "polarisation" in o.get("emission", {})]
    assert polarised == [{"axis_deg": pytest.approx(30.0), "degree": pytest.approx(0.5)}]
    sc = load_scene(tmp_path / "pol")
    assert sc.polarisation == "auto" and sc.eye.analyser["transmittance_along"] == pytest.approx(0.9)
    assert sc.object("film").material.type == "retarder"
    assert sc.object(res["lcd"]).material.params["polariser"]["axis_deg"] == pytest.approx(45.0)

    # Off: the export operator refuses (and leaves no folder); an F12 render says it in Blender's terms.
    assert res["refused"] is not None and not (tmp_path / "off").exists()
    analyser_msg, film_msg = res["in_blender_terms"]
    for msg in (res["refused"], analyser_msg):
        assert "camera 'Eye'" in msg and "Analyser" in msg and "Polarisation to Auto" in msg and "scene.json" not in msg
    assert film_msg.startswith("object 'film': HUD Optical Role") and "Polarisation to Auto" in film_msg

    # Add HUD Preset's builder: the exported folder back into Blender.
    built = res["built"]
    assert built["polarisation"] == "auto"
    assert built["analyser"] == [True, pytest.approx(90.0), pytest.approx(0.9), pytest.approx(0.01)]
    assert built["lcd"] == [True, pytest.approx(45.0)]
    assert built["film"] == ["retarder", pytest.approx(22.5), pytest.approx(90.0)]
    assert built["splitter"] == ["reflectance_s", pytest.approx([0.1] * 3)]
    assert built["metal"] == [True, pytest.approx([1.2, 7.0])]
    sunglasses = res["sunglasses"]
    if sunglasses is not None:  # the tracer's preset of a HUD seen through polarised sunglasses
        assert sunglasses["analyser"] is not None and sunglasses["built"]["use"] is True
        for f in ANALYSER.fields:
            expected = sunglasses["analyser"].get(f.name, f.default)
            assert sunglasses["built"][f.name] == pytest.approx(expected, abs=1e-6), f.name
        assert sunglasses["polarisation"] == sunglasses["raw_polarisation"]
