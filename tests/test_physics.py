"""Closed-form scenes every method must reproduce, and the two methods against each other.

Tolerances are statistical: a deviation must stay inside the Sidak-corrected alpha = 0.01 bound
of the estimator's own reported standard error, and inside the stated relative accuracy.
"""

import math

import numpy as np
import pytest
from conftest import edit_json, film_dof, render, t_bound, z_bound

import presets.analytic_disk as disk_preset
from presets._build import SceneBuilder, frame_matrix, rectangle
from tracer.core.imageio import write_png


@pytest.mark.parametrize("pupil,acc,fov", [(2.0, 300.0, (60.0, 40.0)), (8.0, "infinity", (100.0, 20.0))])
def test_furnace_backward_every_pixel(preset, pupil, acc, fov):
    """Uniform surround L0: every pixel reads L0 within 1 % at 3 sigma, whatever pupil, focus, field."""
    folder = preset("analytic-furnace", pupil_mm=pupil, fov_deg=fov)
    edit_json(folder, lambda d: d["eye"].update(accommodation_distance_mm=acc))
    y, var, res = render(folder, "backward", 1_500_000)
    sigma = np.sqrt(var)
    assert np.all(3 * sigma < 0.01 * 100.0)
    assert np.all(np.abs(y - 100.0) < t_bound(y.size, film_dof(res.film)) * sigma + 1e-9)


def test_furnace_uniform_environment_backward(preset):
    folder = preset("analytic-furnace")
    edit_json(folder, lambda d: (d.update(objects=[], environment={"type": "uniform", "luminance": 42.0})))
    y, var, res = render(folder, "backward", 500_000)
    assert np.all(np.abs(y - 42.0) < t_bound(y.size, film_dof(res.film)) * np.sqrt(var) + 1e-9)


def test_furnace_forward_mean(preset):
    folder = preset("analytic-furnace", resolution=(12, 8))
    y, var, res = render(folder, "forward", 3_000_000)
    sem = math.sqrt(var.sum()) / y.size
    assert abs(y.mean() - 100.0) < z_bound(1) * sem and sem < 0.01 * 100 / 3
    assert np.all(np.abs(y - 100.0) < t_bound(y.size, film_dof(res.film)) * np.sqrt(var))


@pytest.mark.parametrize("method,rays", [("backward", 1_500_000), ("forward", 3_000_000)])
def test_brightness_theorem_mirror(preset, method, rays):
    """A panel of luminance L seen in a mirror of reflectance R reads L R in every covered pixel."""
    folder = preset("analytic-mirror", resolution=(32, 24))
    y, var, _ = render(folder, method, rays)
    expected = 1000.0 * 0.85
    covered = y > 0.5 * expected
    interior = covered.copy()
    for axis in (0, 1):
        interior &= np.roll(covered, 1, axis) & np.roll(covered, -1, axis)
    assert interior.sum() > 20
    sem = math.sqrt(var[interior].sum()) / interior.sum()
    assert abs(y[interior].mean() - expected) < z_bound(2) * sem
    assert 3 * sem < 0.01 * expected


def test_disk_illuminance_closed_form(preset):
    """E = pi L sin^2(alpha) at the foot of a Lambertian disk: the floor reads rho E / pi. With
    next-event estimation the error is 1e-4, so the expectation is the exact illuminance of the disk as
    built (a 256-gon: Lambert's contour formula) at the floor points the pixels see."""
    from tracer.scene import load_scene
    from tracer.transport.eye import ThinLensEye

    folder = preset("analytic-disk", resolution=(3, 3))
    y, var, _ = render(folder, "backward", 3_000_000)
    assert disk_preset.expected_luminance() == pytest.approx(
        disk_preset.RHO * disk_preset.expected_illuminance_lx() / math.pi)
    assert disk_preset.polygon_illuminance_lx(np.zeros((1, 3)))[0] == pytest.approx(
        disk_preset.expected_illuminance_lx(), rel=2e-4)
    eye = ThinLensEye(load_scene(folder).eye)
    sx, sy = eye.pixel_centers()
    gx, gy = np.meshgrid(sx, sy)
    _, d, _ = eye.generate_rays(gx.ravel(), gy.ravel(), np.zeros((2, gx.size)))
    t = -eye.position[2] / d[2].astype(np.float64)
    floor = (eye.position[:, None] + t * d).T  # where the chief rays meet the floor z = 0
    expected = disk_preset.RHO * disk_preset.polygon_illuminance_lx(floor).mean() / math.pi
    sem = math.sqrt(var.sum()) / y.size
    assert abs(y.mean() - expected) < z_bound(1) * sem and 3 * sem < 0.01 * expected


def _point_scene(folder, distance, accommodation):
    """A 0.05 mm emitter square on the axis at ``distance``, seen by a 4 mm pupil."""
    sb = SceneBuilder(folder, "point", "a point source on the axis")
    sb.add("dot", rectangle(0.05, 0.05), {"type": "emitter", "luminance": 1e6, "aim": {"target": "eye", "share": 0.99}},
           frame_matrix([0, distance, 0], [1, 0, 0], [0, -1, 0]))
    return sb.write(eye={"position": [0, 0, 0], "gaze": [0, 1, 0], "up": [0, 0, 1], "pupil_diameter_mm": 4.0,
                         "focal_length_mm": 16.67, "accommodation_distance_mm": accommodation,
                         "resolution": [41, 41], "fov_deg": [1.0, 1.0]})


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


def _lcd_scene(folder, share=0.9):
    """A backlight behind an LCD with one vertical edge (left half clear), in direct view at 300 mm."""
    folder.mkdir(parents=True)
    img = np.zeros((8, 64, 3), np.uint8)
    img[:, :32] = 255
    write_png(folder / "edge.png", img)
    sb = SceneBuilder(folder, "lcd-edge", "an LCD edge seen directly")
    v, f, uv = rectangle(20.0, 10.0)
    sb.add("lcd", (v, f), {"type": "lcd", "image": "edge.png", "transmittance": 0.5, "contrast_ratio": 300},
           frame_matrix([0.3, 300, 0], [1, 0, 0], [0, -1, 0]), uv=uv)
    sb.add("backlight", rectangle(30.0, 20.0)[:2], {"type": "emitter", "luminance": 1000.0,
                                                    "aim": {"target": "eye", "share": share}},
           frame_matrix([0, 310, 0], [1, 0, 0], [0, -1, 0]))
    return sb.write(eye={"position": [0, 0, 0], "gaze": [0, 1, 0], "up": [0, 0, 1], "pupil_diameter_mm": 3.0,
                         "focal_length_mm": 16.67, "accommodation_distance_mm": 300.0,
                         "resolution": [40, 8], "fov_deg": [1.2, 0.24]})


def _edge_position(y):
    """Sub-pixel column where the row-averaged profile crosses half-way between its plateaus."""
    prof = y.mean(axis=0)
    hi, lo = prof[:8].mean(), prof[-8:].mean()
    half = 0.5 * (hi + lo)
    k = np.nonzero((prof[:-1] >= half) & (prof[1:] < half))[0][0]
    return k + (prof[k] - half) / (prof[k] - prof[k + 1]) + 0.5, hi, lo


def test_forward_and_backward_agree_and_place_edges_alike(tmp_path):
    folder = _lcd_scene(tmp_path / "lcd")
    yb, vb, _ = render(folder, "backward", 3_000_000, seed=3)
    yf, vf, _ = render(folder, "forward", 6_000_000, seed=4)
    # Plateaus agree within their combined error, and equal L T and L T / CR.
    left = np.s_[:, :8]
    mb, mf = yb[left].mean(), yf[left].mean()
    sb_, sf = math.sqrt(vb[left].sum()) / vb[left].size, math.sqrt(vf[left].sum()) / vf[left].size
    assert abs(mb - mf) < z_bound(2) * math.hypot(sb_, sf)
    assert mb == pytest.approx(500.0, rel=0.01)
    eb, _, lo_b = _edge_position(yb)
    ef, _, _ = _edge_position(yf)
    assert lo_b == pytest.approx(500.0 / 300, rel=0.05)
    assert abs(eb - ef) < 0.05
    # Geometry: the edge at x = 0.3 mm, 300 mm away, is at column 20 + atan(0.3/300) / pixel angle.
    pixel = math.radians(1.2) / 40
    assert eb == pytest.approx(20 + math.atan(0.3 / 300) / pixel, abs=0.05)


@pytest.mark.parametrize("share", [0.2, 0.9])
def test_directed_split_is_unbiased(tmp_path, share):
    """The paper's directed split (one-sample mixture) gives the same answer for every share w."""
    folder = _lcd_scene(tmp_path / f"w{share}", share=share)
    y, var, res = render(folder, "forward", 4_000_000, seed=5)
    left = np.s_[:, :8]
    m, s = y[left].mean(), math.sqrt(var[left].sum()) / var[left].size
    assert abs(m - 500.0) < z_bound(3) * s


def _stop_scene(folder, share):
    """A panel behind an absorbing screen with a 1.5 mm hole 1 mm off the pupil centre, 5 mm in front of it."""
    sb = SceneBuilder(folder, "stop", "a pupil partly covered by a stop")
    v, f, _ = rectangle(40.0, 40.0, 200, 200)
    c = (v[f].mean(axis=1) - [1.0, 0.0, 0.0])
    keep = np.hypot(c[:, 0], c[:, 1]) > 1.5
    sb.add("screen", (v, f[keep]), {"type": "absorber"}, frame_matrix([0, 5, 0], [1, 0, 0], [0, -1, 0]))
    sb.add("panel", rectangle(400.0, 400.0)[:2], {"type": "emitter", "luminance": 100.0},
           frame_matrix([0, 200, 0], [1, 0, 0], [0, -1, 0]))
    backward = {"exit_pupil": {"center_mm": [1.0, 0.0], "radius_mm": 1.8, "share": share}}
    return sb.write(eye={"position": [0, 0, 0], "gaze": [0, 1, 0], "up": [0, 0, 1], "pupil_diameter_mm": 6.0,
                         "focal_length_mm": 16.67, "accommodation_distance_mm": 200.0,
                         "resolution": [4, 4], "fov_deg": [0.5, 0.5]}, backward=backward)


def test_eq3_stratification_moves_noise_not_answer(tmp_path):
    """Eq. (3): the share of samples sent to the designated exit pupil changes the noise only."""
    means, sems = [], []
    for share in (0.0, 0.5, 0.9):
        y, var, _ = render(_stop_scene(tmp_path / f"s{share}", share), "backward", 400_000, seed=6)
        means.append(y.mean())
        sems.append(math.sqrt(var.sum()) / y.size)
    for i in range(1, 3):
        assert abs(means[i] - means[0]) < z_bound(2) * math.hypot(sems[i], sems[0])
    assert sems[2] < 0.5 * sems[0]


def test_hdri_environment_calibrated_to_a_mean(tmp_path, preset):
    """A panorama calibrated to a mean luminance renders that luminance where it is uniform."""
    from tracer.core.imageio import write_exr

    folder = preset("analytic-furnace")
    img = np.full((16, 32), 3.0, np.float32)
    write_exr(folder / "sky.exr", {"R": img, "G": img, "B": img})
    edit_json(folder, lambda d: d.update(objects=[], environment={
        "type": "hdri", "file": "sky.exr", "calibration": {"mode": "mean", "value": 250.0}, "rotation_deg": 30}))
    y, var, res = render(folder, "backward", 300_000)
    assert np.all(np.abs(y - 250.0) < t_bound(y.size, film_dof(res.film)) * np.sqrt(var) + 1e-6)
    assert y.mean() == pytest.approx(250.0, rel=1e-3)


@pytest.mark.parametrize("luminance,expected", [(1.0, 5.12), (292.0, 2.61), (3000.0, 2.25), (21013.0, 2.12)])
def test_pupil_from_adaptation_watson_yellott(luminance, expected):
    """The derived values of hud-physics.md (60 deg field, age 30, both eyes)."""
    from tracer.optics.pupil import pupil_diameter_mm

    assert pupil_diameter_mm(luminance) == pytest.approx(expected, abs=0.006)


def test_auto_pupil_follows_the_environment(preset):
    from tracer.optics.pupil import pupil_diameter_mm
    from tracer.scene import load_scene

    folder = preset("analytic-furnace")
    edit_json(folder, lambda d: (d.update(environment={"type": "uniform", "luminance": 292.0}),
                                 d["eye"].update(pupil_diameter_mm="auto")))
    assert load_scene(folder).eye.pupil_diameter_mm == pytest.approx(pupil_diameter_mm(292.0))
    edit_json(folder, lambda d: d["eye"].update(adaptation_luminance_cd_m2=3000.0, observer_age=60))
    assert load_scene(folder).eye.pupil_diameter_mm == pytest.approx(pupil_diameter_mm(3000.0, age_years=60))
