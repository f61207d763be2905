"""Analytic shapes (tracer/optics/shapes.py): each sag against its closed form, each gradient against
central differences of the sag, and the implicit form's distance against points placed off the surface."""

import numpy as np
import pytest

from tracer.optics.shapes import SHAPES, Biconic, Conic, XYPolynomial, distance

SHAPE_CASES = {
    "sphere": Conic(1 / 400.0),
    "convex sphere": Conic(-1 / 250.0),
    "paraboloid": Conic(1 / 300.0, -1.0),
    "prolate ellipsoid": Conic(1 / 359.7, -0.467),
    "oblate ellipsoid": Conic(1 / 500.0, 0.6),
    "hyperboloid": Conic(1 / 200.0, -2.5),
    "biconic": Biconic(1 / 3000.0, 1 / 9000.0, -0.3, 0.8),
    "cylinder": Biconic(0.0, 1 / 700.0),
    "xy polynomial": XYPolynomial(Conic(1 / 800.0, -0.2), [(2, 0, 1e-4), (0, 2, -2e-4), (2, 1, 3e-7), (0, 3, 1e-7),
                                                            (4, 0, -1e-9)]),
}


def _points(n=400, half=80.0):
    rng = np.random.default_rng(7)
    return rng.uniform(-half, half, n), rng.uniform(-half, half, n)


def test_sags_are_the_closed_forms():
    x, y = _points()
    r2 = x * x + y * y
    np.testing.assert_allclose(Conic(1 / 400.0).sag(x, y), 400.0 - np.sqrt(400.0 ** 2 - r2), rtol=1e-9, atol=1e-11)
    np.testing.assert_allclose(Conic(1 / 300.0, -1.0).sag(x, y), r2 / 600.0, rtol=1e-12)
    np.testing.assert_allclose(Conic(0.0).sag(x, y), 0.0)
    # a prolate ellipsoid z = a - a sqrt(1 - r^2 / b^2), R = b^2 / a, k = b^2 / a^2 - 1
    a, b = 675.0, 493.0
    ellipsoid = a - a * np.sqrt(1 - r2 / b ** 2)
    np.testing.assert_allclose(Conic(a / b ** 2, b * b / (a * a) - 1).sag(x, y), ellipsoid, atol=1e-10, rtol=1e-11)
    # a cylinder curves in y only; a biconic of equal radii and conics is the conic
    cylinder = 700.0 - np.sqrt(700.0 ** 2 - y * y)
    np.testing.assert_allclose(Biconic(0.0, 1 / 700.0).sag(x, y), cylinder, rtol=1e-9, atol=1e-11)
    np.testing.assert_allclose(Biconic(1 / 400.0, 1 / 400.0, -0.5, -0.5).sag(x, y), Conic(1 / 400.0, -0.5).sag(x, y),
                               rtol=1e-12)
    # outside the domain the sag is NaN
    assert np.isnan(Conic(1 / 50.0).sag(np.array([60.0]), np.array([0.0])))[0]


@pytest.mark.parametrize("name", SHAPE_CASES)
def test_gradients_are_the_sags_derivatives(name):
    shape = SHAPE_CASES[name]
    x, y = _points()
    h = 1e-4
    gx, gy = shape.gradient(x, y)
    fd_x = (shape.sag(x + h, y) - shape.sag(x - h, y)) / (2 * h)
    fd_y = (shape.sag(x, y + h) - shape.sag(x, y - h)) / (2 * h)
    np.testing.assert_allclose(gx, fd_x, rtol=1e-6, atol=1e-9)
    np.testing.assert_allclose(gy, fd_y, rtol=1e-6, atol=1e-9)


def test_distance_of_points_off_a_placed_sphere():
    """A sphere of radius 400 mm placed by a rotation and a translation: points at known distances from it."""
    rng = np.random.default_rng(3)
    r = 400.0
    axis = np.array([0.3, -0.5, 0.8]) / np.linalg.norm([0.3, -0.5, 0.8])
    x = np.cross(axis, [1.0, 0, 0])
    x /= np.linalg.norm(x)
    frame = np.eye(4)
    frame[:3, 0], frame[:3, 1], frame[:3, 2], frame[:3, 3] = x, np.cross(axis, x), axis, [10.0, -20.0, 30.0]
    centre = frame[:3, 3] + r * axis
    dirs = -axis[:, None] + 0.2 * rng.normal(size=(3, 50))
    dirs /= np.linalg.norm(dirs, axis=0)
    off = rng.uniform(-0.05, 0.05, 50)
    p = centre[:, None] + (r + off) * dirs
    np.testing.assert_allclose(distance(Conic(1 / r), np.linalg.inv(frame), p), np.abs(off), rtol=1e-3, atol=1e-9)


def test_every_shape_block_makes_its_shape():
    params = {"radius_mm": 400.0, "conic": -0.5, "radius_x_mm": 0.0, "radius_y_mm": 700.0, "conic_x": 0.0,
              "conic_y": 0.0, "terms": [(2, 0, 1e-4)]}
    made = {name: make(params) for name, (_, make) in SHAPES.items()}
    x, y = _points(20)
    np.testing.assert_allclose(made["plane"].sag(x, y), 0.0)
    np.testing.assert_allclose(made["sphere"].sag(x, y), Conic(1 / 400.0).sag(x, y))
    np.testing.assert_allclose(made["conic"].sag(x, y), Conic(1 / 400.0, -0.5).sag(x, y))
    np.testing.assert_allclose(made["biconic"].sag(x, y), Biconic(0.0, 1 / 700.0).sag(x, y))
    np.testing.assert_allclose(made["xy_polynomial"].sag(x, y), Conic(1 / 400.0, -0.5).sag(x, y) + 1e-4 * x * x)
