"""The sun of an environment (tracer.sources.sun: Sun, EnvironmentWithSun): its luminance, disk and colour,
its illuminance on a tilted surface, bad input; its sampling against its density by chi-square (the sun a
small part of the power, and nearly all of it), the mixture's estimate of the power, and renders against
closed forms: a Lambertian floor lit by the sun reads rho E sin(h) / pi (0 with the sun below its horizon),
and a sun in direct view shows its luminance E / (pi sin^2 delta) and delivers its illuminance E to the
pupil."""

from __future__ import annotations

import math

import numpy as np
import pytest

from presets._build import SceneBuilder, rectangle
from tests.support.chi2 import ChiSquareTest
from tests.support.environment import radiance_rows
from tests.support.render import render
from tests.support.stats import film_dof, t_bound, z_bound
from tracer.core.sampling import make_rng
from tracer.core.units import luminance, luminance3
from tracer.sources.environment import (
    HdriEnvironment,
    NoEnvironment,
    UniformEnvironment,
    direction_to_equirect,
    equirect_to_direction,
)
from tracer.sources.sun import EnvironmentWithSun, Sun

# --- the sun and its figures ------------------------------------------------------------------


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
        y = luminance(radiance_rows(sun, d.astype(dtype)))
        np.testing.assert_allclose(y, [sun.luminance_cd_m2] * 3 + [0.0] * 3, rtol=1e-12)
        np.testing.assert_allclose(sun.pdf(d.astype(dtype).T), [1 / sun.solid_angle_sr] * 3 + [0.0] * 3)
    rgb = radiance_rows(sun, d[:1])[0]
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
    np.testing.assert_allclose(luminance(radiance_rows(env, [[0.0, 1.0, 0.0], [0.0, -1.0, 0.0]])),
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


# --- sampling -----------------------------------------------------------------------------------


#: Sidak family of the chi-square tests of the sun's sampling.
CHI2_TESTS = 5

#: A direction toward the sun, not along any axis.
SUN_DIRECTION = np.array([0.3, -0.5, 0.8]) / np.linalg.norm([0.3, -0.5, 0.8])


def _uniform_base_for_share(sun: Sun, share: float) -> UniformEnvironment:
    """A uniform sky whose power makes the sun ``share`` of the total: 4 pi L = P_sun (1 - share) / share."""
    return UniformEnvironment(sun.power * (1.0 - share) / share / (4.0 * math.pi))


def _sun_frame(axis: np.ndarray):
    """An orthonormal (t, b) perpendicular to ``axis`` (3,), built here with numpy (not the tracer's frame)."""
    t = np.cross(axis, [1.0, 0.0, 0.0] if abs(axis[0]) < 0.9 else [0.0, 1.0, 0.0])
    t /= np.linalg.norm(t)
    return t, np.cross(axis, t)


@pytest.mark.parametrize("base", ["none", "sky 0.05", "sky 0.999"])
def test_chi2_sun_mixture_in_the_suns_frame(base):
    """Directions of the mixture (a real 0.53 deg sun plus a uniform sky that carries 95 %, 0.1 % or none
    of the power) mapped to (phi, y = ln(1 - cos theta)) about the sun's axis, where d omega = e^y dphi dy:
    the log axis resolves the disk (1 - cos delta = 1.07e-5) with 48 rows and the sky out to the
    antipode with 96, and the disk's rim lies on a cell edge, so the density's jump there is integrated
    exactly. The expected density is the reported pdf(d) e^y; the sampler's own density equals pdf(d)
    and its radiance radiance(d)."""
    sun = Sun(SUN_DIRECTION)
    env = EnvironmentWithSun(NoEnvironment() if base == "none" else
                             _uniform_base_for_share(sun, float(base.split()[1])), sun)
    if base != "none":
        assert env.sun_share == pytest.approx(float(base.split()[1]), rel=1e-12)
    t, b = _sun_frame(sun.direction)
    y_rim = math.log(sun.one_minus_cos)
    h = (math.log(2.0) - y_rim) / 96
    bounds = ((0.0, 2 * math.pi), (y_rim - 48 * h, math.log(2.0)))

    def sample(n, rng):
        d, radiance, pdf = env.sample(rng.random((2, n)))
        np.testing.assert_allclose(pdf, env.pdf(d), rtol=1e-12)
        np.testing.assert_allclose(radiance, env.radiance(d), rtol=1e-12)
        np.testing.assert_allclose(np.linalg.norm(d, axis=0), 1.0, atol=1e-7)
        one_minus_cos = 1.0 - (sun.direction @ d) / np.linalg.norm(d, axis=0)
        phi = np.arctan2(b @ d, t @ d) % (2 * math.pi)
        y = np.log(np.maximum(one_minus_cos, 1e-300))
        return np.stack([phi, y], axis=-1), pdf > 0

    def density(phi, y):
        x = np.exp(y)  # 1 - cos(theta)
        sin = np.sqrt(x * (2.0 - x))
        d = (np.cos(phi) * sin)[None] * t[:, None] + (np.sin(phi) * sin)[None] * b[:, None] + \
            (1.0 - x)[None] * sun.direction[:, None]
        return env.pdf(d) * x

    test = ChiSquareTest(bounds, (32, 144), sample, density, 500_000, seed=3)
    ok, msg = test.run(0.01, CHI2_TESTS)
    assert ok, msg


@pytest.mark.parametrize("share", [0.05, 0.99])
def test_chi2_sun_over_a_panorama(share):
    """A structured, rotated panorama (a bright patch, a black band) with a sun at the zenith, where the
    disk is a band of the panorama's own (u, v) coordinates: with an angular radius of pi / 64 its rim
    lies on a cell edge of a grid that also refines the pixels, so no cell straddles a jump of the
    mixture's density. The panorama's scale gives the sun 5 % or 99 % of the power; the expected density
    is pdf(d) d omega / (du dv) = pdf(d) 2 pi^2 cos(latitude)."""
    h, w = 32, 64
    rng = make_rng(7)
    image = rng.random((h, w, 3)) ** 4
    image[5:8, 40:44] = 50.0
    image[:, :5] = 0.0
    sun = Sun([0.0, 0.0, 1.0], 1e5, math.degrees(2 * math.pi / 64))
    raw = HdriEnvironment(image, "scale", 1.0)
    base = HdriEnvironment(image, "scale", sun.power * (1 - share) / share / (4 * math.pi * raw.mean_luminance),
                           rotation_deg=30.0)
    env = EnvironmentWithSun(base, sun)
    assert env.sun_share == pytest.approx(share, rel=1e-12)
    a = math.radians(30.0)

    def to_world(local):
        return np.stack([math.cos(a) * local[0] - math.sin(a) * local[1],
                         math.sin(a) * local[0] + math.cos(a) * local[1], local[2]])

    def sample(n, rng):
        d, radiance, pdf = env.sample(rng.random((2, n)))
        np.testing.assert_allclose(pdf, env.pdf(d), rtol=1e-12)
        u, v = direction_to_equirect(base._to_image(d))
        return np.stack([u, v], axis=-1), pdf > 0

    def density(u, v):
        return env.pdf(to_world(equirect_to_direction(u, v))) * 2 * np.pi**2 * np.cos(np.pi * (v - 0.5))

    test = ChiSquareTest(((0.0, 1.0), (0.0, 1.0)), (2 * w, 4 * h), sample, density, 500_000, seed=5)
    ok, msg = test.run(0.01, CHI2_TESTS)
    assert ok, msg


def test_a_wrong_share_is_rejected():
    """The same chi-square, with a density that claims the sun carries 4 % where it carries 5 %: rejected
    (the test can fail)."""
    sun = Sun(SUN_DIRECTION)
    env = EnvironmentWithSun(_uniform_base_for_share(sun, 0.05), sun)
    t, b = _sun_frame(sun.direction)
    y_rim = math.log(sun.one_minus_cos)
    h = (math.log(2.0) - y_rim) / 96

    def sample(n, rng):
        d = env.sample(rng.random((2, n)))[0]
        return np.stack([np.arctan2(b @ d, t @ d) % (2 * math.pi),
                         np.log(np.maximum(1.0 - sun.direction @ d, 1e-300))], axis=-1), np.ones(n, bool)

    def wrong(phi, y):
        x = np.exp(y)
        inside = x <= sun.one_minus_cos
        return np.where(inside, 0.04 / sun.solid_angle_sr, 0.0) * x + 0.96 / (4 * math.pi) * x

    ok, msg = ChiSquareTest(((0.0, 2 * math.pi), (y_rim - 48 * h, math.log(2.0))), (32, 144), sample, wrong,
                            500_000, seed=3).run(0.01, 1)
    assert not ok, msg


@pytest.mark.parametrize("share", [0.02, 0.98])
def test_the_mixture_estimates_the_power_of_sky_and_sun(share):
    """The mean of Y(radiance) / pdf over the mixture's samples is the integral of the luminance over the
    sphere, 4 pi mean_luminance = 4 pi (the panorama's calibrated mean) + P_sun, for a sun in a generic
    direction over a panorama."""
    image = make_rng(9).random((16, 32, 3)) + 0.1
    sun = Sun(SUN_DIRECTION, 80_000.0, 0.53, color=(1.0, 0.9, 0.7))
    sky_mean = sun.power * (1 - share) / share / (4 * math.pi)
    env = EnvironmentWithSun(HdriEnvironment(image, "mean", sky_mean, rotation_deg=-50.0), sun)
    assert env.mean_luminance == pytest.approx(sky_mean + sun.power / (4 * math.pi), rel=1e-12)
    d, radiance, pdf = env.sample(make_rng(10).random((2, 400_000)))
    est = luminance3(radiance) / pdf
    sem = est.std() / math.sqrt(len(est))
    assert abs(est.mean() - 4 * math.pi * env.mean_luminance) < z_bound(2) * sem
    assert sem < 0.01 * est.mean()


# --- renders --------------------------------------------------------------------------------------


RHO = 0.5  #: the floor's albedo
E_SUN = 100_000.0  #: lx


def _sun_direction(elevation_deg: float, azimuth_deg: float = 35.0) -> list[float]:
    h, a = math.radians(elevation_deg), math.radians(azimuth_deg)
    return [math.cos(h) * math.cos(a), math.cos(h) * math.sin(a), math.sin(h)]


def _floor_scene(folder, environment: dict):
    """A 4 m square Lambertian floor (albedo RHO) at z = 0, seen from 500 mm straight above through a
    10 deg field of 8 x 8 pixels."""
    sb = SceneBuilder(folder, "sunlit floor", "a Lambertian floor under the sun")
    sb.add("floor", rectangle(4000.0, 4000.0), {"type": "lambertian", "reflectance": RHO})
    return sb.write(eye={"position": [0, 0, 500], "gaze": [0, 0, -1], "up": [0, 1, 0], "pupil_diameter_mm": 4.0,
                         "focal_length_mm": 16.67, "accommodation_distance_mm": 500.0,
                         "resolution": [8, 8], "fov_deg": [10.0, 10.0]}, environment=environment)


@pytest.mark.parametrize("elevation,sky", [(30.0, 0.0), (70.0, 0.0), (30.0, 1000.0)])
def test_floor_lit_by_the_sun_reads_rho_e_sin_h_over_pi(tmp_path, elevation, sky):
    """The sun at elevation h (the whole disk above the horizon) gives the floor E sin(h) exactly (the
    integral of the direction over the disk is along its axis); a uniform sky L_s adds pi L_s: the floor
    reads rho (E sin h / pi + L_s). Backward with next-event estimation finds the sun by its cone: all of
    the sun's part of the estimate comes through connections, and 300,000 rays (4,700 per pixel) leave a
    relative standard error below 0.05 % per pixel under the sun alone (1.1e-4 measured at 30 deg)."""
    sun = {"direction": _sun_direction(elevation), "illuminance_lux": E_SUN}
    env = {"type": "none", "sun": sun} if sky == 0 else {"type": "uniform", "luminance": sky, "sun": sun}
    folder = _floor_scene(tmp_path / "floor", env)
    y, var, res = render(folder, "backward", 300_000)
    expected = RHO * (E_SUN * math.sin(math.radians(elevation)) / math.pi + sky)
    sigma = np.sqrt(var)
    assert np.all(np.abs(y - expected) < t_bound(y.size * 3, film_dof(res.film)) * sigma), (y.mean(), expected)
    sem = math.sqrt(var.sum()) / y.size
    assert abs(y.mean() - expected) < z_bound(3) * sem
    # Under the sun alone the noise is the disk's cos(i) spread; a sky adds its own (sampled uniformly).
    assert np.all(sigma < (5e-4 if sky == 0 else 1e-2) * expected), sigma.max() / expected
    # The sun's light comes through connections (the sky's mostly through the paths' own hits, which
    # multiple importance sampling prefers where the BSDF's density beats the sky's).
    sun_part = RHO * E_SUN * math.sin(math.radians(elevation)) / math.pi
    assert res.extra["connection_share"] > 0.999 * sun_part / expected


def test_sun_below_the_floors_horizon_leaves_it_black(tmp_path):
    folder = _floor_scene(tmp_path / "night", {"type": "none", "sun": {"direction": _sun_direction(-20.0)}})
    y, var, res = render(folder, "backward", 100_000)
    assert np.all(y == 0.0) and np.all(var == 0.0)


def test_a_sun_in_direct_view_shows_its_luminance_and_delivers_its_illuminance(tmp_path):
    """An eye looking at the sun through nothing (1 deg field, 40 x 40 pixels, focused at infinity): every
    pixel wholly inside the disk reads L = E / (pi sin^2 delta) (1.49e9 cd/m^2 for 100,000 lx at 0.53 deg),
    every pixel wholly outside it 0; and the image delivers the sun's illuminance to the pupil: the sum of
    Y G_pix over the pixels, over the pupil's area, is E (tracer.transport.eye: the flux of a pixel is its luminance
    times its extent G_pix)."""
    from tracer.scene import load_scene
    from tracer.transport.eye import ThinLensEye

    direction = np.array(_sun_direction(40.0, 20.0))
    sb = SceneBuilder(tmp_path / "sky", "sun in view", "the sun seen through nothing")
    folder = sb.write(eye={"position": [0, 0, 0], "gaze": direction.tolist(), "up": [0, 0, 1],
                           "pupil_diameter_mm": 3.0, "focal_length_mm": 16.67, "accommodation_distance_mm": "infinity",
                           "resolution": [40, 40], "fov_deg": [1.0, 1.0]},
                      environment={"type": "none", "sun": {"direction": direction.tolist(), "illuminance_lux": E_SUN}})
    scene = load_scene(folder)
    sun = scene.environment.sun
    assert sun.luminance_cd_m2 == pytest.approx(1.488e9, rel=1e-3)
    y, var, res = render(folder, "backward", 400_000)
    eye = ThinLensEye(scene.eye)
    # Angle of every pixel's centre from the sun's centre, and the pixel's angular half-diagonal.
    sx, sy = eye.pixel_centers()
    gx, gy = np.meshgrid(sx, sy)
    angle = np.arctan(np.hypot(gx, gy) / eye.focal)
    half_diagonal = math.hypot(eye.pixel_w, eye.pixel_h) / (2 * eye.focal)
    delta = math.radians(0.53) / 2
    inside, outside = angle + half_diagonal < delta, angle - half_diagonal > delta
    assert inside.sum() > 200 and outside.sum() > 500
    sigma = np.sqrt(var)
    assert np.all(np.abs(y[inside] - sun.luminance_cd_m2) < t_bound(inside.sum(), film_dof(res.film)) * sigma[inside]
                  + 1e-6 * sun.luminance_cd_m2)
    assert np.all(y[outside] == 0.0)
    g = eye.extent.reshape(y.shape)
    illuminance = (y * g).sum() / eye.pupil_area
    sem = math.sqrt((var * g * g).sum()) / eye.pupil_area
    assert abs(illuminance - E_SUN) < z_bound(1) * sem + 1e-6 * E_SUN, (illuminance, sem)
    assert sem < 0.01 * E_SUN
