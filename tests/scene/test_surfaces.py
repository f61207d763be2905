"""Reading exact surfaces (tracer/scene/surfaces.py): faces go to the surface their corners lie on, and
every bad surface block is refused with the file and the field."""

import json

import numpy as np
import pytest

from tests.support.scenes import edit_json, plate_scene, sphere_mirror_scene
from tracer.core.errors import SceneError
from tracer.scene import load_scene


def _surfaces(value, obj=0):
    return lambda d: d["objects"][obj].__setitem__("surfaces", value)


def test_a_plates_faces_go_to_its_two_planes(tmp_path):
    """A box's top (z = +t/2) and bottom (z = -t/2) faces belong to two planes; its sides to neither."""
    folder = plate_scene(tmp_path / "plate")
    edit_json(folder, _surfaces([{"type": "plane", "origin": [0, 0, 2.38]},
                                 {"type": "plane", "origin": [0, 0, -2.38], "axis": [0, 0, -1]}]))
    plate = load_scene(folder).objects[0]
    top, bottom = plate.surfaces
    assert len(top.faces) == 2 and len(bottom.faces) == 2 and not set(top.faces) & set(bottom.faces)
    normal = np.cross(plate.local_x, plate.local_y)  # the plate's local z in the world
    centre = plate.vertices.mean(axis=0)
    height = lambda faces: (plate.vertices[plate.faces[faces]].mean(axis=1) - centre) @ normal  # noqa: E731
    np.testing.assert_allclose(height(top.faces), 2.38, atol=1e-6)
    np.testing.assert_allclose(height(bottom.faces), -2.38, atol=1e-6)
    assert top.gap_mm.max() < 1e-9 and bottom.gap_mm.max() < 1e-9


BAD = {
    "not a list": ({"type": "sphere"}, "objects[0].surfaces", "expected a list"),
    "unknown type": ([{"type": "torus"}], "objects[0].surfaces[0].type", "expected one of"),
    "missing radius": ([{"type": "sphere"}], "objects[0].surfaces[0].radius_mm", "missing"),
    "radius too small": ([{"type": "sphere", "radius_mm": 0.01}], "objects[0].surfaces[0].radius_mm", "at least 0.1"),
    "wrong radius": ([{"type": "sphere", "radius_mm": 400}], "objects[0].surfaces[0]", "no face of meshes/mirror.obj"),
    "x axis along the axis": ([{"type": "sphere", "radius_mm": 500, "x_axis": [0, 0, 2]}],
                              "objects[0].surfaces[0].x_axis", "parallel"),
    "zero axis": ([{"type": "sphere", "radius_mm": 500, "axis": [0, 0, 0]}], "objects[0].surfaces[0].axis",
                  "zero vector"),
    "unknown field": ([{"type": "sphere", "radius_mm": 500, "curvature": 1}], "objects[0].surfaces[0].curvature",
                      "unknown field"),
    "terms not pairs": ([{"type": "xy_polynomial", "terms": [[2, 0]]}], "objects[0].surfaces[0].terms[0]",
                        "expected [i, j, a_ij]"),
    "term of order 0": ([{"type": "xy_polynomial", "terms": [[0, 0, 1.0]]}], "objects[0].surfaces[0].terms[0]",
                        "i + j"),
    "fractional exponent": ([{"type": "xy_polynomial", "terms": [[1.5, 0, 1.0]]}],
                            "objects[0].surfaces[0].terms[0]", "integers"),
    "vertex off the mesh": ([{"type": "sphere", "radius_mm": 500, "origin": [0, 0, 1]}], "objects[0].surfaces[0]",
                            "corners lie 0.988 mm from it"),
}


@pytest.mark.parametrize("case", BAD)
def test_bad_surfaces_name_the_field(tmp_path, case):
    value, field, words = BAD[case]
    folder = sphere_mirror_scene(tmp_path / "m")
    edit_json(folder, _surfaces(value))
    with pytest.raises(SceneError) as e:
        load_scene(folder)
    assert e.value.field == field, str(e.value)
    assert words in str(e.value)
    assert "scene.json" in str(e.value)


def test_emitters_and_untraced_objects_take_no_surfaces(tmp_path):
    folder = plate_scene(tmp_path / "plate")
    data = json.loads((folder / "scene.json").read_text())
    names = [o["name"] for o in data["objects"]]
    for name, words in (("emitter", "emitting"), ("eye_image", "not traced")):
        k = names.index(name)
        edit_json(folder, _surfaces([{"type": "plane"}], k))
        with pytest.raises(SceneError, match=words) as e:
            load_scene(folder)
        assert e.value.field == f"objects[{k}].surfaces"
        edit_json(folder, _surfaces([], k))
