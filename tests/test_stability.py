"""Stability where methods fail: the answer degrades honestly (efficiency falls, the report warns),
never into NaN, Inf or a silent black image; and the error of unbiased methods falls as N^-1/2."""

import math

import numpy as np
import pytest
from conftest import edit_json, render

from presets._build import SceneBuilder, box, frame_matrix, rectangle
from tracer.core.errors import SceneError
from tracer.core.imageio import write_exr
from tracer.methods import Budget
from tracer.products.render import render_folder
from tracer.scene import load_scene


def _report(folder, method, rays, tmp_path, seed=1):
    report, _ = render_folder(folder, method, Budget(rays=rays), seed, tmp_path / f"out-{method}-{seed}")
    assert all(math.isfinite(v) for v in (report["luminance"]["mean"], report["luminance"]["max"]))
    return report


def _panel_in_view(folder, panel_mm: float, pupil_mm: float, screen: bool = False):
    """A Lambertian panel 50 mm in front of the eye (behind a diffuse screen at 40 mm if ``screen``),
    without aiming: the plain methods, as the paper describes them."""
    sb = SceneBuilder(folder, "panel", "a panel in view")
    sb.add("panel", rectangle(panel_mm, panel_mm)[:2], {"type": "emitter", "luminance": 100.0},
           frame_matrix([0, 50, 0], [1, 0, 0], [0, -1, 0]))
    if screen:
        sb.add("screen", rectangle(100.0, 100.0)[:2], {"type": "lambertian_transmitter", "transmittance": 0.8},
               frame_matrix([0, 40, 0], [1, 0, 0], [0, -1, 0]))
    return sb.write(eye={"position": [0, 0, 0], "gaze": [0, 1, 0], "up": [0, 0, 1], "pupil_diameter_mm": pupil_mm,
                         "accommodation_distance_mm": 50.0, "resolution": [8, 8], "fov_deg": [90.0, 90.0]})


def test_backward_with_a_shrinking_source(tmp_path):
    """A source behind a diffuse screen shrinks toward a point (the paper's LED behind a scatterer).
    The paper's plain backward method: efficiency falls with the source's area, the report warns once
    the image is noise, and nothing becomes NaN. With next-event estimation every screen point connects
    to the source whatever its size: the efficiency stays 1 and the relative error of the image mean
    stays put while the mean falls by 10^6."""
    effs, warned, rel = [], [], []
    for size in (20.0, 2.0, 0.2, 0.02):
        folder = _panel_in_view(tmp_path / f"src{size}", size, 4.0, screen=True)
        edit_json(folder, lambda d: d.update(methods={"backward": {"next_event": False}}))
        report = _report(folder, "backward", 400_000, tmp_path)
        effs.append(report["efficiency"])
        warned.append(bool(report["warnings"]))
        edit_json(folder, lambda d: d.update(methods={"backward": {"next_event": True}}))
        report = _report(folder, "backward", 400_000, tmp_path, seed=2)
        assert report["efficiency"] == 1.0 and report["method_details"]["connection_share"] > 0.8
        lum = report["luminance"]
        rel.append(lum["mean_standard_error"] / lum["mean"])
    assert effs[0] > effs[1] > effs[2] >= effs[3]
    assert effs[1] == pytest.approx(effs[0] / 100, rel=0.5)
    assert not warned[0] and warned[2] and warned[3]
    assert max(rel) < 2.0 * min(rel) and max(rel) < 0.01


def test_forward_with_a_shrinking_pupil(tmp_path):
    """The pupil shrinks toward a pinhole: forward efficiency falls with its area, the report warns,
    and a zero pupil is refused with the field named."""
    effs, warned = [], []
    for pupil in (4.0, 0.4, 0.04):
        report = _report(_panel_in_view(tmp_path / f"pupil{pupil}", 100.0, pupil), "forward", 2_000_000, tmp_path)
        effs.append(report["efficiency"])
        warned.append(bool(report["warnings"]))
    assert effs[0] > effs[1] > effs[2]
    assert effs[1] == pytest.approx(effs[0] / 100, rel=0.5)
    assert not warned[0] and warned[2]
    folder = _panel_in_view(tmp_path / "pinhole", 100.0, 1.0)
    edit_json(folder, lambda d: d["eye"].update(pupil_diameter_mm=0.0))
    with pytest.raises(SceneError, match="eye.pupil_diameter_mm"):
        load_scene(folder)


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
    folder = _panel_in_view(tmp_path / "panel", 50.0, pupil)
    edit_json(folder, lambda d: d["eye"].update(accommodation_distance_mm=focus))
    y, var, _ = render(folder, "backward", 200_000)
    centre, centre_var = y[3:5, 3:5], var[3:5, 3:5]  # 11 deg from the panel's edge: beyond any blur here
    assert np.all(np.isfinite(y)) and np.all(np.isfinite(var))
    err = math.sqrt(centre_var.sum()) / centre.size
    assert abs(centre.mean() - 100.0) <= 4 * err + 1e-6 * 100.0, (centre.mean(), err)


def test_hdri_with_a_sun_of_1e9(preset, tmp_path):
    """A 1e9 cd/m^2 sun in a 1 cd/m^2 sky: finite everywhere, and the error falls with the budget."""
    folder = preset("analytic-furnace", resolution=(8, 8), fov_deg=(90.0, 90.0))
    sky = np.ones((64, 128), np.float32)
    sky[20:22, 60:62] = 1e9  # a sun high in front of the eye (Blender's mapping: +y at u = 0.25)
    write_exr(folder / "sky.exr", {"R": sky, "G": sky, "B": sky})
    edit_json(folder, lambda d: d.update(objects=[], environment={
        "type": "hdri", "file": "sky.exr", "calibration": {"mode": "scale", "value": 1.0}}))
    ref, _, _ = render(folder, "backward", 6_000_000, seed=100)
    errors = []
    for rays in (200_000, 800_000):
        y, var, _ = render(folder, "backward", rays, seed=7)
        assert np.all(np.isfinite(y)) and np.all(np.isfinite(var))
        errors.append(math.sqrt(np.mean((y - ref) ** 2)) / ref.mean())
    assert errors[1] < errors[0]


def _glass_block(folder, eye_inside=False, grazing=False):
    """A 20 mm glass block in front of a panel; the eye outside, or inside the glass."""
    sb = SceneBuilder(folder, "glass", "a glass block")
    sb.add("glass", box(200.0, 20.0, 200.0), {"type": "dielectric", "ior": 1.5},
           frame_matrix([0, 50, 0], [1, 0, 0], [0, 0, 1]))
    sb.add("panel", rectangle(400.0, 400.0)[:2], {"type": "emitter", "luminance": 100.0},
           frame_matrix([0, 200, 0], [1, 0, 0], [0, -1, 0]))
    gaze = [0, 1, 0] if not grazing else [0.9990482, 0.0436194, 0]  # 87.5 deg from the block's normal
    return sb.write(eye={"position": [0, 50 if eye_inside else 0, 0], "gaze": gaze, "up": [0, 0, 1],
                         "pupil_diameter_mm": 3.0, "accommodation_distance_mm": 500.0,
                         "resolution": [8, 8], "fov_deg": [4.0, 4.0]})


def test_glass_block_transmits_fresnel_and_eye_inside_glass(tmp_path):
    """Through a block (two surfaces at normal incidence) the panel reads L T^2 (plus the small
    inter-reflections); from inside the glass, where the eye sees the panel through one surface,
    radiance is L T n^2 in the glass (the n^2 law, Veach 1997 ch. 5). No NaN at total internal
    reflection or on rays starting on a surface."""
    r = ((1.5 - 1) / 2.5) ** 2
    t = 1 - r
    outside = _glass_block(tmp_path / "outside")
    y, var, _ = render(outside, "backward", 300_000)
    expected = 100.0 * t * t / (1 - r * r)  # incoherent sum of all inter-reflections
    assert y.mean() == pytest.approx(expected, rel=0.01)
    inside = _glass_block(tmp_path / "inside", eye_inside=True)
    y, var, _ = render(inside, "backward", 300_000)
    assert np.all(np.isfinite(y))
    assert y.mean() == pytest.approx(100.0 * t * 1.5**2 / (1 - r * r), rel=0.02)


def test_grazing_incidence_stays_finite(tmp_path):
    folder = _glass_block(tmp_path / "grazing", grazing=True)
    for method in ("backward", "forward"):
        y, var, res = render(folder, method, 200_000)
        assert np.all(np.isfinite(y)) and np.all(np.isfinite(var))


@pytest.mark.parametrize("method", ["backward", "forward"])
def test_error_falls_as_one_over_root_n(preset, method):
    """log RMSE against log rays has slope in [-0.6, -0.4]: the furnace, whose every pixel is exactly
    L0 = 100 cd/m^2, so the error is the estimator's alone (squared errors averaged over 4 seeds)."""
    folder = preset("analytic-furnace", resolution=(12, 8))
    budgets = [100_000, 400_000, 1_600_000]
    errs = []
    for rays in budgets:
        mse = np.mean([np.mean((render(folder, method, rays, seed=s)[0] - 100.0) ** 2) for s in range(4)])
        errs.append(math.sqrt(mse) / 100.0)
    slope = np.polyfit(np.log(budgets), np.log(errs), 1)[0]
    assert -0.6 <= slope <= -0.4, (slope, errs)


@pytest.mark.parametrize("method", ["backward", "forward"])
def test_two_seeds_differ_as_the_reported_variance_says(preset, method):
    """Two seeds of analytic-mirror, compared over 16 x 16 blocks of the image (60 of them lit): z = (Y1 - Y2) /
    sqrt(V1 + V2) per block, with V the block mean's variance from the film's own per-pixel
    variance. If that variance is right, sum z^2 follows chi^2 with one degree of freedom per block:
    a too small variance (overconfident report) fails on the high side, a too large one on the low
    side. Two-sided, alpha = 0.01, Sidak over the two methods."""
    from chi2 import gamma_q

    folder = preset("analytic-mirror")
    (y1, v1, _), (y2, v2, _) = (render(folder, method, 1_000_000, seed=s) for s in (11, 12))
    z2 = []
    for rows_ in np.array_split(np.arange(y1.shape[0]), 16):
        for cols in np.array_split(np.arange(y1.shape[1]), 16):
            block = np.ix_(rows_, cols)
            m = y1[block].size
            var = (v1[block].sum() + v2[block].sum()) / m**2
            if var > 0:
                z2.append((y1[block].mean() - y2[block].mean()) ** 2 / var)
    assert len(z2) >= 30, "the panel must light enough blocks for the test to have power"
    a = 1 - (1 - 0.01) ** (1 / 2)
    p_upper = gamma_q(len(z2) / 2, sum(z2) / 2)
    assert a / 2 < p_upper < 1 - a / 2, (sum(z2), len(z2), p_upper)
