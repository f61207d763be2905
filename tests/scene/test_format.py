"""The scene format's reference (docs/user/scene-format.md) against the schemas it is generated from:
current, its minimal scene loads and renders the luminance it emits, and the loader accepts exactly the
fields the reference lists in every block."""

import importlib.util
import json
import re

import numpy as np
import pytest

from tests.support.paths import ROOT
from tracer.core.errors import SceneError
from tracer.core.units import luminance
from tracer.methods import INTEGRATORS, Budget
from tracer.scene import format as fmt
from tracer.scene import load_scene

_SPEC = importlib.util.spec_from_file_location("scene_format", ROOT / "tools" / "scene_format.py")
scene_format = importlib.util.module_from_spec(_SPEC)
_SPEC.loader.exec_module(scene_format)


def test_the_reference_is_what_the_schemas_give():
    """A schema changed without `python tools/scene_format.py` fails here."""
    assert scene_format.PAGE.read_text() == scene_format.page(), "docs/user/scene-format.md is stale: run " \
                                                                 "python tools/scene_format.py"


def _minimal_scene_from_the_page(folder):
    """The page's own minimal scene: its JSON and OBJ blocks written into ``folder``."""
    text = scene_format.PAGE.read_text()
    section = text[text.index("## A minimal complete scene"):text.index("## Top level")]
    scene_json, mesh = re.findall(r"```(?:json)?\n(.*?)```", section, re.S)
    (folder / "meshes").mkdir(parents=True)
    (folder / "scene.json").write_text(scene_json)
    (folder / "meshes" / "panel.obj").write_text(mesh)
    return folder


def test_the_minimal_scene_renders_the_luminance_it_emits(tmp_path):
    """The panel emits 1000 cd/m^2 from its front side, which its transform turns toward the eye: the
    pixels inside its image read 1000 cd/m^2 (to the float32 rounding of the sample weights: backward
    tracing hits the emitter directly), those outside 0; turned away (rotated -90 deg instead), it is dark."""
    folder = _minimal_scene_from_the_page(tmp_path / "panel")
    scene = load_scene(folder)
    y = luminance(INTEGRATORS["backward"](scene, 1).render(Budget(rays=200_000)).film.rgb())
    h, w = y.shape
    # The panel spans +-50 mm at 500 mm: +-5.7 deg of the 16 x 12 deg view, so +-23 of 64 columns.
    inside = y[h // 2 - 10:h // 2 + 10, w // 2 - 20:w // 2 + 20]
    np.testing.assert_allclose(inside, 1000.0, rtol=1e-3)
    assert abs(inside.mean() - 1000.0) < 0.01
    assert np.all(y[:, :4] == 0) and np.all(y[:, -4:] == 0)
    raw = json.loads((folder / "scene.json").read_text())
    raw["objects"][0]["transform"]["rotate_deg"] = [-90, 0, 0]
    (folder / "scene.json").write_text(json.dumps(raw))
    dark = INTEGRATORS["backward"](load_scene(folder), 1).render(Budget(rays=100_000))
    assert dark.film.rgb().max() == 0


def _allowed(folder, edit) -> set[str]:
    """The fields the loader's refusal of an unknown one lists, after ``edit(raw)`` adds it."""
    raw = json.loads((folder / "scene.json").read_text())
    edit(raw)
    (folder / "scene.json").write_text(json.dumps(raw))
    with pytest.raises(SceneError, match="unknown field") as e:
        load_scene(folder)
    return set(re.search(r"\(allowed: (.*)\)", str(e.value))[1].split(", "))


@pytest.mark.parametrize("block", ["top", "eye", "object", "transform", "aim", "none", "uniform", "hdri", "sun"])
def test_the_loader_accepts_exactly_the_fields_the_reference_lists(tmp_path, block):
    folder = _minimal_scene_from_the_page(tmp_path / block)
    keys = {
        "top": (fmt.TOP, lambda r: r.update(colour=1)),
        "eye": (fmt.EYE, lambda r: r["eye"].update(colour=1)),
        "object": (fmt.OBJECT, lambda r: r["objects"][0].update(colour=1)),
        "transform": (fmt.TRANSFORM_PARTS, lambda r: r["objects"][0]["transform"].update(colour=1)),
        "aim": (fmt.AIM, lambda r: r["objects"][0]["emission"].update(aim={"target": "eye", "colour": 1})),
        "none": (fmt.ENVIRONMENTS["none"], lambda r: r.update(environment={"type": "none", "colour": 1})),
        "uniform": (fmt.ENVIRONMENTS["uniform"],
                    lambda r: r.update(environment={"type": "uniform", "luminance": 1, "colour": 1})),
        "hdri": (fmt.ENVIRONMENTS["hdri"], lambda r: r.update(environment={
            "type": "hdri", "file": "sky.exr", "calibration": {"mode": "scale", "value": 1}, "colour": 1})),
        "sun": (fmt.SUN, lambda r: r.update(environment={"type": "none", "sun": {"direction": [0, 0, 1],
                                                                                 "colour": 1}})),
    }
    schema, edit = keys[block]
    required, optional = schema.keys
    extra = {"type"} if block in fmt.ENVIRONMENTS else set()
    assert _allowed(folder, edit) == required | optional | extra
