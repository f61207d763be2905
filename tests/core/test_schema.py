"""Parsing a field's JSON value by its schema (tracer/core/schema.py): a factor (a field in [0, 1]: a
transmittance, a reflectance) is 0 or at least MIN_FACTOR, in every component of an RGB one, whether
given as one number or as [r, g, b]; below it the float32 path weights underflow and the image comes out
black. The refusal names the file and the field (and the component of a list)."""

import json

import numpy as np
import pytest

from tests.support.cli import assert_one_line_error, run_cli
from tests.support.scenes import edit_json
from tracer.core.errors import SceneError
from tracer.core.schema import parse_value
from tracer.core.validate import MIN_FACTOR, FieldChecker
from tracer.optics.materials import MATERIALS
from tracer.scene import load_scene
from tracer.sources.lights import EMISSION

#: Values of an RGB factor below the floor: (JSON value, the field's suffix in the message, its words).
UNDERFLOWING = {
    "one number": (1e-300, "", "1e-300 is below 1e-09"),
    "a list": ([1e-300, 1e-300, 1e-300], "[0]", "1e-300 (red) is below 1e-09"),
    "one channel of a list": ([0.05, 1e-300, 0.05], "[1]", "1e-300 (green) is below 1e-09"),
    "just below the floor": ([0.5, 0.5, MIN_FACTOR / 2], "[2]", "(blue) is below 1e-09"),
}


def _parse(material: str, name: str, value):
    f = MATERIALS[material].schema.field(name)
    return parse_value(FieldChecker("scene.json"), f, value, f"objects[3].material.{name}", None, {})


@pytest.mark.parametrize("form", sorted(UNDERFLOWING))
@pytest.mark.parametrize("material, name", [("lcd", "transmittance"), ("mirror", "reflectance")])
def test_an_rgb_factor_below_the_floor_is_refused(material, name, form):
    """Before: 1e-300 was refused in a number field (an analyser's transmittance) but loaded in an RGB
    one, as a number or a list, and rendered an all-black image (exit 3)."""
    value, suffix, words = UNDERFLOWING[form]
    with pytest.raises(SceneError) as e:
        _parse(material, name, value)
    assert e.value.file == "scene.json" and e.value.field == f"objects[3].material.{name}{suffix}"
    assert words in e.value.message and "give 0 or at least that" in e.value.message


@pytest.mark.parametrize("value", [0.0, [0.0, 0.0, 0.0], [0.0, 0.5, 0.9], MIN_FACTOR, [MIN_FACTOR, 1.0, 0.0], 1.0])
def test_an_rgb_factor_of_zero_or_at_least_the_floor_is_kept(value):
    """0 (no light passes) stays allowed, as in a number field; the floor itself is a factor."""
    np.testing.assert_array_equal(_parse("mirror", "reflectance", value), np.broadcast_to(value, 3))


def test_only_factors_have_the_floor():
    """The floor is for factors: an emission's colour (in [0, 1e6], normalised to unit luminance) keeps
    its own range."""
    colour = EMISSION.field("color")
    out = parse_value(FieldChecker("scene.json"), colour, [1.0, 1e-300, 1.0], "objects[2].emission.color", None, {})
    assert out[1] == 1e-300


def _object_index(folder, name: str) -> int:
    names = [o["name"] for o in json.loads((folder / "scene.json").read_text())["objects"]]
    return names.index(name)


@pytest.mark.parametrize("form", ["one number", "a list"])
@pytest.mark.parametrize("obj, name", [("lcd", "transmittance"), ("mirror", "reflectance")])
def test_hud_direct_with_an_underflowing_rgb_factor_is_refused_at_load(preset, obj, name, form):
    """The walk-through's case: hud-direct's LCD transmittance or mirror reflectance set to 1e-300 loaded
    and rendered black. Now load_scene refuses it, naming scene.json and the object's field."""
    folder = preset("hud-direct")
    k = _object_index(folder, obj)
    value, suffix, words = UNDERFLOWING[form]
    edit_json(folder, lambda d: d["objects"][k]["material"].__setitem__(name, value))
    with pytest.raises(SceneError) as e:
        load_scene(folder)
    assert e.value.file.endswith("scene.json") and e.value.field == f"objects[{k}].material.{name}{suffix}"
    assert words in e.value.message


@pytest.mark.parametrize("form", ["one number", "a list"])
def test_the_command_line_refuses_it_before_any_ray(preset, tmp_path, form):
    """Through ``hud-trace render``: exit 2, one line naming the file and the field, nothing written."""
    folder = preset("hud-direct")
    k = _object_index(folder, "mirror")
    value, suffix, _ = UNDERFLOWING[form]
    edit_json(folder, lambda d: d["objects"][k]["material"].__setitem__("reflectance", value))
    out = tmp_path / "out"
    code, err = run_cli("render", folder, "--rays", 10**12, "--workers", 1, "--quiet", "--out", out)
    assert_one_line_error(code, err, "scene.json", f"objects[{k}].material.reflectance{suffix}", "below 1e-09")
    assert not out.exists()
