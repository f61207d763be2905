"""The thin-lens eye (tracer.transport.eye): the pixel extent for the smallest pupil and the farthest focus,
a panel rendering its luminance through a pinhole or at a far focus, and the focus and blur of a point."""

import math

import numpy as np
import pytest

from presets._build import SceneBuilder, frame_matrix, rectangle
from tests.support.render import render
from tests.support.scenes import edit_json, panel_in_view


def test_the_pixel_extent_holds_for_the_smallest_pupil_and_the_farthest_focus():
    """The pixel extent is a disk's view factor, F = (1/2) [1 - (h^2 + rho^2 - a^2) / S], which in that
    form cancels to 0 once the pupil's radius a is below 1e-8 of the focus distance h (a 1e-5 mm pupil,
    focus at 1e10 mm): the backward estimate divided by it and was NaN. At focus 1e12 mm (the largest
    allowed) the extent must equal the closed form at infinity, A cos^4 / f^2 integrated over the pixel,
    for the smallest pupil allowed (0.01 mm) and the largest (20 mm)."""
    from tracer.scene import EyeSpec
    from tracer.transport.eye import ThinLensEye

    for pupil in (0.01, 4.0, 20.0):
        spec = dict(position=np.zeros(3), gaze=np.array([0.0, 1, 0]), up=np.array([0.0, 0, 1]),
                    pupil_diameter_mm=pupil, focal_length_mm=16.67, resolution=(9, 7), fov_deg=(120.0, 90.0),
                    adaptation="log_average")
        far = ThinLensEye(EyeSpec(accommodation_distance_mm=1e12, **spec)).extent
        at_infinity = ThinLensEye(EyeSpec(accommodation_distance_mm=math.inf, **spec)).extent
        assert np.all(far > 0)
        np.testing.assert_allclose(far, at_infinity, rtol=1e-9)


@pytest.mark.parametrize("pupil,focus", [(0.01, 50.0), (4.0, 1e10), (0.01, 1e12)])
def test_a_panel_in_view_renders_its_luminance_through_a_pinhole_or_at_a_far_focus(tmp_path, pupil, focus):
    """A Lambertian panel of 100 cd/m^2 that fills the central pixels renders 100 cd/m^2 there whatever
    the pupil and the focus (the brightness theorem): backward tracing, through the smallest pupil
    allowed and at the farthest focus, within 4 standard errors."""
    folder = panel_in_view(tmp_path / "panel", 50.0, pupil)
    edit_json(folder, lambda d: d["eye"].update(accommodation_distance_mm=focus))
    y, var, _ = render(folder, "backward", 200_000)
    centre, centre_var = y[3:5, 3:5], var[3:5, 3:5]  # 11 deg from the panel's edge: beyond any blur here
    assert np.all(np.isfinite(y)) and np.all(np.isfinite(var))
    err = math.sqrt(centre_var.sum()) / centre.size
    assert abs(centre.mean() - 100.0) <= 4 * err + 1e-6 * 100.0, (centre.mean(), err)


def _point_scene(folder, distance, accommodation):
    """A 0.05 mm emitter square on the axis at ``distance``, seen by a 4 mm pupil."""
    sb = SceneBuilder(folder, "point", "a point source on the axis")
    sb.add("dot", rectangle(0.05, 0.05), {"type": "emitter", "luminance": 1e6, "aim": {"target": "eye", "share": 0.99}},
           frame_matrix([0, distance, 0], [1, 0, 0], [0, -1, 0]))
    return sb.write(eye={"position": [0, 0, 0], "gaze": [0, 1, 0], "up": [0, 0, 1], "pupil_diameter_mm": 4.0,
                         "focal_length_mm": 16.67, "accommodation_distance_mm": accommodation,
                         "resolution": [41, 41], "fov_deg": [1.0, 1.0]})


@pytest.mark.slow
def test_thin_lens_focus_and_blur(tmp_path):
    """In focus: the image lies within one pixel of the centre. Out of focus: a uniform blur disk of
    diameter f D |1/d - 1/s| (perceived retina coordinates), i.e. RMS radius = diameter / (2 sqrt 2)."""
    from tracer.scene import load_scene
    from tracer.transport.eye import ThinLensEye

    focused = _point_scene(tmp_path / "in", 500.0, 500.0)
    y, _, _ = render(focused, "forward", 600_000)
    jj, ii = np.indices(y.shape)
    cy, cx = (jj * y).sum() / y.sum(), (ii * y).sum() / y.sum()
    assert abs(cx - 20.0) < 1 and abs(cy - 20.0) < 1
    r2 = ((jj - cy) ** 2 + (ii - cx) ** 2)
    assert math.sqrt((r2 * y).sum() / y.sum()) < 1.0

    blurred = _point_scene(tmp_path / "out", 300.0, 1000.0)
    eye = ThinLensEye(load_scene(blurred).eye)
    diameter_px = eye.blur_diameter_mm(300.0) / eye.pixel_w
    y, _, _ = render(blurred, "forward", 2_000_000)
    cy, cx = (jj * y).sum() / y.sum(), (ii * y).sum() / y.sum()
    rms = math.sqrt((((jj - cy) ** 2 + (ii - cx) ** 2) * y).sum() / y.sum())
    predicted = diameter_px / (2 * math.sqrt(2))
    # The pixel grid adds 1/12 px^2 per axis to the variance.
    assert math.sqrt(rms**2 - 1 / 6) == pytest.approx(predicted, rel=0.03)
