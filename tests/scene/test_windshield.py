"""Windshields from parameters (tracer/scene/windshield.py) and the target image block: closed glass
shells whose two exact surfaces have the thickness, wedge and curvature asked for, and bad blocks
refused with the file and the field."""

import math

import numpy as np
import pytest
import trimesh

from tests.support import imaging
from tests.support.scenes import edit_json
from tracer.core.errors import SceneError
from tracer.scene import load_scene


def _glass(folder):
    return load_scene(folder).object("plate")


def _windshield(**fields):
    return lambda d: d["objects"][0]["windshield"].update(fields)


def _local(obj, p):
    """Points (n, 3) in the windshield's own frame (its inner surface's tangent plane at z = 0)."""
    z = np.cross(obj.local_x, obj.local_y)
    origin = _inner_origin(obj)
    return np.stack([(p - origin) @ obj.local_x, (p - origin) @ obj.local_y, (p - origin) @ z], 1)


def _inner_origin(obj):
    return np.linalg.inv(obj.surfaces[0].to_local)[:3, 3]


def test_a_flat_windshield_is_a_closed_plate_with_its_two_planes(tmp_path):
    glass = _glass(imaging.plate(tmp_path / "p"))
    mesh = trimesh.Trimesh(glass.vertices, glass.faces, process=False)
    assert mesh.is_watertight and mesh.is_winding_consistent and mesh.volume > 0
    assert mesh.volume == pytest.approx(600 * 600 * 4.76, rel=1e-9)
    inner, outer = glass.surfaces
    assert inner.type == "plane" and outer.type == "plane"
    assert len(inner.faces) == 2 and len(outer.faces) == 2
    assert inner.gap_mm.max() < 1e-9 and outer.gap_mm.max() < 1e-9


def test_a_wedge_thickens_the_glass_along_its_direction(tmp_path):
    """0.5 mrad toward the top: 4.76 mm + 0.5e-3 s at height s, the same across."""
    glass = _glass(imaging.plate(tmp_path / "p", wedge_mrad=0.5))
    q = _local(glass, glass.vertices)
    outer = q[:, 2] < -1.0
    np.testing.assert_allclose(-q[outer, 2], 4.76 + math.tan(0.5e-3) * q[outer, 1], atol=1e-6)
    _, sv, vt = np.linalg.svd(q[outer] - q[outer].mean(axis=0))
    assert math.degrees(math.acos(abs(vt[2, 2]))) * 60 == pytest.approx(0.5e-3 * 180 / math.pi * 60, rel=1e-6)


def test_a_wedge_along_x(tmp_path):
    folder = imaging.plate(tmp_path / "p", wedge_mrad=0.5)
    edit_json(folder, _windshield(wedge_direction_deg=0.0))
    q = _local(g := _glass(folder), g.vertices)
    outer = q[:, 2] < -1.0
    np.testing.assert_allclose(-q[outer, 2], 4.76 + math.tan(0.5e-3) * q[outer, 0], atol=1e-6)


def test_a_curved_windshield_is_a_biconic_shell_of_even_thickness(tmp_path):
    """Radii 4000 across and 8000 up: the inner surface's sag at the outline's corners, concentric outer
    radii 4004.76 and 8004.76 (a biconic), and the facets within 0.02 mm of the surface."""
    folder = imaging.plate(tmp_path / "p")
    edit_json(folder, _windshield(radius_x_mm=4000.0, radius_y_mm=8000.0))
    glass = _glass(folder)
    inner, outer = glass.surfaces
    assert (inner.type, outer.type) == ("biconic", "biconic")
    assert inner.params["radius_x_mm"] == 4000.0 and outer.params["radius_y_mm"] == pytest.approx(8004.76)
    mesh = trimesh.Trimesh(glass.vertices, glass.faces, process=False)
    assert mesh.is_watertight and mesh.volume > 0
    q = _local(glass, glass.vertices)
    corner = np.argmax(q[:, 0] + q[:, 1])
    x, y = q[corner, 0], q[corner, 1]
    cx, cy = 1 / 4000, 1 / 8000  # the biconic's sag (OpticStudio's Biconic surface, conic constants 0)
    sag = (cx * x * x + cy * y * y) / (1 + math.sqrt(1 - cx * cx * x * x - cy * cy * y * y))
    assert q[corner, 2] == pytest.approx(sag, abs=1e-6)  # toward the driver: concave seen from inside
    assert inner.gap_mm.max() < 0.02 and outer.gap_mm.max() < 0.02


BAD = {
    "mesh and windshield": (lambda d: d["objects"][0].__setitem__("mesh", "x.obj"), "objects[0]", "exactly one"),
    "not glass": (lambda d: d["objects"][0].__setitem__("material", {"type": "mirror", "reflectance": 1.0}),
                  "objects[0].material.type", "a windshield is glass"),
    "own surfaces": (lambda d: d["objects"][0].__setitem__("surfaces", [{"type": "plane"}]), "objects[0].surfaces",
                     "its own surfaces"),
    "no size": (lambda d: d["objects"][0]["windshield"].pop("size_mm"), "objects[0].windshield.size_mm", "missing"),
    "radius below half the size": (_windshield(radius_x_mm=200.0), "objects[0].windshield.radius_x_mm",
                                   "at least half the size"),
    "wedge that thins to nothing": (_windshield(wedge_mrad=-40.0), "objects[0].windshield", "thickness reaches 0"),
    "unknown field": (_windshield(wedge=1.0), "objects[0].windshield.wedge", "unknown field"),
    "target pgu unknown": (lambda d: d.__setitem__("target", {"pgu": "lcd"}), "target.pgu", "no object named"),
    "target requirement": (lambda d: d.__setitem__("target", {"requirements": ["design_eye.vid_mm >> 3"]}),
                           "target.requirements[0]", ""),
    "target eyebox": (lambda d: d.__setitem__("target", {"eyebox_mm": [130.0]}), "target.eyebox_mm", ""),
    "target forward up": (lambda d: d.__setitem__("target", {"forward": [0, 0, 2]}), "target.forward", "parallel"),
}


@pytest.mark.parametrize("case", BAD)
def test_bad_windshields_and_targets_name_the_field(tmp_path, case):
    edit, field, words = BAD[case]
    folder = imaging.plate(tmp_path / "p")
    edit_json(folder, edit)
    with pytest.raises(SceneError) as e:
        load_scene(folder)
    assert e.value.field == field, str(e.value)
    assert words in str(e.value)
    assert "scene.json" in str(e.value)
