"""Tests of tracer.sources.environment: Blender's equirectangular mapping, rotation, calibration, the three
environment kinds, their sampling against the density they report (chi-square) and the next-event estimate
of the mean luminance, and renders of panoramas: one calibrated to a mean, one with a sun of 1e9 cd/m^2."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tests.support.chi2 import ChiSquareTest
from tests.support.environment import radiance_rows
from tests.support.render import render
from tests.support.scenes import edit_json
from tests.support.stats import film_dof, t_bound, z_bound
from tracer.core.imageio import write_exr
from tracer.core.sampling import make_rng
from tracer.core.units import luminance
from tracer.sources.environment import (
    CALIBRATION_MODES,
    HdriEnvironment,
    NoEnvironment,
    UniformEnvironment,
    direction_to_equirect,
    equirect_to_direction,
    row_solid_angle_fractions,
)


def _uniform_sphere(n: int, seed: int) -> np.ndarray:
    """``n`` directions uniformly distributed over the unit sphere, shape (n, 3)."""
    d = np.random.default_rng(seed).normal(size=(n, 3))
    return d / np.linalg.norm(d, axis=1, keepdims=True)


def _pixel_centre_directions(height: int, width: int) -> np.ndarray:
    """Directions of the pixel centres, shape (H, W, 3): row 0 is the top row."""
    rows, cols = np.meshgrid(np.arange(height), np.arange(width), indexing="ij")
    u = (cols.ravel() + 0.5) / width
    v = 1.0 - (rows.ravel() + 0.5) / height
    return equirect_to_direction(u, v).T.reshape(height, width, 3)


def _rot_z(degrees: float) -> np.ndarray:
    """Rotation matrix about +z, counter-clockwise seen from above."""
    c, s = math.cos(math.radians(degrees)), math.sin(math.radians(degrees))
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _feature_image(height: int, width: int, u: float, v: float) -> np.ndarray:
    """Black image with a 2 x 2 block of value 1 centred on (u, v) (both on pixel edges)."""
    image = np.zeros((height, width, 3))
    col = round(u * width)
    row = round((1.0 - v) * height)
    image[row - 1 : row + 1, col - 1 : col + 1] = 1.0
    return image


# --- mapping conventions ------------------------------------------------------------------


def test_axes_land_where_blender_puts_them():
    d = np.array(
        [[1, 0, 0], [0, 1, 0], [0, -1, 0], [-1, 0, 0], [0, 0, 1], [0, 0, -1]], dtype=float
    )
    u, v = direction_to_equirect(d.T)
    np.testing.assert_allclose(u[:3], [0.5, 0.25, 0.75], atol=1e-15)
    assert u[3] in (0.0, 1.0)  # -x lies on the seam
    np.testing.assert_allclose(v, [0.5, 0.5, 0.5, 0.5, 1.0, 0.0], atol=1e-15)


def test_direction_uv_round_trip():
    d = _uniform_sphere(1000, seed=1)
    u, v = direction_to_equirect(d.T)
    assert np.all((0 <= u) & (u <= 1) & (0 <= v) & (v <= 1))
    np.testing.assert_allclose(equirect_to_direction(u, v).T, d, atol=1e-12)


def test_direction_pixel_direction_round_trip():
    # Bilinear lookup at a pixel centre returns that pixel exactly.
    image = np.random.default_rng(2).random((6, 12, 3))
    env = HdriEnvironment(image, "scale", 1.0)
    centres = _pixel_centre_directions(6, 12)
    radiance = radiance_rows(env, centres.reshape(-1, 3))
    np.testing.assert_allclose(radiance, image.reshape(-1, 3), rtol=1e-12)


@pytest.mark.parametrize(
    ("direction", "u", "v"),
    [
        ((1, 0, 0), 0.5, 0.5),
        ((0, 1, 0), 0.25, 0.5),
        ((0, -1, 0), 0.75, 0.5),
        ((math.sqrt(0.5), 0, math.sqrt(0.5)), 0.5, 0.75),  # 45 degrees up from +x
    ],
)
def test_feature_is_seen_in_its_direction(direction, u, v):
    env = HdriEnvironment(_feature_image(8, 16, u, v), "scale", 1.0)
    np.testing.assert_allclose(radiance_rows(env, np.array([direction], float)), [[1.0, 1.0, 1.0]])
    assert radiance_rows(env, -np.array([direction], float)).max() == 0.0


def test_top_row_is_up():
    image = np.zeros((4, 8, 3))
    image[0] = 5.0
    env = HdriEnvironment(image, "scale", 1.0)
    np.testing.assert_allclose(radiance_rows(env, np.array([[0.0, 0.0, 1.0]])), [[5.0, 5.0, 5.0]])
    np.testing.assert_allclose(radiance_rows(env, np.array([[0.0, 0.0, -1.0]])), [[0.0, 0.0, 0.0]])


def test_wraps_across_the_seam():
    image = np.zeros((2, 8, 3))
    image[:, 0] = 2.0  # left column
    image[:, -1] = 4.0  # right column
    env = HdriEnvironment(image, "scale", 1.0)
    # -x lies on the seam, midway between the centres of the last and first columns.
    np.testing.assert_allclose(radiance_rows(env, np.array([[-1.0, 0.0, 0.0]])), [[3.0, 3.0, 3.0]])


# --- rotation -------------------------------------------------------------------------------


def test_rotation_by_90_degrees_moves_the_centre_from_x_to_y():
    image = _feature_image(8, 16, 0.5, 0.5)  # feature at +x
    x, y, minus_y = np.array([[1.0, 0, 0]]), np.array([[0, 1.0, 0]]), np.array([[0, -1.0, 0]])
    env = HdriEnvironment(image, "scale", 1.0, rotation_deg=90.0)
    np.testing.assert_allclose(radiance_rows(env, y), [[1.0, 1.0, 1.0]], atol=1e-12)
    assert radiance_rows(env, x).max() < 1e-12
    env = HdriEnvironment(image, "scale", 1.0, rotation_deg=-90.0)
    np.testing.assert_allclose(radiance_rows(env, minus_y), [[1.0, 1.0, 1.0]], atol=1e-12)


def test_rotation_turns_the_whole_panorama_counter_clockwise():
    image = np.random.default_rng(3).random((16, 32, 3))
    env = HdriEnvironment(image, "scale", 1.0)
    turned = HdriEnvironment(image, "scale", 1.0, rotation_deg=37.0)
    d = _uniform_sphere(500, seed=4)
    np.testing.assert_allclose(radiance_rows(turned, d @ _rot_z(37.0).T), radiance_rows(env, d), atol=1e-12)


# --- calibration ----------------------------------------------------------------------------


def test_row_solid_angles_are_exact_bands():
    H, W = 7, 13
    fractions = row_solid_angle_fractions(H)
    assert fractions.sum() == pytest.approx(1.0, rel=1e-15)
    lat_top = np.pi / 2 - np.pi * np.arange(H) / H
    lat_bottom = lat_top - np.pi / H
    omega = 2 * np.pi / W * (np.sin(lat_top) - np.sin(lat_bottom))  # one pixel, sr
    np.testing.assert_allclose(fractions, W * omega / (4 * np.pi), rtol=1e-14)


def test_constant_image_gives_constant_radiance():
    env = HdriEnvironment(np.full((9, 20, 3), [0.5, 1.0, 2.0]), "scale", 3.0)
    d = np.vstack([_uniform_sphere(1000, seed=5), [[0, 0, 1], [0, 0, -1], [-1, 0, 0]]])
    np.testing.assert_allclose(radiance_rows(env, d), np.tile([1.5, 3.0, 6.0], (len(d), 1)), rtol=1e-14)


def test_scale_calibration():
    image = np.random.default_rng(6).random((6, 12, 3))
    env = HdriEnvironment(image, "scale", 250.0)
    assert env.scale_factor == 250.0
    centres = _pixel_centre_directions(6, 12).reshape(-1, 3)
    np.testing.assert_allclose(radiance_rows(env, centres), 250.0 * image.reshape(-1, 3), rtol=1e-12)
    assert env.max_luminance == pytest.approx(250.0 * luminance(image).max(), rel=1e-14)


def test_mean_calibration_is_exact():
    H, W = 12, 24
    image = np.random.default_rng(7).random((H, W, 3)) * np.linspace(0.1, 3.0, H)[:, None, None]
    env = HdriEnvironment(image, "mean", 1000.0)
    # Solid angle of each pixel: (2 pi / W) (sin lat_top - sin lat_bottom), summing to 4 pi.
    lat_top = np.pi / 2 - np.pi * np.arange(H) / H
    omega = 2 * np.pi / W * (np.sin(lat_top) - np.sin(lat_top - np.pi / H))
    assert W * omega.sum() == pytest.approx(4 * np.pi, rel=1e-14)
    Y = env.scale_factor * luminance(image)
    mean = (Y * omega[:, None]).sum() / (4 * np.pi)
    assert mean == pytest.approx(1000.0, rel=1e-9)
    assert env.mean_luminance == pytest.approx(1000.0, rel=1e-9)


def test_mean_calibration_monte_carlo():
    H, W = 32, 64
    rng = np.random.default_rng(8)
    brighter_up = np.linspace(2.0, 0.5, H)[:, None, None]
    image = (0.5 + rng.random((H, W, 3))) * brighter_up
    env = HdriEnvironment(image, "mean", 20.0)
    d = _uniform_sphere(400_000, seed=9)
    assert luminance(radiance_rows(env, d)).mean() == pytest.approx(20.0, rel=0.01)


def test_max_calibration():
    image = np.random.default_rng(10).random((8, 16, 3))
    env = HdriEnvironment(image, "max", 5000.0)
    assert env.max_luminance == pytest.approx(5000.0, rel=1e-14)
    Y = luminance(image)
    row, col = np.unravel_index(np.argmax(Y), Y.shape)
    brightest = _pixel_centre_directions(8, 16)[row, col][None, :]
    assert luminance(radiance_rows(env, brightest))[0] == pytest.approx(5000.0, rel=1e-12)
    assert luminance(radiance_rows(env, _uniform_sphere(20_000, seed=11))).max() <= 5000.0 * (1 + 1e-12)


def test_min_calibration():
    image = 0.2 + np.random.default_rng(15).random((8, 16, 3))
    env = HdriEnvironment(image, "min", 30.0)
    assert env.min_luminance == pytest.approx(30.0, rel=1e-14)
    Y = luminance(image)
    row, col = np.unravel_index(np.argmin(Y), Y.shape)
    darkest = _pixel_centre_directions(8, 16)[row, col][None, :]
    assert luminance(radiance_rows(env, darkest))[0] == pytest.approx(30.0, rel=1e-12)
    assert luminance(radiance_rows(env, _uniform_sphere(20_000, seed=16))).min() >= 30.0 * (1 - 1e-12)
    assert env.max_luminance == pytest.approx(30.0 * Y.max() / Y.min(), rel=1e-12)


def test_min_calibration_refuses_a_black_pixel():
    image = np.ones((4, 8, 3))
    image[2, 5] = 0.0
    with pytest.raises(ValueError, match="1 of its 32 pixels are black"):
        HdriEnvironment(image, "min", 10.0)
    image[2, 5] = (0.0, 0.0, 1e-3)  # dark, not black: its luminance is the minimum
    assert HdriEnvironment(image, "min", 10.0).min_luminance == pytest.approx(10.0, rel=1e-14)


#: The value each calibration mode is given in the test below, and what it makes of it.
_MODE_VALUES = {"scale": 250.0, "mean": 1000.0, "max": 5000.0, "min": 40.0}


@pytest.mark.parametrize("mode", CALIBRATION_MODES)
def test_every_calibration_reports_its_value_and_the_mean_of_the_radiance(mode):
    """Each mode reports the value it was given (the factor, the mean, the largest or the smallest pixel
    luminance), each of the three luminances agrees with the one computed here from the pixels and their
    exact solid angles, and the mean luminance of the radiance over random directions agrees with
    mean_luminance within its standard error (Sidak over the modes). The bilinear lookup's mean differs
    from the pixels' by 1e-5 of it on this 32 x 64 panorama (measured by a 4096 x 8192 midpoint
    quadrature), 1/50 of that standard error."""
    H, W = 32, 64
    image = (0.5 + np.random.default_rng(8).random((H, W, 3))) * np.linspace(2.0, 0.5, H)[:, None, None]
    value = _MODE_VALUES[mode]
    env = HdriEnvironment(image, mode, value)
    reported = {"scale": env.scale_factor, "mean": env.mean_luminance, "max": env.max_luminance,
                "min": env.min_luminance}
    assert reported[mode] == pytest.approx(value, rel=1e-12)
    Y = env.scale_factor * luminance(image)
    lat_top = np.pi / 2 - np.pi * np.arange(H) / H
    omega = 2 * np.pi / W * (np.sin(lat_top) - np.sin(lat_top - np.pi / H))  # sr per pixel of each row
    assert env.mean_luminance == pytest.approx((Y * omega[:, None]).sum() / (4 * np.pi), rel=1e-12)
    assert env.max_luminance == pytest.approx(Y.max(), rel=1e-12)
    assert env.min_luminance == pytest.approx(Y.min(), rel=1e-12)
    y = luminance(radiance_rows(env, _uniform_sphere(400_000, seed=17)))
    sem = y.std() / math.sqrt(len(y))
    assert abs(y.mean() - env.mean_luminance) < z_bound(len(CALIBRATION_MODES)) * sem
    assert env.min_luminance * (1 - 1e-12) <= y.min() and y.max() <= env.max_luminance * (1 + 1e-12)


def test_hdri_rejects_bad_input():
    good = np.ones((4, 8, 3))
    negative = good.copy()
    negative[1, 2, 0] = -1e-3
    not_finite = good.copy()
    not_finite[0, 0, 1] = np.inf
    for image in [negative, not_finite, np.ones((4, 8)), np.ones((4, 8, 4)), np.ones((0, 8, 3))]:
        with pytest.raises(ValueError):
            HdriEnvironment(image, "scale", 1.0)
    for calibration, value in [("median", 1.0), ("mean", 0.0), ("max", -2.0), ("scale", math.nan)]:
        with pytest.raises(ValueError):
            HdriEnvironment(good, calibration, value)
    with pytest.raises(ValueError):
        HdriEnvironment(good, "scale", 1.0, rotation_deg=math.inf)
    for calibration in ("mean", "max", "min"):
        with pytest.raises(ValueError, match="zero everywhere"):
            HdriEnvironment(np.zeros((4, 8, 3)), calibration, 1.0)
    assert HdriEnvironment(np.zeros((4, 8, 3)), "scale", 1.0).is_black


def test_hdri_keeps_its_own_copy():
    image = np.ones((4, 8, 3), np.float32)
    env = HdriEnvironment(image, "scale", 2.0)
    image[:] = 7.0
    np.testing.assert_array_equal(radiance_rows(env, np.array([[1.0, 0, 0]])), [[2.0, 2.0, 2.0]])
    assert radiance_rows(env, np.array([[1.0, 0, 0]])).dtype == np.float64


# --- no environment, uniform environment ------------------------------------------------------


def test_no_environment():
    env = NoEnvironment()
    r = radiance_rows(env, _uniform_sphere(5, seed=12))
    assert r.shape == (5, 3) and r.dtype == np.float64 and not r.any()
    assert env.is_black and env.mean_luminance == 0.0 and env.max_luminance == 0.0


def test_uniform_environment():
    env = UniformEnvironment(300.0, color=(1.0, 0.5, 0.25))
    r = radiance_rows(env, _uniform_sphere(7, seed=13))
    assert r.shape == (7, 3) and r.dtype == np.float64
    np.testing.assert_allclose(luminance(r), 300.0, rtol=1e-14)
    np.testing.assert_allclose(r[:, 1] / r[:, 0], 0.5, rtol=1e-14)
    assert env.mean_luminance == env.max_luminance == 300.0 and not env.is_black
    assert UniformEnvironment(0.0).is_black
    for bad in [-1.0, math.inf, math.nan]:
        with pytest.raises(ValueError):
            UniformEnvironment(bad)
    with pytest.raises(ValueError):
        UniformEnvironment(1.0, color=(0.0, 0.0, 0.0))


def test_radiance_rejects_bad_directions():
    hdri = HdriEnvironment(np.ones((2, 4, 3)), "scale", 1.0)
    for env in [NoEnvironment(), UniformEnvironment(1.0), hdri]:
        with pytest.raises(ValueError):
            radiance_rows(env, np.ones(3))
        with pytest.raises(ValueError):
            radiance_rows(env, np.array([[np.nan, 0.0, 1.0]]))


# --- sampling ---------------------------------------------------------------------------------


#: Sidak family of the chi-square tests of the light table's and the environments' samplers.
CHI2_TESTS = 5


def test_chi2_hdri_sampling_against_its_pdf(tmp_path):
    """Directions from a structured, rotated panorama, histogrammed in the panorama's own (u, v)
    coordinates on a grid that refines its pixels (so no cell straddles a jump of the piecewise
    constant density), against the reported density per steradian times d omega / (du dv) =
    2 pi^2 cos(latitude); the sampler's own pdf equals pdf(d) and its radiance the lookup's."""
    from tracer.sources.environment import direction_to_equirect, equirect_to_direction

    h, w = 32, 64
    rng = make_rng(7)
    image = rng.random((h, w, 3)) ** 4
    image[5:8, 40:44] = 50.0  # a sun
    image[:, :5] = 0.0  # a black band: never sampled
    env = HdriEnvironment(image.astype(np.float32), "scale", 3.0, rotation_deg=30.0)

    def sample(n, rng):
        d, radiance, pdf = env.sample(rng.random((2, n)))
        np.testing.assert_allclose(pdf, env.pdf(d), rtol=1e-9)
        np.testing.assert_allclose(radiance, env.radiance(d), rtol=1e-12)
        u, v = direction_to_equirect(env._to_image(d))
        return np.stack([u, v], axis=-1), pdf > 0

    def density(u, v):
        local = equirect_to_direction(u, v)
        a = np.radians(30.0)  # back to the world: rotate by +30 deg about z
        d = np.stack([np.cos(a) * local[0] - np.sin(a) * local[1], np.sin(a) * local[0] + np.cos(a) * local[1],
                      local[2]])
        return env.pdf(d) * 2 * np.pi**2 * np.cos(np.pi * (v - 0.5))

    test = ChiSquareTest(((0.0, 1.0), (0.0, 1.0)), (2 * w, 2 * h), sample, density, 500_000, seed=8)
    ok, msg = test.run(0.01, CHI2_TESTS)
    assert ok, msg
    # The black band is never sampled.
    u, _ = sample(100_000, make_rng(12))[0].T
    assert np.all(u >= 5 / w)


def test_hdri_next_event_estimate_of_the_mean_luminance():
    """The mean of radiance / pdf over samples estimates the integral of the luminance over the sphere:
    4 pi times the panorama's mean luminance (its calibration)."""
    image = make_rng(9).random((16, 32, 3)).astype(np.float32)
    env = HdriEnvironment(image, "mean", 250.0)
    d, radiance, pdf = env.sample(make_rng(10).random((2, 400_000)))
    from tracer.core.units import luminance3

    est = luminance3(radiance) / pdf
    assert abs(est.mean() - 4 * np.pi * 250.0) < z_bound(1) * est.std() / np.sqrt(len(est)) + 0.01 * 4 * np.pi * 250


def test_uniform_environment_sampling():
    env = UniformEnvironment(42.0)
    d, radiance, pdf = env.sample(make_rng(2).random((2, 1000)))
    np.testing.assert_allclose(np.linalg.norm(d, axis=0), 1.0, rtol=1e-7)
    np.testing.assert_allclose(pdf, 1 / (4 * np.pi))
    np.testing.assert_allclose(env.pdf(d), 1 / (4 * np.pi))


# -- renders of panoramas -------------------------------------------------------------------------
@pytest.mark.slow
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
