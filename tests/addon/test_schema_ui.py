"""Panels drawn from the schemas (hud_addon/schema_ui.py): the polarisation of scene.json in Blender, the eye's
analyser, the scene's mode and the polarising materials drawn, exported, loaded by the tracer and built
back.

Each scenario (a ``scenario_*`` function: the scene set up, rendered or exported inside the bpy module)
sits before the tests that assert on its result, and runs in a process of its own through
tests/addon/blender_runner.py (tests.support.addon.in_blender)."""

from __future__ import annotations

import json
import sys
import tempfile
from pathlib import Path

import numpy as np
import pytest

from tests.support.addon import in_blender, needs_bpy

pytestmark = [needs_bpy, pytest.mark.slow]


class _PropLayout:
    """Stands in for a panel's layout: records the names of the properties drawn."""

    def __init__(self, names):
        self.names = names

    def prop(self, owner, name, **kw):
        self.names.append(name)

    def __getattr__(self, name):
        if name in ("column", "row", "box", "grid_flow"):
            return lambda *a, **k: _PropLayout(self.names)
        return lambda *a, **k: None


def scenario_polarisation(out):
    """The polarisation of the scene in Blender: hud-direct with its LCD's output polariser on, a
    retarder film, a coating given for s and p light, a metal mirror, polarised emission, the eye's
    analyser (axis 90, along 0.9, across 0.01) and Polarisation "auto": panels drawn, exported to
    out/pol; with Polarisation "off" the export is refused and an F12-style export names the Blender
    settings; out/pol built back with Add HUD Preset's build_scene; the hud-direct-s-sunglasses preset
    added when the tracer has it."""
    import types

    import bpy

    from tests.support.blender import disable, enable_from_source

    module = enable_from_source(bpy, Path(tempfile.mkdtemp()))
    pkg = f"{module}.hud_addon"
    export_mod, messages_mod, build_mod, ui_mod = (sys.modules[f"{pkg}.{m}"]
                                                   for m in ("export", "messages", "build", "ui"))
    out = Path(out)
    bpy.ops.hud.add_preset(preset="hud-direct")
    scene = bpy.context.scene
    lcd = next(o for o in scene.objects if o.hud.role == "lcd")
    lcd.hud.polariser_use, lcd.hud.polariser_axis_deg = True, 45.0
    led = next(o for o in scene.objects if o.hud.emits)
    led.hud.emission_polarisation_use = True
    led.hud.emission_polarisation_axis_deg, led.hud.emission_polarisation_degree = 30.0, 0.5
    extras = {}
    for k, (name, role) in enumerate((("film", "retarder"), ("splitter", "coating"), ("metal", "mirror"))):
        bpy.ops.mesh.primitive_plane_add(size=5.0, location=(1000.0 + 20.0 * k, 1000.0, 1000.0))
        obj = extras[name] = bpy.context.object
        obj.name, obj.hud.role = name, role
    h = extras["film"].hud
    h.transmittance, h.axis_deg, h.retardance_deg = (0.95, 0.95, 0.95), 22.5, 90.0
    h = extras["splitter"].hud
    h.by = "reflectance_s"
    h.reflectance_s, h.reflectance_p = (0.3,) * 3, (0.1,) * 3
    h.transmittance_s, h.transmittance_p = (0.6,) * 3, (0.8,) * 3
    h = extras["metal"].hud
    h.reflectance, h.metal_use, h.metal_complex_ior = (0.9, 0.9, 0.9), True, (1.2, 7.0)
    eye = scene.camera.data.hud
    eye.analyser_use = True
    eye.analyser_axis_deg, eye.analyser_transmittance_along, eye.analyser_transmittance_across = 90.0, 0.9, 0.01
    scene.hud.polarisation = "auto"
    drawn = {}
    for panel, ctx in (("eye", types.SimpleNamespace(camera=scene.camera.data, scene=scene)),
                       ("render", types.SimpleNamespace(scene=scene)),
                       *((name, types.SimpleNamespace(object=obj)) for name, obj in (("lcd", lcd), *extras.items()))):
        names = drawn[panel] = []
        cls = {"eye": ui_mod.HUD_PT_eye, "render": ui_mod.HUD_PT_render}.get(panel, ui_mod.HUD_PT_object)
        cls.draw(types.SimpleNamespace(layout=_PropLayout(names)), ctx)
    bpy.ops.hud.export_scene(directory=str(out / "pol"))
    scene.hud.polarisation = "off"
    try:
        bpy.ops.hud.export_scene(directory=str(out / "off"))
        refused = None
    except RuntimeError as e:  # the operator's report
        refused = str(e)
    load_scene = sys.modules[f"{module}.tracer.scene"].load_scene
    scene_error = sys.modules[f"{module}.tracer.core.errors"].SceneError
    in_blender_terms = []  # what an F12 render says (the engine's export, then blender_terms)
    for _ in range(2):
        export_mod.export_scene(bpy.context.evaluated_depsgraph_get(), out / "off_unchecked")
        try:
            load_scene(out / "off_unchecked")
            in_blender_terms.append(None)
        except scene_error as e:
            in_blender_terms.append(messages_mod.blender_terms(e, out / "off_unchecked", scene))
        # The next element that needs polarisation, once these are off: the retarder film.
        eye.analyser_use = lcd.hud.polariser_use = led.hud.emission_polarisation_use = False
    lcd_name = lcd.name
    for obj in extras.values():
        bpy.data.objects.remove(obj)
    scene.hud.polarisation = "off"  # build_scene sets it back
    build_mod.build_scene(out / "pol", bpy.context)
    cam = scene.camera.data.hud
    by_name = {o.name: o for o in scene.objects}
    built = {"polarisation": scene.hud.polarisation,
             "analyser": [cam.analyser_use, cam.analyser_axis_deg, cam.analyser_transmittance_along,
                          cam.analyser_transmittance_across],
             "lcd": [by_name[lcd_name].hud.polariser_use, by_name[lcd_name].hud.polariser_axis_deg],
             "film": [by_name["film"].hud.role, by_name["film"].hud.axis_deg, by_name["film"].hud.retardance_deg],
             "splitter": [by_name["splitter"].hud.by, list(by_name["splitter"].hud.reflectance_p)],
             "metal": [by_name["metal"].hud.metal_use, list(by_name["metal"].hud.metal_complex_ior)]}
    presets = sys.modules[f"{module}.presets"].PRESETS
    sunglasses = None
    if "hud-direct-s-sunglasses" in presets:
        folder = presets["hud-direct-s-sunglasses"].write(out / "sunglasses")
        bpy.ops.hud.add_preset(preset="hud-direct-s-sunglasses")
        cam = scene.camera.data.hud
        raw = json.loads((Path(folder) / "scene.json").read_text())
        sunglasses = {"analyser": raw["eye"].get("analyser"), "raw_polarisation": raw.get("polarisation", "auto"),
                      "built": {"use": cam.analyser_use, "axis_deg": cam.analyser_axis_deg,
                                "transmittance_along": cam.analyser_transmittance_along,
                                "transmittance_across": cam.analyser_transmittance_across},
                      "polarisation": scene.hud.polarisation}
    items = [(i.identifier, i.description) for i in scene.hud.bl_rna.properties["polarisation"].enum_items]
    disable(module)
    return {"drawn": drawn, "refused": refused, "in_blender_terms": in_blender_terms, "built": built,
            "sunglasses": sunglasses, "lcd": lcd_name, "items": items}


def test_polarisation_in_blender_eye_analyser_mode_and_polarising_materials(tmp_path):
    """The polarisation of scene.json in Blender: the eye's analyser (HUD Eye > Analyser, from
    tracer.scene.ANALYSER) and the scene's Polarisation mode (HUD Tracer render settings) export as
    eye.analyser and "polarisation"; the polarising materials come from their schemas by themselves (a
    retarder role, the LCD's output polariser group, a coating given for s and p light, a metal mirror,
    polarised emission): drawn, exported, loaded by the tracer and built back by Add HUD Preset. With
    Polarisation Off the export is refused in Blender's terms."""
    res, _ = in_blender(scenario_polarisation, tmp_path)
    from tracer.scene import ANALYSER, POLARISATION_MODES, load_scene

    # Panels: the analyser's toggle and fields, the mode, every new material field.
    assert res["drawn"]["eye"][-4:] == ["analyser_use", "analyser_axis_deg_shown", "analyser_transmittance_along",
                                        "analyser_transmittance_across"]
    assert "polarisation" in res["drawn"]["render"]
    assert {"polariser_use", "polariser_axis_deg_shown"} <= set(res["drawn"]["lcd"])
    assert {"transmittance_grey", "axis_deg_shown", "retardance_deg_shown"} <= set(res["drawn"]["film"])
    assert {"by", "reflectance_s_grey", "transmittance_p_grey"} <= set(res["drawn"]["splitter"])
    # the alternative not chosen is hidden
    assert not {"reflectance", "reflectance_grey"} & set(res["drawn"]["splitter"])
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


class _LabelLayout(_PropLayout):
    """Records (property, label text) of every row drawn."""

    def prop(self, owner, name, **kw):
        self.names.append((name, kw.get("text")))

    def __getattr__(self, name):
        if name in ("column", "row", "box", "grid_flow"):
            return lambda *a, **k: _LabelLayout(self.names)
        return lambda *a, **k: None


def scenario_role_fields():
    """A Lambertian panel that emits, drawn in the HUD Optical Role panel: the rows and their labels, and
    the tooltip of Reflectance (one property that the mirror, the coating and the Lambertian roles share)."""
    import bpy

    from tests.support.blender import disable, enable_from_source

    module = enable_from_source(bpy, Path(tempfile.mkdtemp()))
    bpy.ops.mesh.primitive_plane_add(size=10)
    obj = bpy.context.object
    obj.hud.role, obj.hud.emits = "lambertian", True
    rows = []

    class Panel:
        layout = _LabelLayout(rows)

    sys.modules[f"{module}.hud_addon.ui"].HUD_PT_object.draw(Panel(), bpy.context)
    tooltip = obj.hud.bl_rna.properties["reflectance"].description
    disable(module)
    return {"rows": rows, "tooltip": tooltip}


def test_a_role_s_fields_say_what_they_mean_for_it_and_their_units():
    """Issue 31's walk-through: a Lambertian surface's Reflectance read "Specular reflectance (at normal
    incidence for a metal)" (the mirror's meaning of the shared property), and Emission's luminance
    showed no unit. The tooltip now gives each role's meaning, the Lambertian's albedo among them, and
    rows with a unit show it beside the name."""
    res, _ = in_blender(scenario_role_fields)
    tip = res["tooltip"]
    assert "Lambertian reflector: diffuse albedo" in tip and "Mirror: " in tip, tip
    labels = dict(res["rows"])
    assert labels.get("emission_luminance") == "Luminance (cd/m²)", res["rows"]


def scenario_lamp_and_factors(out):
    """Add Lamp (80 x 40 mm, 4,000 cd/m²) and a plane mirror whose Reflectance is set through its number
    field (0.5): the mirror's panel rows before and after the colour button, a preset's tinted
    reflectance applied, and the scene exported to ``out`` with a camera."""
    import bpy

    from tests.support.blender import disable, enable_from_source

    module = enable_from_source(bpy, Path(tempfile.mkdtemp()))
    schema_ui = sys.modules[f"{module}.hud_addon.schema_ui"]
    materials = sys.modules[f"{module}.tracer.optics.materials"]
    bpy.ops.wm.read_homefile(use_empty=True)
    bpy.ops.object.camera_add(location=(0.0, 0.0, 1.0))
    bpy.context.scene.camera = bpy.context.object
    bpy.ops.hud.add_lamp(size_mm=(80.0, 40.0), luminance=4000.0)
    lamp = bpy.context.object
    bpy.ops.mesh.primitive_plane_add(size=0.2, location=(0.0, 0.3, 0.0))
    mirror = bpy.context.object
    mirror.name, mirror.hud.role = "mirror", "mirror"
    mirror.hud.reflectance_grey = 0.5
    res = {"lamp": [lamp.name, lamp.hud.role, lamp.hud.emits, lamp.hud.emission_luminance],
           "reflectance": list(mirror.hud.reflectance)}

    def rows_of(obj):
        rows = []

        class Panel:
            layout = _LabelLayout(rows)

        bpy.context.view_layer.objects.active = obj
        sys.modules[f"{module}.hud_addon.ui"].HUD_PT_object.draw(Panel(), bpy.context)
        return rows

    res["rows_number"] = rows_of(mirror)
    mirror.hud.reflectance_per_channel = True
    res["rows_colour"] = rows_of(mirror)
    mirror.hud.reflectance_per_channel = False
    bpy.ops.hud.export_scene(directory=str(Path(out) / "scene"))
    schema_ui.apply(mirror.hud, materials.MATERIALS["mirror"].schema.fields, {"reflectance": [0.9, 0.5, 0.5]})
    res["tinted"] = [mirror.hud.reflectance_per_channel, list(mirror.hud.reflectance)]
    schema_ui.apply(mirror.hud, materials.MATERIALS["mirror"].schema.fields, {"reflectance": 0.3})
    res["grey"] = [mirror.hud.reflectance_per_channel, mirror.hud.reflectance_grey]
    disable(module)
    return res


def test_a_factor_is_a_number_and_a_lamp_is_one_button(tmp_path):
    """Issue 31's walk-through: scalar reflectances and transmittances were colour swatches, and a lamp was
    made by choosing "Absorber" and ticking Emits light. A factor's row is now a number (its colour button
    gives R, G and B apart; a preset's tinted value opens it), and Add Lamp makes a rectangle that emits
    from its +Z face: exported and loaded, 80 x 40 mm of absorber at 4,000 cd/m², beside a mirror of
    reflectance 0.5 set through the number."""
    from tracer.scene import load_scene

    res, _ = in_blender(scenario_lamp_and_factors, tmp_path)
    number, colour = ([tuple(r) for r in res[k]] for k in ("rows_number", "rows_colour"))
    assert res["lamp"][1:] == ["absorber", True, 4000.0]
    assert res["reflectance"] == pytest.approx([0.5] * 3)
    assert ("reflectance_grey", "Reflectance") in number and ("reflectance", "Reflectance") not in number, number
    assert {("reflectance", "Reflectance"), ("reflectance_per_channel", "")} <= set(colour)
    assert res["tinted"][0] is True and res["tinted"][1] == pytest.approx([0.9, 0.5, 0.5])
    assert res["grey"][0] is False and res["grey"][1] == pytest.approx(0.3)
    scene = load_scene(tmp_path / "scene")
    lamp = scene.object(res["lamp"][0])
    assert next(o for o in scene.raw["objects"] if o["name"] == lamp.name)["material"]["type"] == "absorber"
    a, b, c = lamp.triangles[0]
    normal = np.cross(b - a, c - a)  # the emitting face toward +Z
    assert not lamp.emission.two_sided and normal[2] > 0 and np.allclose(normal[:2], 0.0)
    assert lamp.emission.luminance == pytest.approx(4000.0) and lamp.area_mm2 == pytest.approx(80.0 * 40.0, rel=1e-6)
    mirror = next(o for o in scene.raw["objects"] if o["name"] == "mirror")
    assert np.allclose(mirror["material"]["reflectance"], 0.5)


def scenario_every_preset(out):
    """Every preset added with Add HUD Preset (into a fresh file each) and exported again."""
    import bpy

    from tests.support.blender import disable, enable_from_source

    module = enable_from_source(bpy, Path(tempfile.mkdtemp()))
    export_mod = sys.modules[f"{module}.hud_addon.export"]
    presets = sys.modules[f"{module}.presets"].PRESETS
    refused = {}
    for name, p in presets.items():
        bpy.ops.wm.read_homefile(use_empty=True)
        p.write(Path(out) / "given" / name)
        bpy.ops.hud.add_preset(preset=name)
        try:
            export_mod.export_scene(bpy.context.evaluated_depsgraph_get(), Path(out) / "exported" / name)
        except Exception as e:  # noqa: BLE001 - the test names the preset and the message
            refused[name] = f"{type(e).__name__}: {e}"
    disable(module)
    return {"names": list(presets), "refused": refused}


def test_every_preset_added_in_blender_exports_the_materials_it_was_given(tmp_path):
    """Add HUD Preset then export, for every preset: the export loads, and every material and emission
    field the preset gives comes back with its value. Materials share their Blender properties by name
    (one "reflectance" for every material that has one), and a field a preset does not give kept
    another material's default: hud-screen's screen (a Lambertian transmitter, tau 0.7, no reflectance)
    exported the Lambertian reflector's reflectance and was refused, "reflectance + transmittance must
    not exceed 1", so hud-screen could not be rendered from Blender at all."""
    res, _ = in_blender(scenario_every_preset, tmp_path)
    from tracer.scene import load_scene

    assert res["refused"] == {}, res["refused"]
    assert len(res["names"]) >= 10
    for name in res["names"]:
        load_scene(tmp_path / "exported" / name)
        given = {o["name"]: o for o in json.loads((tmp_path / "given" / name / "scene.json").read_text())["objects"]}
        out = {o["name"]: o for o in json.loads((tmp_path / "exported" / name / "scene.json").read_text())["objects"]}
        for obj, spec in given.items():
            assert obj in out, (name, obj)
            for block in ("material", "emission"):
                for key, value in (spec.get(block) or {}).items():
                    if isinstance(value, (int, float)) and not isinstance(value, bool):
                        back = out[obj][block][key]
                        back = back[0] if isinstance(back, list) and len(set(back)) == 1 else back
                        assert back == pytest.approx(value, rel=1e-6), (name, obj, block, key, value, back)
                    elif isinstance(value, str) and key == "type":
                        assert out[obj][block][key] == value, (name, obj, key)
