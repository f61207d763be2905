"""Loading a scene folder (tracer/scene/load.py, with tracer/core/validate.py): every bad value, type,
path or file of scene.json is refused before the first ray in one line that names the file and the field
(through ``hud-trace render``: exit 2, the earlier output set untouched), the limits keep every output
finite, paths stay inside the scene folder unless allowed, and a byte-order mark is read."""

import json
from pathlib import Path

import numpy as np
import pytest

from tests.support.cli import assert_complete_set, assert_one_line_error, hashes, hud_trace, run_cli
from tests.support.scenes import edit_json, plate_scene, set_field
from tracer.core.errors import SceneError
from tracer.scene import load_scene

HUGE = 1e308
BAD_VALUES = {
    # 1e308 in every kind of field
    "pupil 1e308": (set_field(("eye", "pupil_diameter_mm"), HUGE), "eye.pupil_diameter_mm"),
    "focal length 1e308": (set_field(("eye", "focal_length_mm"), HUGE), "eye.focal_length_mm"),
    "accommodation 1e308": (set_field(("eye", "accommodation_distance_mm"), HUGE),
                            "eye.accommodation_distance_mm"),
    "luminance 1e308": (set_field(("objects", 2, "emission", "luminance"), HUGE),
                        "objects[2].emission.luminance"),
    "flux 1e308": (lambda d: d["objects"][2].update(emission={"flux": HUGE}), "objects[2].emission.flux"),
    "scale 1e308": (set_field(("objects", 0, "transform"), {"scale": [HUGE, 1, 1]}),
                    "objects[0].transform.scale"),
    # beyond float range
    "integer 10**400": (set_field(("eye", "pupil_diameter_mm"), 10**400), "eye.pupil_diameter_mm"),
    # a resolution whose film does not fit in memory
    "resolution 16384^2": (set_field(("eye", "resolution"), [16384, 16384]), "eye.resolution"),
    # values whose render would overflow float32 or JSON
    "luminance 1e30": (set_field(("objects", 2, "emission", "luminance"), 1e30),
                       "objects[2].emission.luminance"),
    "environment 1e308": (set_field(("environment",), {"type": "uniform", "luminance": HUGE}),
                          "environment.luminance"),
    # a vertex beyond float32
    "vertex 1e39": (None, "meshes/mirror.obj"),
    # a fraction where a whole number belongs
    "max_depth 1.5": (set_field(("methods",), {"backward": {"max_depth": 1.5}}),
                      "methods.backward.max_depth"),
    # the cause named, not "degenerate"
    "translation 1e308": (set_field(("objects", 0, "transform"), {"translate": [HUGE, 0, 0]}),
                          "translate"),
    "scale 1e-30": (set_field(("objects", 0, "transform"), {"scale": [1e-30, 1, 1]}), "scale"),
    "matrix entry 1e308": (lambda d: d["objects"][0]["transform"]["matrix"][0].__setitem__(1, HUGE), "matrix"),
}


@pytest.mark.parametrize("case", sorted(BAD_VALUES))
def test_bad_values_give_one_line_naming_file_and_field(mirror, earlier, case):
    """Values out of range or of the wrong kind: each is exit 2, one line, file and field named, the
    earlier outputs untouched (they were OverflowError, MemoryError, Inf in the outputs, "all triangles
    are degenerate" for a translation)."""
    out, before = earlier
    edit, field = BAD_VALUES[case]
    if edit is None:
        mesh = mirror / "meshes" / "mirror.obj"
        text = mesh.read_text().splitlines()
        first = next(i for i, ln in enumerate(text) if ln.startswith("v "))
        text[first] = "v 1e39 0 0"
        mesh.write_text("\n".join(text) + "\n")
    else:
        edit_json(mirror, edit)
    code, err = run_cli("render", mirror, "--rays", 10**12, "--workers", 1, "--quiet", "--out", out)
    assert_one_line_error(code, err, field)
    assert "scene.json" in err or field.startswith("meshes/")
    assert "degenerate" not in err and "flattens" not in err
    assert hashes(out) == before


def test_the_memory_message_gives_the_limit_and_the_estimate(mirror):
    edit_json(mirror, set_field(("eye", "resolution"), [16384, 16384]))
    code, err = run_cli("render", mirror, "--rays", 1000, "--workers", 1, "--quiet", "--out", mirror / "o")
    assert code == 2 and "16384 x 16384" in err and "GiB" in err, err


def test_the_brightest_allowed_source_renders_finite_outputs(mirror, tmp_path):
    """The luminance limit keeps every output finite: at the limit, Y_var (float32) and the report
    (JSON) still hold the values."""
    from tracer.core.validate import MAX_LUMINANCE

    edit_json(mirror, set_field(("objects", 2, "emission", "luminance"), MAX_LUMINANCE))
    out = tmp_path / "o"
    code, err = run_cli("render", mirror, "--rays", 100_000, "--workers", 1, "--quiet", "--out", out)
    assert code == 0, err
    report = assert_complete_set(out)
    assert report["luminance"]["max"] == pytest.approx(0.85 * MAX_LUMINANCE, rel=0.05)


def test_deep_nesting_and_duplicate_keys(mirror, earlier):
    """JSON nested 100,000 deep (a RecursionError) and duplicate keys (the last won): each refused in one
    line naming scene.json."""
    out, before = earlier
    scene = mirror / "scene.json"
    text = scene.read_text()
    scene.write_text("[" * 100_000 + "]" * 100_000)
    code, err = run_cli("render", mirror, "--rays", 10**12, "--workers", 1, "--quiet", "--out", out)
    assert_one_line_error(code, err, "scene.json", "nested")
    scene.write_text(text.replace('"eye": {', '"eye": {"pupil_diameter_mm": 3.0, ', 1))
    code, err = run_cli("render", mirror, "--rays", 10**12, "--workers", 1, "--quiet", "--out", out)
    assert_one_line_error(code, err, "scene.json", "pupil_diameter_mm", "duplicate key")
    assert hashes(out) == before


def test_an_unreadable_scene_or_meshes_folder_names_the_file(mirror, earlier, monkeypatch):
    """An unreadable scene.json or mesh is named in one line, not a PermissionError traceback.
    (Permissions are simulated: the tests may run as root, who reads everything.)"""
    out, before = earlier
    real_read, real_stat = Path.read_bytes, Path.stat

    def read_bytes(self):
        if self.name == "scene.json":
            raise PermissionError(13, "Permission denied", str(self))
        return real_read(self)

    with monkeypatch.context() as m:
        m.setattr(Path, "read_bytes", read_bytes)
        code, err = run_cli("render", mirror, "--rays", 10**12, "--workers", 1, "--quiet", "--out", out)
    assert_one_line_error(code, err, "scene.json", "Permission denied")

    def stat(self, *a, **kw):
        if self.parent.name == "meshes":
            raise PermissionError(13, "Permission denied", str(self))
        return real_stat(self, *a, **kw)

    with monkeypatch.context() as m:
        m.setattr(Path, "stat", stat)
        code, err = run_cli("render", mirror, "--rays", 10**12, "--workers", 1, "--quiet", "--out", out)
    assert_one_line_error(code, err, "objects[0].mesh", "Permission denied")
    assert hashes(out) == before


def test_paths_stay_inside_the_scene_folder_unless_allowed(mirror, tmp_path):
    outside = tmp_path / "elsewhere"
    outside.mkdir()
    (outside / "m.obj").write_bytes((mirror / "meshes" / "mirror.obj").read_bytes())
    (mirror / "meshes" / "link.obj").symlink_to(outside / "m.obj")
    for path in (str(outside / "m.obj"), "../elsewhere/m.obj", "meshes/link.obj", "meshes/../../elsewhere/m.obj"):
        edit_json(mirror, lambda d, p=path: d["objects"][0].update(mesh=p))
        code, err = run_cli("render", mirror, "--rays", 10**12, "--workers", 1, "--quiet", "--out", tmp_path / "o")
        assert_one_line_error(code, err, "objects[0].mesh", "--allow-external-files")
        assert load_scene(mirror, allow_external=True).object("mirror").vertices.shape[0] > 0


def test_a_truncated_texture_gives_one_line_not_the_image_library_s_own(preset, tmp_path):
    """libpng prints its errors to the process' stderr beside the error OpenImageIO returns, which
    itself can span lines: the user gets one line (checked in a subprocess, where C output shows)."""
    folder = preset("hud-direct")
    slide = folder / "textures" / "slide.png"
    slide.write_bytes(slide.read_bytes()[:100])
    res = hud_trace("render", folder, "--rays", 1000, "--workers", 1, "--quiet", "--out", tmp_path / "o", timeout=300)
    assert res.returncode == 2, res.stderr
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: ") and "textures/slide.png" in lines[0], res.stderr


def test_a_key_with_a_control_character_is_named_on_one_line(mirror, earlier):
    """Found by fuzzing: a key "sha\\re" in scene.json was echoed raw, and its carriage return split
    the error line in two. Keys and values are escaped in messages."""
    out, before = earlier
    edit_json(mirror, lambda d: d["objects"][2]["emission"].update({"sha\re": 1}))
    code, err = run_cli("render", mirror, "--rays", 10**12, "--workers", 1, "--quiet", "--out", out)
    assert_one_line_error(code, err, "objects[2].emission.sha\\re", "unknown field")
    assert hashes(out) == before


# -- values that underflowed or crashed, names that escaped the checks ------------------------------------
TINY_OR_MISTYPED = {
    # a pupil of 1e-5 mm made the pixel extent (a view factor) cancel to 0 and the estimate NaN
    "pupil 1e-5": (set_field(("eye", "pupil_diameter_mm"), 1e-5), "eye.pupil_diameter_mm"),
    "pupil 1e-300": (set_field(("eye", "pupil_diameter_mm"), 1e-300), "eye.pupil_diameter_mm"),
    # a black image and "none reached a source" instead of a refusal
    "luminance 1e-300": (set_field(("objects", 2, "emission", "luminance"), 1e-300),
                         "objects[2].emission.luminance"),
    "flux 1e-300": (lambda d: d["objects"][2].update(emission={"flux": 1e-300}), "objects[2].emission.flux"),
    "lobe 1e-30 deg": (set_field(("objects", 0, "material"), {"type": "diffuser", "transmittance": 0.5,
                                                              "sigma_deg": [1e-30, 3.0]}),
                       "objects[0].material.sigma_deg[0]"),
    # a metal that reflects nothing at normal incidence: the angular law divides by its R(0)
    "metal 1 + 0i": (set_field(("objects", 0, "material", "metal"), {"complex_ior": [1.0, 0.0]}),
                     "objects[0].material.metal.complex_ior"),
    "metal 0 + 0i": (set_field(("objects", 0, "material", "metal"), {"complex_ior": [0.0, 0.0]}),
                     "objects[0].material.metal.complex_ior"),
    # true and 1.0 equal 1 in Python
    "version true": (set_field(("version",), True), "version"),
    "version 1.0": (set_field(("version",), 1.0), "version"),
    # null was the identity here and refused for every other block
    "transform null": (set_field(("objects", 0, "transform"), None), "objects[0].transform"),
    # os functions raise ValueError on a NUL
    "NUL in a mesh path": (set_field(("objects", 0, "mesh"), "meshes/mirror.obj\0x"), "objects[0].mesh"),
    # an aperture (not traced) with an emission block was dropped from the light table without a word
    # ("the scene has no light source" when it was the only one)
    "emission on an aperture": (set_field(("objects", 1, "emission"), {"luminance": 1000.0}),
                                "objects[1].emission"),
    # every ray to the focused point grazed the pupil plane: black, and the method was blamed
    "accommodation 0.001 mm": (set_field(("eye", "accommodation_distance_mm"), 0.001),
                               "eye.accommodation_distance_mm"),
    # a black image of exit 0 and a RuntimeWarning from the roulette
    "environment 1e-300": (set_field(("environment",), {"type": "uniform", "luminance": 1e-300}),
                           "environment.luminance"),
    # tracebacks from the colour's normalisation
    "environment colour of luminance 0": (set_field(("environment",), {"type": "uniform", "luminance": 100.0,
                                                                       "color": [0.0, 0.0, 5e-324]}),
                                          "environment.color"),
    "sun colour of luminance 0": (set_field(("environment",), {"type": "none", "sun": {"direction": [0, 1, 1],
                                                                                       "color": [5e-324, 0.0, 0.0]}}),
                                  "environment.sun.color"),
    # an almost opaque analyser: 1e-300 rendered black with exit 0, 1e-40 overflowed a reciprocal
    "analyser of 1e-300": (set_field(("eye", "analyser"), {"transmittance_along": 1e-300,
                                                           "transmittance_across": 0.0}),
                           "eye.analyser.transmittance_along"),
    "analyser of 1e-40": (set_field(("eye", "analyser"), {"transmittance_along": 1e-40, "transmittance_across": 0.0}),
                          "eye.analyser.transmittance_along"),
    # an analyser that passes nothing rendered black with "try the other method, or more rays"
    "analyser passing nothing": (set_field(("eye", "analyser"), {"transmittance_along": 0.0,
                                                                 "transmittance_across": 0.0}),
                                 "eye.analyser"),
}


@pytest.mark.parametrize("case", sorted(TINY_OR_MISTYPED))
def test_tiny_and_mistyped_values_give_one_line_naming_file_and_field(mirror, earlier, case):
    """Before: a FloatingPointError traceback (pupil 1e-5 mm), black images reported as "no light
    path found" (luminance 1e-300), overflow warnings (a 1e-30 deg lobe), divide-by-zero warnings and
    a black mirror (complex index 0 or 1), a version of true accepted, a ValueError traceback for a
    NUL. Now exit 2, one line, file and field named, the earlier outputs untouched."""
    out, before = earlier
    edit, field = TINY_OR_MISTYPED[case]
    edit_json(mirror, edit)
    code, err = run_cli("render", mirror, "--rays", 10**12, "--workers", 1, "--quiet", "--out", out)
    assert_one_line_error(code, err, "scene.json", field)
    assert hashes(out) == before


def test_a_scene_file_with_a_byte_order_mark_loads(mirror):
    """Windows editors save UTF-8 with a byte-order mark, which the loader refused with Python's own
    words ("Unexpected UTF-8 BOM (decode using utf-8-sig)"; a hand-built input): it reads the scene."""
    path = mirror / "scene.json"
    plain = load_scene(mirror)
    path.write_bytes(b"\xef\xbb\xbf" + path.read_bytes())
    marked = load_scene(mirror)
    assert [o.name for o in marked.objects] == [o.name for o in plain.objects]
    assert all(np.array_equal(a.vertices, b.vertices) for a, b in zip(marked.objects, plain.objects, strict=True))
    assert np.array_equal(marked.eye.position, plain.eye.position)


BAD = {
    "malformed_json": (lambda p: (p / "scene.json").write_text("{ not json"), ""),
    "missing_mesh": (lambda p: edit_json(p, lambda d: d["objects"][0].update(mesh="meshes/nope.obj")),
                     "objects[0].mesh"),
    "missing_texture": (lambda p: edit_json(p, lambda d: d["objects"][2]["material"].update(image="textures/nope.png")),
                        "objects[2].material.image"),
    "negative_luminance": (lambda p: edit_json(p, lambda d: d["objects"][-2]["emission"].update(luminance=-5)),
                           "emission.luminance"),
    "zero_pupil": (lambda p: edit_json(p, lambda d: d["eye"].update(pupil_diameter_mm=0)), "eye.pupil_diameter_mm"),
    "negative_pupil": (lambda p: edit_json(p, lambda d: d["eye"].update(pupil_diameter_mm=-4)),
                       "eye.pupil_diameter_mm"),
    "unknown_material": (lambda p: edit_json(p, lambda d: d["objects"][1]["material"].update(type="unobtainium")),
                         "objects[1].material.type"),
    "degenerate_transform": (lambda p: edit_json(p, lambda d: d["objects"][1].update(
        transform={"scale": [1, 0, 1]})), "objects[1].transform"),
}


@pytest.mark.slow
@pytest.mark.parametrize("case", sorted(BAD))
def test_bad_input_names_file_and_field_and_writes_nothing(tmp_path, case):
    folder = tmp_path / "scene"
    assert hud_trace("export", "hud-direct", folder).returncode == 0
    spoil, field = BAD[case]
    spoil(folder)
    out = tmp_path / "out"
    res = hud_trace("render", folder, "--method", "forward", "--rays", 1000, "--out", out, "--quiet")
    assert res.returncode == 2, res.stderr
    assert "scene.json" in res.stderr and field in res.stderr
    assert "Traceback" not in res.stderr
    assert not out.exists()


def _edit(folder, fn):
    edit_json(folder, fn)
    return folder


@pytest.mark.parametrize("edit,field", [
    (lambda d: d.update(polarisation="partly"), "polarisation"),
    (lambda d: (d.update(polarisation="off"), d["eye"].update(analyser={})), "eye.analyser"),
    (lambda d: d["eye"].update(analyser={"axis_deg": 90, "transmittance_along": 1.5}),
     "eye.analyser.transmittance_along"),
    (lambda d: d["eye"].update(analyser={"axis": 90}), "eye.analyser.axis"),
    (lambda d: d["objects"][1]["emission"].update(polarisation={"axis_deg": 0, "degree": 2}),
     "objects[1].emission.polarisation.degree"),
    (lambda d: (d.update(polarisation="off"), d["objects"][1]["emission"].update(polarisation={"axis_deg": 0})),
     "objects[1].emission.polarisation"),
    (lambda d: d["objects"][0].update(material={"type": "coating", "reflectance_s": 0.5, "reflectance_p": 0.2,
                                                "transmittance_s": 0.6, "transmittance_p": 0.5}),
     "objects[0].material"),
    (lambda d: d["objects"][0].update(material={"type": "coating", "reflectance_s": 0.5, "reflectance": 0.2,
                                                "transmittance": 0.6}), "objects[0].material"),
    (lambda d: d["objects"][0].update(material={"type": "mirror", "reflectance": 0.9, "metal": {}}),
     "objects[0].material.metal.complex_ior"),
    (lambda d: d["objects"][0].update(material={"type": "retarder", "retardance_deg": 90}),
     "objects[0].material.axis_deg"),
])
def test_bad_polarisation_input_names_the_field(tmp_path, edit, field):
    folder = _edit(plate_scene(tmp_path / "b"), edit)
    with pytest.raises(SceneError) as e:
        load_scene(folder)
    assert e.value.field == field, str(e.value)
    assert "scene.json" in str(e.value)


def test_lcds_need_polarisers_on_all_or_none(preset):
    folder = preset("hud-direct-s")

    def add_lcd(d):
        lcd = next(o for o in d["objects"] if o["name"] == "lcd")
        d["objects"].append(json.loads(json.dumps(lcd)) | {"name": "lcd_2"})
        d["objects"][-1]["material"].pop("polariser")

    edit_json(folder, add_lcd)
    with pytest.raises(SceneError) as e:
        load_scene(folder)
    assert e.value.field.endswith(".material.polariser") and "every LCD" in str(e.value)
