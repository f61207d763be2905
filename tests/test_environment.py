"""Tests of tracer.sources.environment: Blender's equirectangular mapping, rotation, calibration,
the three environment kinds, the sun and the scene.json factory (the sun's sampling and renders
with it: tests/test_sun.py)."""

from __future__ import annotations

import ast
import importlib.util
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import OpenImageIO as oiio
import pytest
from conftest import z_bound

from tracer.core.errors import SceneError
from tracer.core.imageio import write_exr
from tracer.core.units import luminance
from tracer.scene.environment import environment_from_spec
from tracer.sources.environment import (
    CALIBRATION_MODES,
    HdriEnvironment,
    NoEnvironment,
    UniformEnvironment,
    direction_to_equirect,
    equirect_to_direction,
    row_solid_angle_fractions,
)
from tracer.sources.sun import EnvironmentWithSun, Sun


def _uniform_sphere(n: int, seed: int) -> np.ndarray:
    """``n`` directions uniformly distributed over the unit sphere, shape (n, 3)."""
    d = np.random.default_rng(seed).normal(size=(n, 3))
    return d / np.linalg.norm(d, axis=1, keepdims=True)


def _rows(env, d) -> np.ndarray:
    """The environment's radiance for directions given as rows (n, 3), as rows (n, 3) (the tracer
    works on (3, n) planes)."""
    return env.radiance(np.asarray(d, dtype=np.float64).T).T


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
    radiance = _rows(env, centres.reshape(-1, 3))
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
    np.testing.assert_allclose(_rows(env, np.array([direction], float)), [[1.0, 1.0, 1.0]])
    assert _rows(env, -np.array([direction], float)).max() == 0.0


def test_top_row_is_up():
    image = np.zeros((4, 8, 3))
    image[0] = 5.0
    env = HdriEnvironment(image, "scale", 1.0)
    np.testing.assert_allclose(_rows(env, np.array([[0.0, 0.0, 1.0]])), [[5.0, 5.0, 5.0]])
    np.testing.assert_allclose(_rows(env, np.array([[0.0, 0.0, -1.0]])), [[0.0, 0.0, 0.0]])


def test_wraps_across_the_seam():
    image = np.zeros((2, 8, 3))
    image[:, 0] = 2.0  # left column
    image[:, -1] = 4.0  # right column
    env = HdriEnvironment(image, "scale", 1.0)
    # -x lies on the seam, midway between the centres of the last and first columns.
    np.testing.assert_allclose(_rows(env, np.array([[-1.0, 0.0, 0.0]])), [[3.0, 3.0, 3.0]])


# --- rotation -------------------------------------------------------------------------------


def test_rotation_by_90_degrees_moves_the_centre_from_x_to_y():
    image = _feature_image(8, 16, 0.5, 0.5)  # feature at +x
    x, y, minus_y = np.array([[1.0, 0, 0]]), np.array([[0, 1.0, 0]]), np.array([[0, -1.0, 0]])
    env = HdriEnvironment(image, "scale", 1.0, rotation_deg=90.0)
    np.testing.assert_allclose(_rows(env, y), [[1.0, 1.0, 1.0]], atol=1e-12)
    assert _rows(env, x).max() < 1e-12
    env = HdriEnvironment(image, "scale", 1.0, rotation_deg=-90.0)
    np.testing.assert_allclose(_rows(env, minus_y), [[1.0, 1.0, 1.0]], atol=1e-12)


def test_rotation_turns_the_whole_panorama_counter_clockwise():
    image = np.random.default_rng(3).random((16, 32, 3))
    env = HdriEnvironment(image, "scale", 1.0)
    turned = HdriEnvironment(image, "scale", 1.0, rotation_deg=37.0)
    d = _uniform_sphere(500, seed=4)
    np.testing.assert_allclose(_rows(turned, d @ _rot_z(37.0).T), _rows(env, d), atol=1e-12)


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
    np.testing.assert_allclose(_rows(env, d), np.tile([1.5, 3.0, 6.0], (len(d), 1)), rtol=1e-14)


def test_scale_calibration():
    image = np.random.default_rng(6).random((6, 12, 3))
    env = HdriEnvironment(image, "scale", 250.0)
    assert env.scale_factor == 250.0
    centres = _pixel_centre_directions(6, 12).reshape(-1, 3)
    np.testing.assert_allclose(_rows(env, centres), 250.0 * image.reshape(-1, 3), rtol=1e-12)
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
    assert luminance(_rows(env, d)).mean() == pytest.approx(20.0, rel=0.01)


def test_max_calibration():
    image = np.random.default_rng(10).random((8, 16, 3))
    env = HdriEnvironment(image, "max", 5000.0)
    assert env.max_luminance == pytest.approx(5000.0, rel=1e-14)
    Y = luminance(image)
    row, col = np.unravel_index(np.argmax(Y), Y.shape)
    brightest = _pixel_centre_directions(8, 16)[row, col][None, :]
    assert luminance(_rows(env, brightest))[0] == pytest.approx(5000.0, rel=1e-12)
    assert luminance(_rows(env, _uniform_sphere(20_000, seed=11))).max() <= 5000.0 * (1 + 1e-12)


def test_min_calibration():
    image = 0.2 + np.random.default_rng(15).random((8, 16, 3))
    env = HdriEnvironment(image, "min", 30.0)
    assert env.min_luminance == pytest.approx(30.0, rel=1e-14)
    Y = luminance(image)
    row, col = np.unravel_index(np.argmin(Y), Y.shape)
    darkest = _pixel_centre_directions(8, 16)[row, col][None, :]
    assert luminance(_rows(env, darkest))[0] == pytest.approx(30.0, rel=1e-12)
    assert luminance(_rows(env, _uniform_sphere(20_000, seed=16))).min() >= 30.0 * (1 - 1e-12)
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
    y = luminance(_rows(env, _uniform_sphere(400_000, seed=17)))
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
    np.testing.assert_array_equal(_rows(env, np.array([[1.0, 0, 0]])), [[2.0, 2.0, 2.0]])
    assert _rows(env, np.array([[1.0, 0, 0]])).dtype == np.float64


# --- no environment, uniform environment -------------------------------------------------------


def test_no_environment():
    env = NoEnvironment()
    r = _rows(env, _uniform_sphere(5, seed=12))
    assert r.shape == (5, 3) and r.dtype == np.float64 and not r.any()
    assert env.is_black and env.mean_luminance == 0.0 and env.max_luminance == 0.0


def test_uniform_environment():
    env = UniformEnvironment(300.0, color=(1.0, 0.5, 0.25))
    r = _rows(env, _uniform_sphere(7, seed=13))
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
            _rows(env, np.ones(3))
        with pytest.raises(ValueError):
            _rows(env, np.array([[np.nan, 0.0, 1.0]]))


# --- the sun --------------------------------------------------------------------------------


def test_sun_luminance_is_its_illuminance_over_pi_sin2_delta():
    """L = E / (pi sin^2 delta): 1.488e9 cd/m^2 for 100,000 lx at 0.53 deg. A second method: the
    illuminance on a surface facing the disk, 2 pi L integral_0^delta cos(theta) sin(theta) d theta,
    by Gauss-Legendre quadrature, is E again."""
    sun = Sun([0.0, 0.0, 1.0])
    assert sun.illuminance_lux == 100_000.0 and sun.angular_diameter_deg == 0.53
    delta = math.radians(0.53) / 2
    assert sun.luminance_cd_m2 == pytest.approx(1e5 / (math.pi * math.sin(delta) ** 2), rel=1e-14)
    assert sun.luminance_cd_m2 == pytest.approx(1.488e9, rel=1e-3)
    nodes, weights = np.polynomial.legendre.leggauss(16)
    theta = 0.5 * delta * (nodes + 1.0)
    e = 2 * math.pi * sun.luminance_cd_m2 * 0.5 * delta * np.sum(weights * np.cos(theta) * np.sin(theta))
    assert e == pytest.approx(1e5, rel=1e-12)
    assert sun.solid_angle_sr == pytest.approx(2 * math.pi * (1 - math.cos(delta)), rel=1e-9)
    assert sun.power == pytest.approx(2e5 / (1 + math.cos(delta)), rel=1e-12)
    for e_lux, diameter in [(120_000.0, 0.53), (1.0, 20.0), (5e4, 0.01)]:
        s = Sun([1.0, 2.0, 3.0], e_lux, diameter)
        assert s.luminance_cd_m2 * math.pi * math.sin(math.radians(diameter) / 2) ** 2 == pytest.approx(e_lux)


def test_sun_disk_edges_and_colour():
    """Radiance L colour inside the disk (float64 and float32 directions alike), 0 outside, with the rim
    resolved to 1 % of the 0.265 deg radius; the colour keeps unit luminance."""
    axis = np.array([0.2, -0.6, 0.7]) / np.linalg.norm([0.2, -0.6, 0.7])
    sun = Sun(axis * 3.0, 80_000.0, 0.53, color=(1.0, 0.8, 0.5))
    np.testing.assert_allclose(sun.direction, axis, rtol=1e-15)
    t = np.cross(axis, [1.0, 0.0, 0.0])
    t /= np.linalg.norm(t)
    delta = math.radians(0.53) / 2
    angles = np.array([0.0, 0.5, 0.99, 1.01, 2.0, 90.0 / 0.265]) * delta
    d = np.cos(angles)[:, None] * axis + np.sin(angles)[:, None] * t
    for dtype in (np.float64, np.float32):
        y = luminance(_rows(sun, d.astype(dtype)))
        np.testing.assert_allclose(y, [sun.luminance_cd_m2] * 3 + [0.0] * 3, rtol=1e-12)
        np.testing.assert_allclose(sun.pdf(d.astype(dtype).T), [1 / sun.solid_angle_sr] * 3 + [0.0] * 3)
    rgb = _rows(sun, d[:1])[0]
    np.testing.assert_allclose(rgb / rgb[0], [1.0, 0.8, 0.5], rtol=1e-12)


@pytest.mark.parametrize("incidence_deg", [0.0, 40.0, 89.0])
def test_sun_illuminance_on_a_tilted_surface_is_e_cos_i(incidence_deg):
    """The mean of L max(0, n.d) / pdf over the sun's own samples is the illuminance on a surface whose
    normal n makes the angle i with the sun: E cos(i), exactly while the disk lies above the surface's
    horizon (here up to 89 deg), within the estimate's standard error."""
    sun = Sun([0.0, 0.0, 1.0], 100_000.0, 0.53)
    i = math.radians(incidence_deg)
    normal = np.array([math.sin(i), 0.0, math.cos(i)])
    d, radiance, pdf = sun.sample(np.random.default_rng(18).random((2, 200_000)))
    np.testing.assert_allclose(np.linalg.norm(d, axis=0), 1.0, rtol=1e-14)
    assert np.all(sun.pdf(d) == pdf) and np.all(luminance(radiance.T) == sun.luminance_cd_m2)
    e = luminance(radiance.T) * np.maximum(normal @ d, 0.0) / pdf
    sem = e.std() / math.sqrt(len(e))
    assert abs(e.mean() - 1e5 * math.cos(i)) < z_bound(3) * sem + 1e-9 * 1e5


def test_environment_with_sun_adds_the_sun_to_every_figure():
    sun = Sun([0.0, 1.0, 0.0], 50_000.0, 1.0)
    sky = UniformEnvironment(200.0)
    env = EnvironmentWithSun(sky, sun)
    assert env.mean_luminance == pytest.approx(200.0 + sun.power / (4 * math.pi), rel=1e-14)
    assert env.max_luminance == pytest.approx(200.0 + sun.luminance_cd_m2, rel=1e-14)
    assert env.sun_share == pytest.approx(sun.power / (sun.power + 4 * math.pi * 200.0), rel=1e-14)
    np.testing.assert_allclose(luminance(_rows(env, [[0.0, 1.0, 0.0], [0.0, -1.0, 0.0]])),
                               [200.0 + sun.luminance_cd_m2, 200.0], rtol=1e-12)
    assert not env.is_black and not EnvironmentWithSun(NoEnvironment(), sun).is_black
    dark = EnvironmentWithSun(NoEnvironment(), Sun([0.0, 1.0, 0.0], 0.0))
    assert dark.is_black and dark.sun_share == 0.0
    hdri = HdriEnvironment(np.random.default_rng(19).random((8, 16, 3)), "mean", 300.0)
    with_sun = EnvironmentWithSun(hdri, sun)
    assert hdri.mean_luminance == pytest.approx(300.0) and with_sun.base is hdri  # calibrated before the sun


def test_sun_rejects_bad_input():
    for kwargs in [{"direction": [0.0, 0.0, 0.0]}, {"direction": [np.nan, 0.0, 1.0]},
                   {"direction": [0, 0, 1], "illuminance_lux": -1.0},
                   {"direction": [0, 0, 1], "illuminance_lux": np.inf},
                   {"direction": [0, 0, 1], "angular_diameter_deg": 0.0},
                   {"direction": [0, 0, 1], "angular_diameter_deg": 20.5},
                   {"direction": [0, 0, 1], "color": (0.0, 0.0, 0.0)}]:
        with pytest.raises(ValueError):
            Sun(**kwargs)


# --- environment_from_spec ------------------------------------------------------------------


@pytest.fixture
def scene_dir(tmp_path):
    """A scene folder with panoramas good and bad."""
    textures = tmp_path / "textures"
    textures.mkdir()
    rng = np.random.default_rng(14)
    rgb = rng.random((8, 16, 3))
    write_exr(textures / "sky.exr", {"R": rgb[..., 0], "G": rgb[..., 1], "B": rgb[..., 2]})
    write_exr(textures / "black.exr", {c: np.zeros((4, 8)) for c in "RGB"})
    one_black = np.ones((4, 8))
    one_black[1, 3] = 0.0
    write_exr(textures / "one_black.exr", {c: one_black for c in "RGB"})
    write_exr(textures / "negative.exr", {c: np.full((4, 8), -1.0) for c in "RGB"})
    write_exr(textures / "five.exr", {c: np.ones((4, 8)) for c in ["R", "G", "B", "Y", "Y_var"]})
    write_exr(textures / "rgba.exr", {"R": np.ones((4, 8)), "G": np.ones((4, 8)),
                                      "B": np.ones((4, 8)), "A": np.full((4, 8), 0.5)})
    grey = oiio.ImageOutput.create("png")
    assert grey.open(str(textures / "grey.png"), oiio.ImageSpec(8, 4, 1, oiio.UINT8))
    assert grey.write_image(np.full((4, 8, 1), 128, np.uint8)) and grey.close()
    (textures / "corrupt.exr").write_bytes(b"not an EXR file at all")
    return tmp_path


def test_spec_none_and_uniform(scene_dir):
    assert isinstance(environment_from_spec({"type": "none"}, scene_dir), NoEnvironment)
    env = environment_from_spec({"type": "uniform", "luminance": 10}, scene_dir)
    assert isinstance(env, UniformEnvironment) and env.mean_luminance == 10.0
    env = environment_from_spec(_uniform(luminance=5.0, color=[0, 1, 0]), scene_dir)
    np.testing.assert_allclose(_rows(env, np.array([[0, 0, 1.0]])), [[0, 5.0 / 0.7152, 0]])


def test_spec_hdri(scene_dir):
    spec = {
        "type": "hdri",
        "file": "textures/sky.exr",
        "calibration": {"mode": "mean", "value": 800},
        "rotation_deg": 45,
    }
    env = environment_from_spec(spec, scene_dir)
    assert isinstance(env, HdriEnvironment)
    assert env.mean_luminance == pytest.approx(800.0, rel=1e-9)
    assert env.rotation_deg == 45.0 and env.source == "textures/sky.exr"
    assert env.calibration == "mean" and env.value == 800.0 and env.scale_factor > 0


def test_spec_sun(scene_dir):
    env = environment_from_spec({"type": "none", "sun": {"direction": [0, 0, 2]}}, scene_dir)
    assert isinstance(env, EnvironmentWithSun) and isinstance(env.base, NoEnvironment)
    sun = env.sun
    np.testing.assert_array_equal(sun.direction, [0.0, 0.0, 1.0])
    assert (sun.illuminance_lux, sun.angular_diameter_deg) == (100_000.0, 0.53)
    np.testing.assert_allclose(sun.color, 1.0)
    assert env.max_luminance == pytest.approx(1.488e9, rel=1e-3) and env.sun_share == 1.0
    spec = {"type": "uniform", "luminance": 50,
            "sun": {"direction": [1, 0, 1], "illuminance_lux": 60_000, "angular_diameter_deg": 2.0,
                    "color": [1.0, 0.9, 0.8]}}
    env = environment_from_spec(spec, scene_dir)
    assert env.base.mean_luminance == 50.0 and env.sun.illuminance_lux == 60_000.0
    assert env.sun.angular_diameter_deg == 2.0
    np.testing.assert_allclose(env.sun.direction, [math.sqrt(0.5), 0.0, math.sqrt(0.5)])
    np.testing.assert_allclose(env.sun.color / env.sun.color[0], [1.0, 0.9, 0.8])
    env = environment_from_spec(_hdri(calibration={"mode": "mean", "value": 800},
                                      sun={"direction": [0, 1, 0.2]}), scene_dir)
    assert isinstance(env.base, HdriEnvironment) and env.base.mean_luminance == pytest.approx(800.0)
    assert env.mean_luminance == pytest.approx(800.0 + env.sun.power / (4 * math.pi))


def test_spec_hdri_grey_png_is_decoded_and_grey(scene_dir):
    env = environment_from_spec(_hdri(file="textures/grey.png", rotation_deg=10), scene_dir)
    np.testing.assert_allclose(_rows(env, np.array([[1.0, 0, 0]])), [[0.2158605] * 3], rtol=1e-6)


def test_spec_hdri_drops_alpha(scene_dir):
    env = environment_from_spec(_hdri(file="textures/rgba.exr"), scene_dir)
    np.testing.assert_array_equal(_rows(env, np.array([[0, 0, 1.0]])), [[1.0, 1.0, 1.0]])


def _hdri(**fields):
    calibration = {"mode": "scale", "value": 1}
    return {"type": "hdri", "file": "textures/sky.exr", "calibration": calibration, **fields}


def _uniform(**fields):
    return {"type": "uniform", "luminance": 1.0, **fields}


def _sun(**fields):
    return {"type": "none", "sun": {"direction": [0, 0, 1], **fields}}


@pytest.mark.parametrize(
    ("spec", "field"),
    [
        ("none", "environment"),
        ({}, "environment.type"),
        ({"type": "sky"}, "environment.type"),
        ({"type": 3}, "environment.type"),
        ({"type": ["hdri"]}, "environment.type"),
        ({"type": "none", "luminance": 1}, "environment.luminance"),
        ({"type": "uniform"}, "environment.luminance"),
        (_uniform(luminance=-1), "environment.luminance"),
        (_uniform(luminance="10"), "environment.luminance"),
        (_uniform(luminance=True), "environment.luminance"),
        (_uniform(luminance=float("nan")), "environment.luminance"),
        (_uniform(luminance=None), "environment.luminance"),
        # positive but below 1e-9 cd/m^2: a black image and no warning before (2026-12-04)
        (_uniform(luminance=1e-300), "environment.luminance"),
        (_uniform(luminance=1e-10), "environment.luminance"),
        (_uniform(color=[1, 1]), "environment.color"),
        (_uniform(color="white"), "environment.color"),
        (_uniform(color=[1, -1, 1]), "environment.color[1]"),
        (_uniform(color=[1, 1, "1"]), "environment.color[2]"),
        (_uniform(color=[0, 0, 0]), "environment.color"),
        (_uniform(colour=[1, 1, 1]), "environment.colour"),
        ({"type": "hdri", "calibration": {"mode": "scale", "value": 1}}, "environment.file"),
        (_hdri(file=3), "environment.file"),
        (_hdri(file=""), "environment.file"),
        (_hdri(file="textures/missing.exr"), "environment.file"),
        (_hdri(file="textures/corrupt.exr"), "environment.file"),
        (_hdri(file="textures/five.exr"), "environment.file"),
        (_hdri(file="textures/negative.exr"), "environment.file"),
        (_hdri(file="textures/black.exr", calibration={"mode": "mean", "value": 1}),
         "environment.file"),
        (_hdri(file="textures/one_black.exr", calibration={"mode": "min", "value": 1}),
         "environment.file"),
        ({"type": "hdri", "file": "textures/sky.exr"}, "environment.calibration"),
        (_hdri(calibration="mean"), "environment.calibration"),
        (_hdri(calibration={"value": 1}), "environment.calibration.mode"),
        (_hdri(calibration={"mode": "median", "value": 1}), "environment.calibration.mode"),
        (_hdri(calibration={"mode": "mean"}), "environment.calibration.value"),
        (_hdri(calibration={"mode": "mean", "value": 0}), "environment.calibration.value"),
        (_hdri(calibration={"mode": "max", "value": -5}), "environment.calibration.value"),
        (_hdri(calibration={"mode": "min", "value": 0}), "environment.calibration.value"),
        (_hdri(calibration={"mode": "min", "value": 2e12}), "environment.calibration.value"),
        (_hdri(calibration={"mode": "max", "value": "5"}), "environment.calibration.value"),
        (_hdri(calibration={"mode": "scale", "value": 1e-12}), "environment.calibration.value"),
        (_hdri(calibration={"mode": "max", "value": 1e-10}), "environment.calibration.value"),
        (_hdri(calibration={"mode": "max", "value": 5, "unit": "nit"}),
         "environment.calibration.unit"),
        (_hdri(rotation_deg="90"), "environment.rotation_deg"),
        (_hdri(rotation_deg=float("inf")), "environment.rotation_deg"),
        (_hdri(rotation=90), "environment.rotation"),
        ({"type": "none", "sun": "up"}, "environment.sun"),
        ({"type": "none", "sun": {}}, "environment.sun.direction"),
        (_sun(direction=[0, 0, 0]), "environment.sun.direction"),
        (_sun(direction=[0, 1]), "environment.sun.direction"),
        (_sun(direction=[0, 1, "1"]), "environment.sun.direction[2]"),
        (_sun(direction=[0, 1, float("nan")]), "environment.sun.direction[2]"),
        (_sun(illuminance_lux=-1), "environment.sun.illuminance_lux"),
        (_sun(illuminance_lux="100 klx"), "environment.sun.illuminance_lux"),
        (_sun(illuminance_lux=2e12), "environment.sun.illuminance_lux"),
        (_sun(illuminance_lux=1e-300), "environment.sun.illuminance_lux"),
        (_sun(angular_diameter_deg=0), "environment.sun.angular_diameter_deg"),
        (_sun(angular_diameter_deg=-0.5), "environment.sun.angular_diameter_deg"),
        (_sun(angular_diameter_deg=20.01), "environment.sun.angular_diameter_deg"),
        (_sun(illuminance_lux=1e6, angular_diameter_deg=1e-4), "environment.sun"),
        (_sun(color=[0, 0, 0]), "environment.sun.color"),
        (_sun(color=[1, -1, 1]), "environment.sun.color[1]"),
        (_sun(elevation_deg=30), "environment.sun.elevation_deg"),
        (_uniform(sun={"direction": [0, 0, 1], "illuminance": 1}), "environment.sun.illuminance"),
        (_hdri(sun={"illuminance_lux": 1}), "environment.sun.direction"),
    ],
)
def test_spec_errors_name_the_field(scene_dir, spec, field):
    with pytest.raises(SceneError) as info:
        environment_from_spec(spec, scene_dir, file="scenes/demo/scene.json")
    assert info.value.field == field
    assert info.value.file == "scenes/demo/scene.json"


def test_unknown_names_are_shown_as_json_not_as_python():
    """A list where a name belongs was echoed as Python's repr (['none'])."""
    for spec, shown in (({"type": ["none"]}, 'unknown type ["none"] (known: none, uniform, hdri)'),
                        (_hdri(calibration={"mode": ["mean"], "value": 1}), 'unknown mode ["mean"] (known: scale')):
        with pytest.raises(SceneError) as info:
            environment_from_spec(spec, Path("."))
        assert shown in info.value.message
    assert info.value.message


def test_spec_hdri_min(scene_dir):
    env = environment_from_spec(_hdri(calibration={"mode": "min", "value": 25}), scene_dir)
    assert env.calibration == "min" and env.min_luminance == pytest.approx(25.0, rel=1e-12)
    with pytest.raises(SceneError) as info:
        environment_from_spec(_hdri(file="textures/one_black.exr", calibration={"mode": "min", "value": 1}),
                              scene_dir)
    assert "textures/one_black.exr" in info.value.message and "black" in info.value.message


def test_spec_unreadable_image_reports_the_reason(scene_dir):
    with pytest.raises(SceneError) as info:
        environment_from_spec(_hdri(file="textures/missing.exr"), scene_dir)
    assert "textures/missing.exr" in info.value.message
    assert info.value.file == "scene.json"


# --- presets/hdri.py: Blender's studio panoramas and their figures ---------------------------------

_NO_BPY = importlib.util.find_spec("bpy") is None
_needs_bpy = pytest.mark.skipif(_NO_BPY, reason="the studio panoramas ship inside the bpy package "
                                                "(pip install bpy==4.5.15)")


@_needs_bpy
def test_studio_hdri_finds_every_panorama_without_importing_bpy():
    """Each of the eight panoramas is found inside the installed bpy package, in a child process that
    never imports bpy (importing it takes seconds), and loads as an environment."""
    from presets.hdri import STUDIO_HDRIS

    code = ("import sys; from presets.hdri import STUDIO_HDRIS, studio_hdri; "
            "print([str(studio_hdri(n)) for n in STUDIO_HDRIS]); print('bpy' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True,
                         cwd=Path(__file__).resolve().parents[1]).stdout.splitlines()
    paths = [Path(p) for p in ast.literal_eval(out[0])]
    assert out[1] == "False"
    package = Path(importlib.util.find_spec("bpy").origin).parent
    for name, path in zip(STUDIO_HDRIS, paths, strict=True):
        assert path.name == f"{name}.exr" and path.is_file() and path.is_relative_to(package)
    env = environment_from_spec({"type": "hdri", "file": str(paths[0]), "calibration": {"mode": "mean", "value": 2e3}},
                                Path("."), allow_external=True)
    assert env.mean_luminance == pytest.approx(2000.0)


def test_studio_hdri_says_where_the_panorama_comes_from(monkeypatch):
    """Without bpy: one ValueError naming the panorama, the bpy package, its pip line and the way out (a
    file); an unknown name lists the eight."""
    import presets.hdri as hdri

    monkeypatch.setattr(hdri.importlib.util, "find_spec", lambda name: None)
    with pytest.raises(ValueError) as info:
        hdri.studio_hdri("forest")
    message = str(info.value)
    for words in ("'forest'", "bpy", "pip install bpy==4.5.15", "file"):
        assert words in message, message
    with pytest.raises(ValueError, match="city, courtyard, forest, interior, night, studio, sunrise, sunset"):
        hdri.studio_hdri("beach")


def test_studio_hdri_inside_blender(tmp_path, monkeypatch):
    """Inside Blender itself bpy is <version>/scripts/modules/bpy and the panoramas are in
    <version>/datafiles/studiolights/world: found there too."""
    import types

    import presets.hdri as hdri

    package = tmp_path / "4.5" / "scripts" / "modules" / "bpy"
    package.mkdir(parents=True)
    (package / "__init__.py").write_text("")
    world = tmp_path / "4.5" / "datafiles" / "studiolights" / "world"
    world.mkdir(parents=True)
    (world / "night.exr").write_bytes(b"exr")
    monkeypatch.setattr(hdri.importlib.util, "find_spec",
                        lambda name: types.SimpleNamespace(origin=str(package / "__init__.py")))
    assert hdri.studio_hdri("night") == world / "night.exr"
    with pytest.raises(ValueError, match="pip install"):
        hdri.studio_hdri("city")


def test_panorama_stats_against_a_panorama_of_known_figures(tmp_path):
    """An 8 x 16 panorama whose row i (0 at the top) has luminance i + 1, one pixel of the top row black:
    min 0, max 8, the mean over the rows' exact solid angles, and percentiles by solid angle: the top row
    (3.8 % of the sphere) holds the 1st percentile's value 1 (the black pixel covers only 0.24 %), the
    bottom row (the same 3.8 %) the 99th's value 8."""
    from presets.hdri import panorama_stats

    rows = np.arange(1.0, 9.0)
    image = np.repeat(np.repeat(rows[:, None], 16, axis=1)[..., None], 3, axis=2)
    image[0, 3] = 0.0
    write_exr(tmp_path / "rows.exr", {c: image[..., i] for i, c in enumerate("RGB")})
    st = panorama_stats(tmp_path / "rows.exr")
    f = row_solid_angle_fractions(8)
    assert (st["min"], st["max"], st["black_pixels"], st["negative_values"]) == (0.0, 8.0, 1, 0)
    assert (st["width"], st["height"]) == (16, 8)
    assert st["mean"] == pytest.approx(f @ rows - f[0] / 16 * 1.0, rel=1e-12)
    assert f[0] / 16 < 0.01 < f[0] and f[-1] > 0.01
    assert st["p01"] == 1.0 and st["p99"] == 8.0


@_needs_bpy
@pytest.mark.parametrize("name", ["city", "night"])
def test_panorama_stats_of_a_studio_panorama_agree_with_the_environment(name, tmp_path):
    """The panorama copied into a scene folder (copy_panorama: night.exr has 250 slightly negative colour
    components from its lossy compression, city.exr none) loads as an environment whose min, mean and max
    (scale 1) are the copy's figures; the percentiles cut the sphere's solid angle at 1 % and 99 % (the
    pixels below p01 cover less than 1 % of it, those at or below it at least 1 %)."""
    from presets.hdri import copy_panorama, panorama_stats, studio_hdri
    from tracer.core.imageio import read_image

    raw = panorama_stats(studio_hdri(name))
    negative = copy_panorama(studio_hdri(name), tmp_path / "textures" / "sky.exr")
    assert negative == raw["negative_values"] and (negative > 0) == (name == "night")
    st = panorama_stats(tmp_path / "textures" / "sky.exr")
    assert st["negative_values"] == 0 and st["mean"] == pytest.approx(raw["mean"], rel=1e-6)
    env = environment_from_spec({"type": "hdri", "file": "textures/sky.exr", "calibration": {"mode": "scale",
                                                                                             "value": 1}}, tmp_path)
    assert st["mean"] == pytest.approx(env.mean_luminance, rel=1e-12)
    assert st["min"] == pytest.approx(env.min_luminance, rel=1e-12)
    assert st["max"] == pytest.approx(env.max_luminance, rel=1e-12)
    y = luminance(read_image(tmp_path / "textures" / "sky.exr")[..., :3])
    omega = np.broadcast_to(row_solid_angle_fractions(y.shape[0])[:, None] / y.shape[1], y.shape)
    for q, value in ((0.01, st["p01"]), (0.99, st["p99"])):
        assert omega[y < value].sum() < q <= omega[y <= value].sum()
    assert st["min"] < st["p01"] < st["mean"] and st["p99"] < st["max"]
