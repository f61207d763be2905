"""Exporting a Blender scene to a scene folder (hud_addon/export.py): the round trip into the tracer's
scene format, errors naming the World's or slide's field at fault, objects whose names clean alike, a failed
export leaving the earlier one as it was, render visibility and collection instances, the slides' colour
spaces, and a Sun light as the environment's sun.

Each scenario (a ``scenario_*`` function: the scene set up, rendered or exported inside the bpy module)
sits before the tests that assert on its result, and runs in a process of its own through
tests/addon/blender_runner.py (tests.support.addon.in_blender)."""

from __future__ import annotations

import hashlib
import json
import math
import os
import sys
import tempfile
from pathlib import Path

import numpy as np
import pytest

from tests.support.addon import in_blender, needs_bpy
from tests.support.render import render
from tests.support.stats import film_dof, t_bound

pytestmark = [needs_bpy, pytest.mark.slow]


def scenario_roundtrip(out):
    import bpy

    from tests.support.blender import disable, enable_from_source

    module = enable_from_source(bpy, Path(tempfile.mkdtemp()))
    scene = bpy.context.scene
    scene.unit_settings.scale_length = 1.0
    bpy.ops.mesh.primitive_plane_add(size=0.2, location=(0.1, 0.2, 0.3), rotation=(0.5, 0.0, 0.25))
    mirror = bpy.context.object
    mirror.name = "mirror"
    mirror.hud.role, mirror.hud.reflectance, mirror.hud.smooth_normals = "mirror", (0.8, 0.7, 0.6), True
    subdiv = mirror.modifiers.new("subdivide", "SUBSURF")  # exported evaluated: 2 triangles become 8
    subdiv.subdivision_type, subdiv.levels = "SIMPLE", 1
    bpy.ops.mesh.primitive_cube_add(size=0.1, location=(0.0, 0.5, 0.0))
    glass = bpy.context.object
    glass.name = "glass"
    glass.scale = (1.0, 0.05, 1.0)
    glass.hud.role, glass.hud.ior = "dielectric", 1.6
    bpy.ops.mesh.primitive_plane_add(size=0.01, location=(0.0, 0.8, 0.0))
    led = bpy.context.object
    led.name = "led"
    led.hud.role, led.hud.emits, led.hud.emission_by, led.hud.emission_luminance = "absorber", True, "luminance", 1234.0
    h = led.hud
    h.emission_aim, h.emission_aim_object, h.emission_aim_share, h.emission_aim_mode = "OBJECT", mirror, 0.7, "toward"
    bpy.ops.mesh.primitive_plane_add(size=0.1, location=(0.3, 0.5, 0.0))
    floor = bpy.context.object
    floor.name = "floor"
    floor.hud.role, floor.hud.reflectance = "lambertian", (0.5, 0.5, 0.5)
    floor.hud.light_aim, floor.hud.light_aim_object, floor.hud.light_aim_share = "OBJECT", mirror, 0.6
    scene.hud.backward_max_depth, scene.hud.backward_next_event = 17, False  # method options are exported
    cam = scene.camera
    cam.location = (0.0, -1.0, 0.1)
    cam.data.hud.pupil_diameter_mm, cam.data.hud.accommodation_distance_mm = 3.5, 2000.0
    cam.data.hud.focal_length_mm = 17.0
    scene.hud.seed = 4  # not exported: a render setting
    bpy.ops.hud.export_scene(directory=str(Path(out) / "fixed_pupil"))
    cam.data.hud.pupil, cam.data.hud.adaptation_luminance, cam.data.hud.observer_age = "AUTO", 292.0, 30.0
    scene.render.resolution_x, scene.render.resolution_y, scene.render.resolution_percentage = 320, 160, 50
    img = bpy.data.images.new("sky", 16, 8, float_buffer=True)
    img.pixels.foreach_set([0.5] * (16 * 8 * 4))
    img.filepath_raw = str(Path(out) / "sky.exr")
    img.file_format = "OPEN_EXR"
    img.save()
    world = scene.world or bpy.data.worlds.new("World")
    scene.world = world
    world.hud.kind, world.hud.image, world.hud.calibration, world.hud.value = "hdri", img, "mean", 500.0
    world.hud.rotation_deg = 45.0
    bpy.ops.hud.export_scene(directory=str(Path(out) / "scene"))
    expected = {
        "mirror_location_mm": [100.0, 200.0, 300.0], "glass_location_mm": [0.0, 500.0, 0.0],
        "camera_location_mm": [0.0, -1000.0, 100.0],
        "camera_up": list(cam.matrix_world.to_3x3().col[1]), "camera_gaze": list(-cam.matrix_world.to_3x3().col[2]),
        "lens": cam.data.lens, "sensor": cam.data.sensor_width,
    }
    disable(module)
    return expected


def test_export_round_trip(tmp_path):
    expected, _ = in_blender(scenario_roundtrip, tmp_path)
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


def scenario_world_and_slide_messages(out):
    """Exports that fail on the World's fields and on a slide's pixels: what each says."""
    import bpy

    from tests.support.blender import disable, enable_from_source

    module = enable_from_source(bpy, Path(tempfile.mkdtemp()))
    bpy.ops.hud.add_preset(preset="hud-direct")
    scene = bpy.context.scene
    world = scene.world or bpy.data.worlds.new("World")
    scene.world = world
    sky = bpy.data.images.new("old sky", 16, 8, float_buffer=True)
    sky.pixels.foreach_set([1.0] * 16 * 8 * 4)
    sky.pack()
    world.hud.image = sky
    messages = {}

    def attempt(case):
        try:
            bpy.ops.hud.export_scene(directory=str(Path(out) / case))
            messages[case] = None
        except RuntimeError as e:
            messages[case] = str(e)

    world.hud.kind, world.hud.luminance = "uniform", 1e300  # the panorama is left over, not used
    attempt("uniform luminance")
    world.hud.kind, world.hud.calibration, world.hud.value = "hdri", "scale", 1e300
    attempt("calibration value")
    world.hud.kind = "none"
    lcd = next(o for o in scene.objects if o.hud.role == "lcd")
    hot = bpy.data.images.new("hot slide", 8, 8, float_buffer=True)  # generated, filled: its pixels are here
    hot.pixels.foreach_set([2.0] * 256)
    lcd.hud.image = hot
    attempt("slide above 1")
    disable(module)
    return messages


def test_world_and_slide_errors_name_the_field_at_fault(tmp_path):
    """A uniform World's luminance was blamed on a panorama it does not use, a calibration value named no
    field, and a slide with values above 1 got the hint that a generated image loses its pixels, which
    these (in memory, filled) had not."""
    res, _ = in_blender(scenario_world_and_slide_messages, tmp_path)
    assert "World 'World': HUD Environment > Luminance" in res["uniform luminance"], res
    assert "old sky" not in res["uniform luminance"]
    assert "World 'World': HUD Environment > Value" in res["calibration value"], res
    assert "'hot slide'" not in res["slide above 1"] or "regenerates" not in res["slide above 1"], res
    assert "Slide" in res["slide above 1"], res


def _vertex_set(v) -> np.ndarray:
    """Distinct vertex positions (n, 3) mm, sorted: meshes exported with UVs repeat corner vertices."""
    return np.unique(np.round(np.asarray(v, dtype=np.float64), 3), axis=0)


def _float_image(name: str, value: float, w: int = 8, h: int = 4):
    import bpy

    img = bpy.data.images.new(name, w, h, float_buffer=True)
    img.pixels.foreach_set([value, value, value, 1.0] * (w * h))
    return img


def _world_vertices_mm(obj) -> list:
    """The object's vertices in world millimetres (unit scale 1)."""
    return [list(obj.matrix_world @ v.co * 1000.0) for v in obj.data.vertices]


def scenario_name_collision(out):
    """Objects whose names clean to the same file name ("m.a", "m_a", "M.A"; LCDs "s.1", "s_1" with
    different slides) export to one mesh / texture file each."""
    import bpy

    from tests.support.blender import disable, enable_from_source

    module = enable_from_source(bpy, Path(tempfile.mkdtemp()))
    scene = bpy.context.scene
    scene.unit_settings.scale_length = 1.0
    expected = {}
    for name, add in (("m.a", lambda: bpy.ops.mesh.primitive_plane_add(size=0.1, location=(0.0, 0.3, 0.0))),
                      ("m_a", lambda: bpy.ops.mesh.primitive_cube_add(size=0.1, location=(0.2, 0.5, 0.1))),
                      ("M.A", lambda: bpy.ops.mesh.primitive_ico_sphere_add(radius=0.05, location=(-0.2, 0.7, -0.1)))):
        add()
        obj = bpy.context.object
        obj.name = name
        obj.hud.role = "mirror"
        expected[name] = {"vertices_mm": _world_vertices_mm(obj)}
    for name, value, loc in (("s.1", 0.25, (0.0, 1.0, 0.0)), ("s_1", 0.75, (0.3, 1.0, 0.0))):
        bpy.ops.mesh.primitive_plane_add(size=0.1, location=loc)
        obj = bpy.context.object
        obj.name = name
        obj.hud.role, obj.hud.image, obj.hud.image_encoding = "lcd", _float_image(f"slide {name}", value), "linear"
        expected[name] = {"vertices_mm": _world_vertices_mm(obj), "slide": value}
    bpy.ops.hud.export_scene(directory=str(Path(out) / "scene"))
    disable(module)
    return expected


def test_objects_whose_names_clean_alike_export_their_own_geometry(tmp_path):
    """"m.a", "m_a" and "M.A" all clean to m_a (case aside): each gets its own mesh file, unique even
    case-insensitively, and loads with its own vertices; two LCDs "s.1" and "s_1" keep their own slides."""
    expected, _ = in_blender(scenario_name_collision, tmp_path)
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


def _file_hashes(folder: Path) -> dict:
    """SHA-256 of every file under ``folder`` by relative path."""
    return {p.relative_to(folder).as_posix(): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(folder.rglob("*")) if p.is_file()}


def scenario_failed_export(out):
    """A good export into F, then exports into F that fail (missing HDRI file, LCD without slide, an aim
    object not chosen, an orthographic or shifted camera, a role on a text, no camera; and a folder
    holding other files): what each says, and F afterwards."""
    import bpy

    from tests.support.blender import disable, enable_from_source

    module = enable_from_source(bpy, Path(tempfile.mkdtemp()))
    export_scene = sys.modules[f"{module}.hud_addon.export"].export_scene
    out = Path(out)
    parent = out / "exports"
    target = parent / "F"
    scene = bpy.context.scene
    scene.unit_settings.scale_length = 1.0
    bpy.ops.mesh.primitive_plane_add(size=0.2, location=(0.0, 0.3, 0.0))
    mirror = bpy.context.object
    mirror.name, mirror.hud.role = "mirror", "mirror"
    bpy.ops.mesh.primitive_plane_add(size=0.1, location=(0.0, 0.6, 0.0))
    lcd = bpy.context.object
    slide = _float_image("slide", 0.5)
    lcd.name, lcd.hud.role, lcd.hud.image, lcd.hud.image_encoding = "lcd panel", "lcd", slide, "linear"
    bpy.ops.mesh.primitive_plane_add(size=0.01, location=(0.0, 0.8, 0.0))
    led = bpy.context.object
    led.name, led.hud.role, led.hud.emits, led.hud.emission_luminance = "led", "absorber", True, 1000.0
    bpy.ops.mesh.primitive_plane_add(size=0.05, location=(0.3, 0.3, 0.0))
    extra = bpy.context.object
    extra.name, extra.hud.role = "extra", "absorber"
    sky_file = out / "sky.exr"
    made = _float_image("sky source", 0.5, 16, 8)
    made.filepath_raw, made.file_format = str(sky_file), "OPEN_EXR"
    made.save()
    sky = bpy.data.images.load(str(sky_file), check_existing=False)
    sky.name = "sky"
    world = scene.world or bpy.data.worlds.new("World")
    scene.world = world
    world.hud.kind, world.hud.image, world.hud.calibration, world.hud.value = "hdri", sky, "mean", 500.0

    def depsgraph():
        return bpy.context.evaluated_depsgraph_get()

    export_scene(depsgraph(), target)
    good = _file_hashes(target)
    # Change the geometry and the slide, so that anything the failing exports write shows in F's files.
    for v in mirror.data.vertices:
        v.co.x *= 2.0
    slide.pixels.foreach_set([0.9] * (8 * 4 * 4))
    attempts = {}

    def attempt(case, folder=target, operator=False):
        try:
            if operator:
                bpy.ops.hud.export_scene(directory=str(folder))
            else:
                export_scene(depsgraph(), folder)
            message = None
        except Exception as e:  # noqa: BLE001 - the message is what is tested
            message = f"{type(e).__name__}: {e}"
        attempts[case] = {"message": message, "hashes": _file_hashes(folder),
                          "hidden": sorted(n for n in os.listdir(parent) if n.startswith("."))}

    missing = out / "missing" / "sky.exr"
    sky.filepath = str(missing)
    attempt("hdri_missing")
    attempt("hdri_missing_operator", operator=True)
    sky.filepath = str(sky_file)
    lcd.hud.image = None
    attempt("lcd_no_image")
    lcd.hud.image = slide
    led.hud.emission_aim, led.hud.emission_aim_object = "OBJECT", None
    attempt("aim_unset")
    led.hud.emission_aim = "NONE"
    # File system failures: a disk that fills while meshes are written; a staging folder that cannot
    # take F's place (after F was moved aside).
    files_mod = sys.modules[f"{module}.hud_addon.export_files"]  # the staged folder's files are written there
    write_obj, rename = files_mod.write_obj, os.rename

    def write_half(path, *args, **kwargs):
        Path(path).write_text("v 0 0 0\n")
        raise OSError(28, "No space left on device", str(path))

    def rename_fails_for_staging(src, dst):
        if ".staging-" in str(src):
            raise OSError(13, "Permission denied", str(dst))
        return rename(src, dst)

    files_mod.write_obj = write_half
    attempt("disk_full")
    files_mod.write_obj = write_obj
    os.rename = rename_fails_for_staging
    try:
        attempt("rename_fails")
    finally:
        os.rename = rename
    # The tracer's validation rejects the staged folder (an open dielectric: a plane of glass).
    extra.hud.role = "dielectric"
    attempt("tracer_rejects", operator=True)
    extra.hud.role = "absorber"
    foreign = parent / "G"
    foreign.mkdir()
    (foreign / "notes.txt").write_text("not an export\n")
    attempt("foreign_folder", folder=foreign)
    camera = scene.camera
    camera.data.type = "ORTHO"
    attempt("ortho_camera")
    camera.data.type = "PERSP"
    camera.data.shift_x = 0.1
    attempt("shifted_camera")
    camera.data.shift_x = 0.0
    bpy.ops.object.text_add(location=(0.0, 0.4, 0.0))
    text = bpy.context.object
    text.name, text.hud.role = "label", "mirror"
    attempt("role_on_text")
    bpy.data.objects.remove(text)
    camera_data = camera.data
    bpy.data.objects.remove(camera)
    attempt("no_camera")
    # Put the camera back and drop "extra": the export now replaces F as a whole.
    camera = bpy.data.objects.new("Camera", camera_data)
    scene.collection.objects.link(camera)
    camera.location = (0.0, -1.0, 0.0)
    scene.camera = camera
    bpy.data.objects.remove(extra)
    attempt("after_fix")
    # A folder relative to the .blend ("//") while the .blend is not saved: Blender resolved it against
    # the working directory, and the export landed wherever that was.
    cwd = os.getcwd()
    os.chdir(out)
    try:
        bpy.ops.hud.export_scene(directory="//hud_export/")
        relative = None
    except RuntimeError as e:
        relative = str(e)
    finally:
        os.chdir(cwd)
    attempts["relative_unsaved"] = {"message": relative, "written": (out / "hud_export").exists()}
    disable(module)
    return {"good": good, "attempts": attempts, "missing": str(missing)}


def test_a_failed_export_leaves_the_earlier_export_as_it_was(tmp_path):
    """Export into F, then fail eight ways (HDRI file missing, LCD without slide, aim object not
    chosen, no camera; a write error while staging, the staged folder failing to take F's place, the
    tracer's validation rejecting the staged folder): each says what is wrong and where, F is byte for
    byte the earlier export, and no hidden staging or backup folder is left beside it. A folder
    holding other files is not replaced. Once fixed, the export replaces F as a whole (the dropped
    object's mesh is gone)."""
    res, _ = in_blender(scenario_failed_export, tmp_path)
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


def scenario_visibility(out):
    """Render visibility decides what is exported: an object hidden in the
    viewport only is exported; one disabled in renders, one in a collection disabled in renders and
    one in a collection excluded from the view layer are not."""
    import bpy

    from tests.support.blender import disable, enable_from_source

    module = enable_from_source(bpy, Path(tempfile.mkdtemp()))
    scene = bpy.context.scene
    names = {}
    for i, name in enumerate(("shown", "viewport_hidden", "render_hidden", "in_hidden_collection",
                              "in_excluded_collection")):
        bpy.ops.mesh.primitive_plane_add(size=0.1, location=(0.2 * i, 0.5, 0.0))
        obj = bpy.context.object
        obj.name = name
        obj.hud.role = "mirror"
        names[name] = obj
    names["viewport_hidden"].hide_set(True)
    names["viewport_hidden"].hide_viewport = True
    names["render_hidden"].hide_render = True
    for name, flag in (("in_hidden_collection", "hide_render"), ("in_excluded_collection", "exclude")):
        coll = bpy.data.collections.new(f"{name}_coll")
        scene.collection.children.link(coll)
        obj = names[name]
        for c in list(obj.users_collection):
            c.objects.unlink(obj)
        coll.objects.link(obj)
        if flag == "hide_render":
            coll.hide_render = True
        else:
            bpy.context.view_layer.layer_collection.children[coll.name].exclude = True
    bpy.ops.hud.export_scene(directory=str(Path(out) / "scene"))
    disable(module)
    return {}


def test_export_follows_render_visibility(tmp_path):
    """Hidden in the viewport only -> exported; disabled in renders, in a
    collection disabled in renders, or in a collection excluded from the view layer -> not."""
    in_blender(scenario_visibility, tmp_path)
    data = json.loads((tmp_path / "scene" / "scene.json").read_text())
    assert sorted(o["name"] for o in data["objects"]) == ["shown", "viewport_hidden"]


def scenario_instances(out):
    """Collection instances and an object hidden from renders: a mirror in a
    collection excluded from the view layer, instanced by two empties, exports as two mirrors at the
    instances' places; a third instance disabled in renders is left out."""
    import bpy

    from tests.support.blender import disable, enable_from_source

    module = enable_from_source(bpy, Path(tempfile.mkdtemp()))
    scene = bpy.context.scene
    scene.unit_settings.scale_length = 0.001  # 1 Blender unit = 1 mm
    coll = bpy.data.collections.new("optics")
    scene.collection.children.link(coll)
    bpy.ops.mesh.primitive_plane_add(size=20.0, location=(0.0, 0.0, 0.0))
    mirror = bpy.context.object
    mirror.name = "mirror"
    mirror.hud.role, mirror.hud.reflectance = "mirror", (0.9, 0.9, 0.9)
    for c in list(mirror.users_collection):
        c.objects.unlink(mirror)
    coll.objects.link(mirror)
    bpy.context.view_layer.layer_collection.children[coll.name].exclude = True
    places = {"inst_a": (100.0, 0.0, 0.0), "inst_b": (0.0, 200.0, 0.0), "inst_hidden": (0.0, 0.0, 300.0)}
    for name, loc in places.items():
        empty = bpy.data.objects.new(name, None)
        empty.instance_type, empty.instance_collection = "COLLECTION", coll
        empty.location = loc
        scene.collection.objects.link(empty)
    bpy.data.objects["inst_hidden"].hide_render = True
    bpy.ops.hud.export_scene(directory=str(Path(out) / "scene"))
    disable(module)
    return {"places": places}


def test_collection_instances_export_as_objects_and_hide_render_is_honoured(tmp_path):
    """Each instance of a collection becomes an object of its own at the instance's
    place, even though the collection itself is excluded; an instancer disabled in renders is not."""
    res, _ = in_blender(scenario_instances, tmp_path)
    from tracer.scene import load_scene

    data = json.loads((tmp_path / "scene" / "scene.json").read_text())
    names = sorted(o["name"] for o in data["objects"])
    assert names == ["mirror @ inst_a 1", "mirror @ inst_b 1"]
    assert len({o["mesh"] for o in data["objects"]}) == 1  # instances share one mesh file
    sc = load_scene(tmp_path / "scene")
    for name, inst in (("mirror @ inst_a 1", "inst_a"), ("mirror @ inst_b 1", "inst_b")):
        np.testing.assert_allclose(sc.object(name).vertices.mean(axis=0), res["places"][inst], atol=1e-6)
        assert sc.object(name).area_mm2 == pytest.approx(400.0)


def scenario_colour_space(out):
    """An LCD's slide encoding follows the image's own Color Space."""
    import bpy

    from tests.support.blender import disable, enable_from_source

    module = enable_from_source(bpy, Path(tempfile.mkdtemp()))
    bpy.ops.hud.add_preset(preset="hud-direct")
    lcd = next(o for o in bpy.context.scene.objects if o.hud.role == "lcd")
    image = lcd.hud.image
    lcd.hud.image_encoding = "linear"  # the old Encoding property: no longer what decides
    result = {"spaces": {}}
    for space in ("sRGB", "Non-Color", "ACEScg"):
        try:
            image.colorspace_settings.name = space
        except TypeError:
            continue  # not in this Blender's OCIO configuration
        try:
            bpy.ops.hud.export_scene(directory=str(Path(out) / space))
            data = json.loads((Path(out) / space / "scene.json").read_text())
            mat = next(o["material"] for o in data["objects"] if o["material"]["type"] == "lcd")
            result["spaces"][space] = mat["image_encoding"]
        except RuntimeError as e:
            result["spaces"][space] = "error: " + str(e)
    result["is_float"] = image.is_float
    result["image"] = image.name
    disable(module)
    return result


def test_lcd_slide_encoding_follows_the_image_color_space(tmp_path):
    """An 8-bit slide in sRGB exports as sRGB-encoded, in Non-Color as linear,
    whatever the old Encoding property says; a colour space the tracer cannot read a transmittance from
    is refused, naming the image."""
    res, _ = in_blender(scenario_colour_space, tmp_path)
    assert res["is_float"] is False
    assert res["spaces"]["sRGB"] == "srgb" and res["spaces"]["Non-Color"] == "linear"
    if "ACEScg" in res["spaces"]:
        msg = res["spaces"]["ACEScg"]
        assert msg.startswith("error:") and res["image"] in msg and "ACEScg" in msg


def scenario_sun(out):
    """A Sun light as the environment's sun: a 4 m Lambertian floor seen from 0.5 m above; a Sun light
    turned 60 deg about x (it shines along its -Z: toward +y and down, so the sun stands 30 deg high
    toward -y), Angle 0.53 deg, a warm colour, HUD Sun 80,000 lx, keyframed to turn 90 deg about z at
    frame 2; a point light beside it (not exported). Exports: frame 1 with no World, frame 2, frame 1
    with an HDRI World calibrated to its minimum; then the failures: a second Sun light rendered, the
    same disabled in renders (exported again), an Angle of 0, a black Color in an F12 render; and the
    HUD Sun panel drawn."""
    import math
    import types

    import bpy

    from tests.support.blender import Layout, StubEngine, disable, enable_from_source

    module = enable_from_source(bpy, Path(tempfile.mkdtemp()))
    export_mod = sys.modules[f"{module}.hud_addon.export"]
    ui_mod = sys.modules[f"{module}.hud_addon.ui"]
    out = Path(out)
    scene = bpy.context.scene
    scene.unit_settings.scale_length = 1.0
    for obj in list(scene.objects):
        if obj.type != "CAMERA":
            bpy.data.objects.remove(obj)
    scene.world = None
    bpy.ops.mesh.primitive_plane_add(size=4.0, location=(0.0, 0.0, 0.0))
    floor = bpy.context.object
    floor.name, floor.hud.role, floor.hud.reflectance = "floor", "lambertian", (0.5, 0.5, 0.5)
    cam = scene.camera
    cam.location, cam.rotation_euler = (0.0, 0.0, 0.5), (0.0, 0.0, 0.0)  # looking straight down
    scene.render.resolution_x, scene.render.resolution_y, scene.render.resolution_percentage = 8, 8, 100
    light = bpy.data.lights.new("Sun", type="SUN")
    light.angle, light.color, light.hud.illuminance_lux = math.radians(0.53), (1.0, 0.9, 0.8), 80_000.0
    sun = bpy.data.objects.new("Sun", light)
    scene.collection.objects.link(sun)
    for frame, turn in ((1, 0.0), (2, 90.0)):
        sun.rotation_euler = (math.radians(60.0), 0.0, math.radians(turn))
        sun.keyframe_insert("rotation_euler", frame=frame)
    lamp = bpy.data.objects.new("lamp", bpy.data.lights.new("lamp", type="POINT"))
    scene.collection.objects.link(lamp)

    def export(name):
        try:
            bpy.ops.hud.export_scene(directory=str(out / name))
            return None
        except RuntimeError as e:  # the operator's report
            return str(e)

    scene.frame_set(1)
    messages = {"frame1": export("frame1")}
    scene.frame_set(2)
    messages["frame2"] = export("frame2")
    scene.frame_set(1)
    directions = {"frame1": list(sun.matrix_world.col[2][:3])}
    scene.frame_set(2)
    directions["frame2"] = list(sun.matrix_world.col[2][:3])
    scene.frame_set(1)
    sky = bpy.data.images.new("sky", 16, 8, float_buffer=True)
    sky.pixels.foreach_set([0.2 + 0.01 * (i % 7) if i % 4 != 3 else 1.0 for i in range(16 * 8 * 4)])
    sky.filepath_raw, sky.file_format = str(out / "sky.exr"), "OPEN_EXR"
    sky.save()
    world = bpy.data.worlds.new("World")
    scene.world = world
    world.hud.kind, world.hud.image, world.hud.calibration, world.hud.value = "hdri", sky, "min", 5.0
    messages["hdri_min"] = export("hdri_min")
    second = bpy.data.objects.new("Sun.second", bpy.data.lights.new("Sun.second", type="SUN"))
    scene.collection.objects.link(second)
    messages["two_suns"] = export("two_suns")
    second.hide_render = True
    messages["second_hidden"] = export("second_hidden")
    light.angle = 0.0
    messages["angle_0"] = export("angle_0")
    light.angle = math.radians(0.53)
    light.color = (0.0, 0.0, 0.0)  # refused by the tracer's validation: F12 names the light and its Color
    engine_mod = sys.modules[f"{module}.hud_addon.engine"]
    messages["black_f12"] = engine_mod.render_final(StubEngine(10**9), bpy.context.evaluated_depsgraph_get())["error"]
    light.color = (1.0, 0.9, 0.8)
    labels = []

    class Panel:
        layout = Layout(labels)

    context = types.SimpleNamespace(light=light, engine="HUD_TRACER", scene=scene)
    polls = {"sun": ui_mod.HUD_PT_sun.poll(context),
             "other engine": ui_mod.HUD_PT_sun.poll(types.SimpleNamespace(light=light, engine="CYCLES")),
             "no light": ui_mod.HUD_PT_sun.poll(types.SimpleNamespace(light=None, engine="HUD_TRACER"))}
    ui_mod.HUD_PT_sun.draw(Panel(), context)
    spec_direct = export_mod.sun_spec(bpy.context.evaluated_depsgraph_get())
    disable(module)
    return {"messages": messages, "directions": directions, "polls": polls, "labels": labels,
            "spec_direct": spec_direct}


def test_a_sun_light_exports_as_the_environments_sun(tmp_path):
    """A Sun light turned 60 deg about x shines along its -Z (toward +y and down): the exported sun stands
    30 deg high toward -y (its +Z), with the light's Angle, Color and HUD Sun illuminance; keyframed to
    turn 90 deg about z, frame 2's sun stands toward +x. The folder loads in the tracer, and its floor
    (albedo 0.5) renders rho E sin(30 deg) / pi. With an HDRI World calibrated to its minimum both
    export together. Two rendered Sun lights are refused naming both (one disabled in renders is not
    counted), an Angle of 0 naming the light, a black Color (the tracer's refusal, in an F12 render)
    naming the light and its Color; the HUD Sun panel shows with the engine and gives the disk's
    luminance."""
    res, _ = in_blender(scenario_sun, tmp_path)
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
