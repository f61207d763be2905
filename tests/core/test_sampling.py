"""Chi-square tests of every warp in :mod:`tracer.core.sampling`, plus exact checks.

Each chi^2 test maps the samples to 2D coordinates in which the density is smooth over the
whole domain rectangle, so that Gauss-Legendre quadrature gives accurate expected counts (a
discontinuous density, such as the indicator of a disk in Cartesian coordinates, would not):
(phi, cos theta) on the sphere (d omega = d phi d cos theta), direction cosines for narrow
lobes, equal-area polar coordinates (phi, r^2) on disks, and vertex-polar coordinates (s, w)
on triangles (s = 1 - b0, w = b2 / (b1 + b2), area element 2 A s ds dw). The tracer's routines
take and return (k, n) planes; the harness (tests/support/chi2.py) histograms (n, 2) rows. The
harness's power: a wrong density or samples outside the support are rejected."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tests.support.chi2 import ChiSquareTest
from tracer.core import sampling as smp

SAMPLES = 1_000_000
SIGNIFICANCE = 0.01
#: Sidak family: the chi^2 tests of correct samplers in this module. The tests that must
#: reject a wrong density use the same (stricter) level.
TEST_COUNT = 10

TWO_PI = 2.0 * np.pi
SPHERE = ((0.0, TWO_PI), (-1.0, 1.0))
HEMISPHERE = ((0.0, TWO_PI), (0.0, 1.0))
POLAR_DISK = ((0.0, TWO_PI), (0.0, 1.0))

#: Narrow anisotropic lobe (4 deg x 1.5 deg) and a wide lobe truncated at |beta| = 1.
NARROW_BETA0, NARROW_SIGMA = np.array([0.2, 0.1]), np.radians([4.0, 1.5])
WIDE_BETA0, WIDE_SIGMA = np.array([0.4, -0.2]), np.array([0.5, 0.5])

#: An eye-box-like aperture seen obliquely from an origin off its axis: the direction to the
#: centre makes about 50 deg with the normal and the disk subtends a wide cone, so the
#: dist^2 / cos Jacobian varies strongly across it.
ORIGIN = np.array([0.0, 0.0, 0.0])
APERTURE = {
    "center": np.array([40.0, -15.0, 50.0]),
    "normal": np.array([-1.0, 0.3, -0.2]) / np.linalg.norm([-1.0, 0.3, -0.2]),
    "radius": 30.0,
}

#: Unequal triangles in 3D, one of them degenerate (never sampled).
MESH = np.array(
    [
        [[0.0, 0.0, 0.0], [4.0, 0.0, 0.0], [0.0, 3.0, 0.0]],
        [[4.0, 0.0, 0.0], [9.0, 1.0, 2.0], [0.0, 3.0, 0.0]],
        [[1.0, 1.0, 1.0], [2.0, 2.0, 2.0], [3.0, 3.0, 3.0]],
        [[0.0, 0.0, 0.0], [0.5, 0.0, 0.3], [0.2, 0.9, 0.1]],
    ]
)


#: Uniform points on a mesh and indices by weight, built from the tracer's own Distribution1D and
#: TriangleSet (the light table's parts), to test those by chi-square.
def triangle_areas(tris: np.ndarray) -> np.ndarray:
    """Areas (mm^2), (m,), of triangles given as corners (m, 3, 3) (``tris[i, k]`` is corner k)."""
    tris = np.asarray(tris, dtype=np.float64)
    c = np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0])
    return 0.5 * np.sqrt(c[:, 0] * c[:, 0] + c[:, 1] * c[:, 1] + c[:, 2] * c[:, 2])


def sample_discrete(weights: np.ndarray, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Indices drawn with probability proportional to ``weights`` (tracer.core.sampling.Distribution1D)."""
    return smp.Distribution1D(weights).sample(u)


def sample_triangles(tris: np.ndarray, u: np.ndarray, areas: np.ndarray | None = None):
    """Uniform points on a triangle mesh (density 1/total_area per unit area).

    A triangle is chosen with probability proportional to its area (u[0]), then a point uniformly
    inside it (:func:`tracer.core.sampling.uniform_triangle` on u[1:]). ``tris`` (m, 3, 3) mm; ``u`` (3, n).

    Returns (points (3, n) mm, triangle indices (n,)).
    """
    ts = smp.TriangleSet(tris)
    tri, _ = smp.Distribution1D(ts.area if areas is None else areas).sample(u[0])
    return ts.point(tri, u[1:]), tri


def check(test: ChiSquareTest) -> None:
    ok, message = test.run(SIGNIFICANCE, TEST_COUNT)
    assert ok, message


def check_rejected(test: ChiSquareTest) -> None:
    ok, message = test.run(SIGNIFICANCE, TEST_COUNT)
    assert not ok, message


def all_valid(pts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    return pts, np.ones(len(pts), dtype=bool)


def constant(value: float):
    return lambda x, y: np.full_like(x, value)


def sphere_coords(d: np.ndarray) -> np.ndarray:
    """(phi in [0, 2 pi), cos theta), (n, 2) rows, of unit directions (3, n)."""
    return np.stack([np.arctan2(d[1], d[0]) % TWO_PI, d[2]], axis=-1)


def sphere_direction(phi: np.ndarray, cos_theta: np.ndarray) -> np.ndarray:
    """Unit directions (3, k) from (phi, cos theta)."""
    sin_theta = np.sqrt(np.maximum(0.0, 1.0 - cos_theta**2))
    return np.stack([sin_theta * np.cos(phi), sin_theta * np.sin(phi), cos_theta])


def lift(beta_x: np.ndarray, beta_y: np.ndarray) -> np.ndarray:
    """Upper-hemisphere unit directions (3, k) with direction cosines (beta_x, beta_y)."""
    return np.stack([beta_x, beta_y, np.sqrt(1.0 - beta_x**2 - beta_y**2)])


def vertex_polar(p: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    """(s, w) of points p in triangles (a, b, c), all (n, 3) or (n, 2), from the geometry.

    p = a + s ((1 - w) (b - a) + w (c - a)): s runs from the vertex a to the opposite edge, w
    along that edge. A uniform density over the triangle is 2 s in (s, w).
    """
    e1, e2, v = b - a, c - a, p - a
    g11, g12, g22 = np.sum(e1 * e1, -1), np.sum(e1 * e2, -1), np.sum(e2 * e2, -1)
    r1, r2 = np.sum(v * e1, -1), np.sum(v * e2, -1)
    det = g11 * g22 - g12 * g12
    b1 = (g22 * r1 - g12 * r2) / det
    b2 = (g11 * r2 - g12 * r1) / det
    s = b1 + b2
    w = np.divide(b2, s, out=np.full_like(s, np.nan), where=s > 0.0)
    return np.stack([s, w], axis=-1)


def lobe_pdf(d: np.ndarray, beta0: np.ndarray, sigma: np.ndarray) -> np.ndarray:
    return smp.gaussian_lobe_pdf(d, np.broadcast_to(np.asarray(beta0)[:, None], (2, d.shape[1])), sigma)


def wide_lobe_pdf(phi: np.ndarray, cos_theta: np.ndarray) -> np.ndarray:
    return lobe_pdf(sphere_direction(phi, cos_theta), WIDE_BETA0, WIDE_SIGMA)


def lobe_test(beta0, sigma_sampled, sigma_tested, seed) -> ChiSquareTest:
    """Narrow lobe in direction cosines over beta0 +- 5 sigma, density pdf / d_z."""

    def sample(n, rng):
        beta0_n = np.broadcast_to(np.asarray(beta0)[:, None], (2, n))
        d, valid = smp.gaussian_lobe(rng.random((2, n)), beta0_n, sigma_sampled)
        return d[:2].T, valid

    def density(beta_x, beta_y):
        d = lift(beta_x, beta_y)
        return lobe_pdf(d, beta0, sigma_tested) / d[2]

    bounds = tuple((c - 5.0 * s, c + 5.0 * s) for c, s in zip(beta0, sigma_tested, strict=True))
    return ChiSquareTest(bounds, (64, 64), sample, density, SAMPLES, seed=seed)


def gauss_legendre_2d(f, bounds, panels, order=8) -> float:
    """Integral of f(x, y) (vectorised) over a rectangle by composite Gauss-Legendre."""
    nodes, weights = np.polynomial.legendre.leggauss(order)
    axes = []
    for (lo, hi), k in zip(bounds, panels, strict=True):
        h = (hi - lo) / k
        x = lo + h * (np.arange(k)[:, None] + 0.5 * (nodes + 1.0))
        axes.append((x.ravel(), np.tile(0.5 * h * weights, k)))
    (x, wx), (y, wy) = axes
    xx, yy = np.meshgrid(x, y, indexing="ij")
    return float(wx @ f(xx.ravel(), yy.ravel()).reshape(len(x), len(y)) @ wy)


# ----------------------------------------------------------------------------- harness


def test_harness_rejects_cosine_samples_against_uniform_hemisphere():
    def sample(n, rng):
        return all_valid(sphere_coords(smp.cosine_hemisphere(rng.random((2, n)))))

    check_rejected(ChiSquareTest(HEMISPHERE, (64, 32), sample, constant(1 / TWO_PI), seed=11))


def test_harness_rejects_lobe_with_wrong_sigma():
    check_rejected(lobe_test(NARROW_BETA0, NARROW_SIGMA, 1.1 * NARROW_SIGMA, seed=12))


def test_harness_rejects_samples_outside_support():
    test = ChiSquareTest(
        ((0.0, 1.0), (0.0, 1.0)),
        (8, 8),
        lambda n, rng: all_valid(rng.random((n, 2))),  # the harness's own rows
        lambda x, y: np.where(x < 0.5, 2.0, 0.0),
        sample_count=10_000,
    )
    ok, message = test.run()
    assert not ok
    assert "outside its support" in message


# ----------------------------------------------------------------------------- chi^2 tests


def test_chi2_uniform_disk_concentric():
    # In (phi, r^2) the uniform density 1/pi per unit area is 1/(2 pi).
    def sample(n, rng):
        p = smp.uniform_disk_concentric(rng.random((2, n)))
        phi = np.arctan2(p[1], p[0]) % TWO_PI
        return all_valid(np.stack([phi, p[0] * p[0] + p[1] * p[1]], axis=-1))

    check(ChiSquareTest(POLAR_DISK, (64, 32), sample, constant(1 / TWO_PI), seed=1))


def test_chi2_cosine_hemisphere():
    def sample(n, rng):
        return all_valid(sphere_coords(smp.cosine_hemisphere(rng.random((2, n)))))

    def density(phi, cos_theta):
        return smp.cosine_hemisphere_pdf(sphere_direction(phi, cos_theta))

    check(ChiSquareTest(SPHERE, (64, 64), sample, density, seed=2))


def test_chi2_uniform_sphere():
    def sample(n, rng):
        return all_valid(sphere_coords(smp.uniform_sphere(rng.random((2, n)))))

    check(ChiSquareTest(SPHERE, (64, 64), sample, constant(1 / (4 * np.pi)), seed=3))


def test_chi2_uniform_triangle_skewed():
    a, b, c = np.array([0.0, 0.0]), np.array([5.0, 0.4]), np.array([6.5, 1.2])

    def sample(n, rng):
        b12 = smp.uniform_triangle(rng.random((2, n)))
        p = a + b12[0][:, None] * (b - a) + b12[1][:, None] * (c - a)
        return all_valid(vertex_polar(p, a, b, c))

    check(ChiSquareTest(((0.0, 1.0), (0.0, 1.0)), (32, 32), sample, lambda s, w: 2 * s, seed=4))


@pytest.mark.parametrize(
    "beta0, sigma, seed",
    [((0.3, -0.2), np.radians([2.0, 2.0]), 5), (NARROW_BETA0, NARROW_SIGMA, 10)],
    ids=["isotropic-2deg", "anisotropic-4x1.5deg"],
)
def test_chi2_gaussian_lobe_narrow(beta0, sigma, seed):
    check(lobe_test(np.asarray(beta0), sigma, sigma, seed))


def test_chi2_gaussian_lobe_wide_truncated():
    # Much of the lobe lies at |beta| >= 1: those samples are invalid and land in the outside
    # cell, whose expected count n (1 - integral of the pdf over the hemisphere) tests the
    # absorbed mass.
    def sample(n, rng):
        beta0_n = np.broadcast_to(WIDE_BETA0[:, None], (2, n))
        d, valid = smp.gaussian_lobe(rng.random((2, n)), beta0_n, WIDE_SIGMA)
        return sphere_coords(d), valid

    check(ChiSquareTest(HEMISPHERE, (64, 32), sample, wide_lobe_pdf, seed=6))


def test_chi2_sample_disk_aperture():
    # Coordinates: the hit point on the disk in its own frame, polar (phi, s = (r/R)^2).
    center, normal, r = APERTURE["center"], APERTURE["normal"], APERTURE["radius"]
    t, b, _ = (e[:, 0] for e in smp.frame_from_normal(normal[:, None]))

    def sample(n, rng):
        origins = np.broadcast_to(ORIGIN[:, None], (3, n))
        d, dist, pdf = smp.sample_disk_aperture(origins, **APERTURE, u=rng.random((2, n)))
        offset = (origins + dist * d).T - center
        x, y = offset @ t / r, offset @ b / r
        return np.stack([np.arctan2(y, x) % TWO_PI, x * x + y * y], axis=-1), pdf > 0.0

    def density(phi, s):
        # Solid-angle pdf of the direction to the disk point (phi, s) times the Jacobian
        # d omega / (d phi d s) = |cos| / dist^2 * R^2 / 2; 1/(2 pi) if all is consistent.
        rho = r * np.sqrt(s)
        v = center + (rho * np.cos(phi))[:, None] * t + (rho * np.sin(phi))[:, None] * b - ORIGIN
        dist = np.linalg.norm(v, axis=-1)
        d = v / dist[:, None]
        pdf = smp.disk_aperture_pdf(np.broadcast_to(ORIGIN[:, None], d.T.shape), d.T, **APERTURE)
        return pdf * np.abs(d @ normal) / dist**2 * (0.5 * r * r)

    check(ChiSquareTest(POLAR_DISK, (64, 32), sample, density, seed=7))


def test_chi2_sample_triangles():
    # x = triangle index + s, y = w; the density in triangle i is 2 s area_i / total_area.
    areas = triangle_areas(MESH)

    def sample(n, rng):
        points, tri = sample_triangles(MESH, rng.random((3, n)))
        v = MESH[tri]
        s, w = vertex_polar(points.T, v[:, 0], v[:, 1], v[:, 2]).T
        return all_valid(np.stack([tri + s, w], axis=-1))

    def density(x, w):
        i = np.floor(x).astype(np.int64)
        return 2.0 * (x - i) * areas[i] / areas.sum()

    m = len(MESH)
    check(ChiSquareTest(((0.0, m), (0.0, 1.0)), (16 * m, 16), sample, density, seed=8))


def test_chi2_sample_discrete():
    weights = np.array([3.0, 0.0, 1.0, 0.5, 5.0, 0.25, 0.0])
    k = len(weights)

    def sample(n, rng):
        idx, _ = sample_discrete(weights, rng.random(n))
        return all_valid(np.stack([idx + 0.5, np.full(n, 0.5)], axis=-1))

    def density(x, y):
        return weights[np.floor(x).astype(np.int64)] / weights.sum()

    check(ChiSquareTest(((0.0, k), (0.0, 1.0)), (k, 1), sample, density, seed=9))


# ----------------------------------------------------------------------------- exact tests


def test_make_rng_streams():
    a = smp.make_rng(7, 3).random(8)
    np.testing.assert_array_equal(a, smp.make_rng(7, 3).random(8))
    assert not np.array_equal(a, smp.make_rng(7, 4).random(8))
    assert not np.array_equal(a, smp.make_rng(7).random(8))


def test_uniform_disk_concentric_edges():
    u = np.array([[0.5, 0.5], [0.0, 0.0], [0.0, 0.5], [0.5, 0.0]]).T
    p = smp.uniform_disk_concentric(u).T
    np.testing.assert_array_equal(p[0], [0.0, 0.0])
    # The warp's angles are float32 (tracer.core.sampling): radii of 1 to float32 precision.
    np.testing.assert_allclose(np.linalg.norm(p[1:], axis=-1), 1.0, rtol=1e-7)
    p = smp.uniform_disk_concentric(smp.make_rng(0).random((2, 10_000)))
    assert np.all(np.linalg.norm(p, axis=0) <= 1.0 + 1e-7)


def awkward_normals() -> np.ndarray:
    special = np.array(
        [
            [0.0, 0.0, 1.0],
            [0.0, 0.0, -1.0],
            [1e-9, -2e-9, 1.0],
            [3e-9, 1e-9, -1.0],
            [-1e-4, 1e-4, -1.0],
            [1.0, 0.0, 0.0],
            [0.0, -1.0, -0.0],
        ]
    )
    normals = np.concatenate([special, smp.make_rng(1).normal(size=(1000, 3))])
    return normals / np.linalg.norm(normals, axis=-1, keepdims=True)


def assert_orthonormal_right_handed(t, b, n):
    for v in (t, b, n):
        np.testing.assert_allclose(np.linalg.norm(v, axis=-1), 1.0, atol=1e-12)
    for v, w in ((t, b), (t, n), (b, n)):
        np.testing.assert_allclose(np.sum(v * w, axis=-1), 0.0, atol=1e-12)
    np.testing.assert_allclose(np.cross(t, b), n, atol=1e-12)


def frames(n: np.ndarray, hint=None):
    """frame_from_normal on rows (k, 3), returning rows."""
    h = None if hint is None else (np.asarray(hint) if np.ndim(hint) == 1 else np.asarray(hint).T)
    return tuple(e.T for e in smp.frame_from_normal(n.T, h))


def test_frame_from_normal_is_orthonormal_right_handed():
    n = awkward_normals()
    t, b, n_out = frames(n)
    np.testing.assert_allclose(n_out, n, atol=1e-15)
    assert_orthonormal_right_handed(t, b, n_out)


def test_frame_from_normal_with_hint():
    n = awkward_normals()
    hint = np.array([1.0, 0.0, 0.0])
    t, b, n_out = frames(n, hint)
    assert_orthonormal_right_handed(t, b, n_out)
    perp = hint - (n @ hint)[:, None] * n
    usable = np.linalg.norm(perp, axis=-1) > 1e-3
    assert np.count_nonzero(~usable) == 1  # the normal (1, 0, 0)
    expected = perp[usable] / np.linalg.norm(perp[usable], axis=-1, keepdims=True)
    np.testing.assert_allclose(t[usable], expected, atol=1e-12)
    # A hint parallel to n gives the hint-free frame.
    t_duff, b_duff, _ = frames(n[~usable])
    np.testing.assert_array_equal(t[~usable], t_duff)
    np.testing.assert_array_equal(b[~usable], b_duff)
    # A per-normal hint of shape (3, n), of any length, gives the same frames.
    t2, b2, _ = frames(n, np.broadcast_to(2.0 * hint, n.shape))
    np.testing.assert_allclose(t2, t, atol=1e-15)
    np.testing.assert_allclose(b2, b, atol=1e-15)


def test_to_local_to_world_round_trip():
    t, b, n = smp.frame_from_normal(awkward_normals().T)
    v = smp.make_rng(2).normal(size=(3, n.shape[1]))
    local = smp.to_local(v, t, b, n)
    np.testing.assert_allclose(smp.to_world(local, t, b, n), v, atol=1e-12)
    np.testing.assert_allclose(local[2], np.sum(v * n, axis=0), atol=1e-12)
    np.testing.assert_allclose(smp.to_local(n, t, b, n).T, [[0.0, 0.0, 1.0]] * n.shape[1], atol=1e-12)


def test_cosine_hemisphere_pdf_integrates_to_one():
    def pdf(phi, cos_theta):
        return smp.cosine_hemisphere_pdf(sphere_direction(phi, cos_theta))

    assert gauss_legendre_2d(pdf, HEMISPHERE, (4, 4)) == pytest.approx(1.0, abs=1e-13)
    assert gauss_legendre_2d(pdf, ((0.0, TWO_PI), (-1.0, 0.0)), (4, 4)) == 0.0


def test_gaussian_lobe_pdf_integrates_to_valid_fraction():
    # Narrow lobe, over direction cosines with d omega = d beta / d_z: the mass is 1.
    def narrow(beta_x, beta_y):
        d = lift(beta_x, beta_y)
        return lobe_pdf(d, NARROW_BETA0, NARROW_SIGMA) / d[2]

    bounds = tuple((c - 8.0 * s, c + 8.0 * s) for c, s in zip(NARROW_BETA0, NARROW_SIGMA, strict=True))
    assert gauss_legendre_2d(narrow, bounds, (16, 16)) == pytest.approx(1.0, abs=1e-10)

    # Wide lobe: the hemisphere integral equals P(|beta| < 1), integrated independently over
    # the unit disk of beta in polar coordinates (rho, psi).
    def g2_polar(rho, psi):
        zx = (rho * np.cos(psi) - WIDE_BETA0[0]) / WIDE_SIGMA[0]
        zy = (rho * np.sin(psi) - WIDE_BETA0[1]) / WIDE_SIGMA[1]
        return rho * np.exp(-0.5 * (zx**2 + zy**2)) / (TWO_PI * np.prod(WIDE_SIGMA))

    p_valid = gauss_legendre_2d(g2_polar, ((0.0, 1.0), (0.0, TWO_PI)), (16, 32))
    assert 0.3 < p_valid < 0.8
    total = gauss_legendre_2d(wide_lobe_pdf, HEMISPHERE, (32, 32))
    assert total == pytest.approx(p_valid, rel=1e-10)
    below = sphere_direction(np.zeros(3), np.array([-0.5, 0.0, -1.0]))
    np.testing.assert_array_equal(lobe_pdf(below, np.zeros(2), WIDE_SIGMA), 0.0)


def test_gaussian_lobe_invalid_samples():
    u = smp.make_rng(3).random((2, 10_000))
    d, valid = smp.gaussian_lobe(u, np.broadcast_to(np.array([[0.9], [0.0]]), (2, u.shape[1])), np.array([0.3, 0.1]))
    d = d.T
    np.testing.assert_allclose(np.linalg.norm(d, axis=-1), 1.0, rtol=1e-14)
    assert 0 < np.count_nonzero(~valid) < len(d)
    assert np.all(d[~valid] == [0.0, 0.0, 1.0])
    assert np.all(np.sum(d[valid, :2] ** 2, axis=-1) < 1.0)


def test_disk_aperture_pdf_matches_sampler():
    u = smp.make_rng(4).random((2, 100_000))
    origins = np.broadcast_to(ORIGIN[:, None], (3, u.shape[1]))
    d, dist, pdf = smp.sample_disk_aperture(origins, **APERTURE, u=u)
    np.testing.assert_allclose(np.linalg.norm(d, axis=0), 1.0, rtol=1e-14)
    assert np.all(pdf > 0.0)
    np.testing.assert_allclose(smp.disk_aperture_pdf(origins, d, **APERTURE), pdf, rtol=1e-10)
    flipped = {**APERTURE, "normal": -APERTURE["normal"]}
    np.testing.assert_allclose(smp.disk_aperture_pdf(origins, d, **flipped), pdf, rtol=1e-10)
    offset = (origins + dist * d).T - APERTURE["center"]
    assert np.all(np.linalg.norm(offset, axis=-1) <= APERTURE["radius"] * (1.0 + 1e-7))
    np.testing.assert_allclose(offset @ APERTURE["normal"], 0.0, atol=1e-10)
    # Opposite directions never reach the disk.
    np.testing.assert_array_equal(smp.disk_aperture_pdf(origins, -d, **APERTURE), 0.0)


def test_disk_aperture_pdf_integrates_to_one():
    # Over the cone around the axis origin -> centre that contains the disk.
    axis = APERTURE["center"] - ORIGIN
    t, b, a = smp.frame_from_normal(axis[:, None])
    cos_max = math.sqrt(1.0 - (APERTURE["radius"] / np.linalg.norm(axis)) ** 2)

    def pdf(phi, cos_theta):
        d = smp.to_world(sphere_direction(phi, cos_theta), t, b, a)
        return smp.disk_aperture_pdf(np.broadcast_to(ORIGIN[:, None], d.shape), d, **APERTURE)

    # The density jumps at the disk's rim, so the quadrature is only accurate to ~1e-4.
    total = gauss_legendre_2d(pdf, ((0.0, TWO_PI), (cos_max, 1.0)), (250, 250), order=4)
    assert total == pytest.approx(1.0, abs=2e-3)


def test_sample_disk_aperture_origin_in_plane():
    u = smp.make_rng(5).random((2, 1000))
    tangent = smp.frame_from_normal(APERTURE["normal"][:, None])[0][:, 0]
    origins = np.broadcast_to((APERTURE["center"] + 2.5 * APERTURE["radius"] * tangent)[:, None], (3, u.shape[1]))
    d, _, pdf = smp.sample_disk_aperture(origins, **APERTURE, u=u)
    np.testing.assert_array_equal(pdf, 0.0)
    np.testing.assert_allclose(np.linalg.norm(d, axis=0), 1.0, rtol=1e-14)
    np.testing.assert_array_equal(smp.disk_aperture_pdf(origins, d, **APERTURE), 0.0)


def test_triangle_areas_and_sample_triangles():
    np.testing.assert_allclose(triangle_areas(MESH)[[0, 2]], [6.0, 0.0])
    points, tri = sample_triangles(MESH, smp.make_rng(6).random((3, 10_000)))
    assert not np.any(tri == 2)
    v = MESH[tri]
    s, w = vertex_polar(points.T, v[:, 0], v[:, 1], v[:, 2]).T
    assert np.all((s >= -1e-12) & (s <= 1 + 1e-12) & (w >= -1e-12) & (w <= 1 + 1e-12))
    # Points lie in their triangles' planes.
    normal = np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])
    np.testing.assert_allclose(np.sum((points.T - v[:, 0]) * normal, axis=-1), 0.0, atol=1e-12)


def test_sample_discrete_pmf_and_errors():
    weights = np.array([2.0, 0.0, 6.0])
    dist = smp.Distribution1D(weights)
    idx, pmf = dist.invert(np.array([0.0, 0.2499, 0.25, 0.999999]))
    np.testing.assert_array_equal(idx, [0, 0, 2, 2])
    np.testing.assert_allclose(pmf, [0.25, 0.25, 0.75, 0.75])
    # The largest u below 1 does not reach trailing zero weights, by either method.
    tail = smp.Distribution1D(np.array([1.0, 1.0, 0.0]))
    assert tail.invert(np.array([np.nextafter(1.0, 0.0)]))[0][0] == 1
    assert tail.sample(np.array([np.nextafter(1.0, 0.0)]))[0][0] != 2
    # The alias table never returns a weight of 0, and its frequencies are the pmf (exactly, on a grid).
    u = (np.arange(60_000) + 0.5) / 60_000
    idx, pmf = dist.sample(u)
    assert not np.any(idx == 1)
    np.testing.assert_allclose(np.bincount(idx, minlength=3) / len(u), [0.25, 0.0, 0.75], atol=1e-4)
    np.testing.assert_allclose(pmf, dist.pmf(idx))
    for bad in ([0.0, 0.0], [1.0, -1.0], [1.0, np.nan], [1.0, np.inf], []):
        with pytest.raises(ValueError):
            sample_discrete(np.array(bad), np.array([0.5]))
