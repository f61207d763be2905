"""Binocular renders (tracer/scene/binocular.py, ``hud-trace render --eye``): each eye of a pair sits IPD / 2
to its side across the vehicle's forward direction, and the image it renders is displaced by the vergence
angle the optical analysis reports for that pair."""

import math

import numpy as np
import pytest

from tests.support import imaging
from tests.support.cli import run_cli
from tracer.analysis.optics import analyse
from tracer.core.units import Y_WEIGHTS
from tracer.methods import INTEGRATORS, Budget
from tracer.scene import load_scene
from tracer.scene.binocular import eye_for, right_axis
from tracer.transport.eye import ThinLensEye
from tracer.transport.world import World


def test_the_eyes_sit_half_the_ipd_to_either_side(tmp_path):
    scene = load_scene(imaging.plane_mirror(tmp_path / "p", target={"ipd_mm": 60.0}))
    np.testing.assert_allclose(right_axis(scene), [1.0, 0.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(eye_for(scene, "left").position, [-30.0, 0.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(eye_for(scene, "right").position, [30.0, 0.0, 0.0], atol=1e-12)
    assert eye_for(scene, "centre") is scene.eye
    with pytest.raises(ValueError, match="one of centre, left, right"):
        eye_for(scene, "middle")


def _centroid_column(scene, side) -> float:
    world = World(scene, ThinLensEye(eye_for(scene, side)))
    film = INTEGRATORS["backward"](world, 1).render(Budget(rays=400_000)).film
    y = film.rgb() @ Y_WEIGHTS
    cols = np.arange(y.shape[1])
    return float((y.sum(axis=0) * cols).sum() / y.sum())


def test_each_eye_sees_the_image_displaced_by_the_reported_vergence_angle(tmp_path):
    """The panel 1000 mm away: the right eye sees it further left than the left eye does, by the
    centre pair's vergence angle (2 atan(IPD / 2D) = 65 mrad, 18.6 pixels of 3.5 mrad), within a pixel."""
    scene = load_scene(imaging.plane_mirror(tmp_path / "p", target={"field_grid": [3, 3]}))
    doc = analyse(scene, spot=False, compare_mesh=False)
    pair = next(p for p in doc["pairs"] if p["midpoint_mm"] == [0.0, 0.0])
    angle_mrad = pair["vergence_angle_mrad"][4]  # the centre of the 3 x 3 field
    shift = _centroid_column(scene, "left") - _centroid_column(scene, "right")
    eye = scene.eye
    pixel_mrad = 2 * math.tan(math.radians(eye.fov_deg[0]) / 2) / eye.resolution[0] * 1e3
    assert shift * pixel_mrad == pytest.approx(angle_mrad, abs=pixel_mrad)


def test_eye_both_writes_two_sets_and_their_previews_side_by_side(tmp_path):
    folder = imaging.plane_mirror(tmp_path / "p")
    code, err = run_cli("render", str(folder), "--method", "backward", "--rays", "200000", "--eye", "both",
                        "--workers", "1", "--quiet", "--out", str(tmp_path / "out"))
    assert code == 0, err
    for side in ("left", "right"):
        assert {p.name for p in (tmp_path / "out" / side).iterdir()} == {"image.exr", "preview.png", "report.json"}
    from tracer.core.imageio import read_image

    both = read_image(tmp_path / "out" / "both.png")
    left = read_image(tmp_path / "out" / "left" / "preview.png")
    assert both.shape[1] == 2 * left.shape[1] + 4 and both.shape[0] == left.shape[0]


def test_a_binocular_renders_optics_block_is_the_design_eye_points(tmp_path):
    """--eye left renders from the left eye, but report.json's optics block analyses the scene's own eye
    (the design eye point), as hud-trace optics does; image.eye says which eye rendered."""
    from tracer.products.render import render_scene

    folder = imaging.plane_mirror(tmp_path / "p", target={"eye_grid": [3, 1]})
    scene = load_scene(folder)
    report, _ = render_scene(scene, "backward", Budget(rays=100_000), 1, tmp_path / "left", eye="left")
    assert report["image"]["eye"]["side"] == "left"
    np.testing.assert_allclose(report["image"]["eye"]["position_mm"], [-32.5, 0.0, 0.0], atol=1e-9)
    own = analyse(scene, spot=False, compare_mesh=False)["summary"]["design_eye"]
    assert report["optics"]["design_eye"]["look_over_deg"] == pytest.approx(own["look_over_deg"], abs=1e-9)
    assert report["optics"]["design_eye"]["vid_mm"] == pytest.approx(own["vid_mm"], rel=1e-9)
