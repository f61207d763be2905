"""The light table (tracer.sources.lights): every sampler against the density it reports (chi-square, as
for the materials), power-proportional choices, emission by flux or luminance, and next-event estimates of
illuminance against closed forms."""

import math

import numpy as np
import pytest

from tests.support.chi2 import ChiSquareTest, SurfaceAdapter
from tests.support.stats import z_bound
from tracer.core.sampling import make_rng
from tracer.core.schema import parse_block
from tracer.core.validate import FieldChecker
from tracer.scene import Material, SceneObject
from tracer.sources.lights import EMISSION, LightTable, make_emission

#: Sidak family of the chi-square tests of the light table's and the environments' samplers.
CHI2_TESTS = 5


def square(slot: int, center, size: float, normal_sign: float = -1.0, luminance: float = 1000.0, two_sided=False):
    """A square light of side ``size`` mm in a plane z = const, facing -z (down) by default."""
    c = np.asarray(center, dtype=np.float64)
    h = 0.5 * size
    v = c + np.array([[-h, -h, 0], [h, -h, 0], [h, h, 0], [-h, h, 0]])
    f = np.array([[0, 2, 1], [0, 3, 2]]) if normal_sign < 0 else np.array([[0, 1, 2], [0, 2, 3]])
    o = SceneObject(f"light{slot}", slot, v, f, Material("absorber", {}))
    params = parse_block(FieldChecker("t"), {"luminance": luminance, "two_sided": two_sided}, "emission",
                         EMISSION.fields, alternatives=EMISSION.alternatives)
    o.emission = make_emission(params, o.area_mm2, None)
    return o


LIGHTS = [square(0, [0.0, 0.0, 100.0], 4.0, luminance=1000.0),
          square(1, [30.0, 0.0, 80.0], 2.0, luminance=8000.0),
          square(2, [-20.0, 25.0, 120.0], 6.0, luminance=300.0, two_sided=True)]


def test_emission_is_power_proportional_and_reports_its_density():
    table = LightTable(LIGHTS)
    n = 400_000
    tri, points, normal, pdf = table.sample_emission(make_rng(1).random((4, n)))
    power = np.array([o.emission.luminance * o.area_mm2 * (2 if o.emission.two_sided else 1) for o in LIGHTS])
    share = power / power.sum()
    counts = np.bincount(table.cluster[tri], minlength=3) / n
    assert np.all(np.abs(counts - share) < z_bound(3) * np.sqrt(share * (1 - share) / n))
    # The density of a point (and side) is its share over its object's area (halved for two sides).
    obj = table.cluster[tri]
    area = np.array([o.area_mm2 for o in LIGHTS])[obj]
    sides = np.where(table.two_sided[tri], 2.0, 1.0)
    np.testing.assert_allclose(pdf, share[obj] / (area * sides), rtol=1e-12)
    # Points lie on their triangles; normals face the emitting side (both sides for the two-sided one).
    np.testing.assert_allclose(points[2], np.array([100.0, 80.0, 120.0])[obj], atol=1e-9)
    assert np.all(normal[2, obj < 2] == -1.0)
    two = obj == 2
    assert 0.45 < np.mean(normal[2, two] > 0) < 0.55


def _importance(p, table):
    """A Lambertian receiver facing up at p: its sampling density toward the lights (cos / pi)."""
    return table.importance(p, lambda w: np.maximum(w[2], 0.0) / np.pi)


@pytest.mark.parametrize("with_importance", [False, True], ids=["power", "importance"])
def test_chi2_next_event_points_against_their_density(with_importance):
    """Points for next-event estimation, histogrammed by light and position on it: x = light index +
    the point's first coordinate on its square, y = its second; the expected density there is the
    reported area density times the square's area."""
    table = LightTable(LIGHTS)
    p0 = np.array([[5.0], [3.0], [0.0]])
    sizes = np.array([4.0, 2.0, 6.0])
    corners = np.array([[-2.0, -2.0], [29.0, -1.0], [-23.0, 22.0]])

    def sample(n, rng):
        p = np.repeat(p0, n, axis=1)
        imp = _importance(p, table) if with_importance else None
        tri, y, pdf = table.sample_direct(p, rng.random((3, n)), imp)
        k = table.cluster[tri]
        s = (y[0] - corners[k, 0]) / sizes[k]
        t = (y[1] - corners[k, 1]) / sizes[k]
        sample.pdf_area = (k, s, t, pdf)
        return np.stack([k + s, t], axis=-1), np.ones(n, bool)

    def density(x, t):
        k = np.floor(x).astype(np.int64)
        s = x - k
        y = np.stack([corners[k, 0] + s * sizes[k], corners[k, 1] + t * sizes[k],
                      np.array([100.0, 80.0, 120.0])[k]])
        # The density the sampler reports for a point: recompute it through the same selection.
        p = np.repeat(p0, len(x), axis=1)
        imp = _importance(p, table) if with_importance else None
        share = table.cluster_power / table.cluster_power.sum()
        if imp is None:
            q = share[k]
        else:
            q_all = 0.1 * share[:, None] + 0.9 * imp / imp.sum(axis=0)
            q = q_all[k, np.arange(len(k))]
        a, b = table.cluster_range[k, 0], table.cluster_range[k, 1]
        area = np.array([table.tris.area[i:j].sum() for i, j in zip(a, b, strict=True)])
        del y
        return q / area * sizes[k] ** 2

    test = ChiSquareTest(((0.0, 3.0), (0.0, 1.0)), (24, 8), sample, density, 300_000, seed=5)
    ok, msg = test.run(0.01, CHI2_TESTS)
    assert ok, msg
    # The reported pdf equals that density at the sampled points (the importance is float32).
    k, s, t, pdf = sample.pdf_area
    np.testing.assert_allclose(pdf * sizes[k] ** 2, density(k + s, t), rtol=1e-6)


def test_next_event_estimates_the_illuminance_of_a_small_source():
    """E = I cos(theta) / d^2 with I = L A cos(theta_e) for a small flat source (a 0.2 mm square at
    about 100 mm, so the small-source error is ~1e-6), by power and by importance selection alike."""
    small = [square(0, [40.0, 0.0, 100.0], 0.2, luminance=1e6)]
    table = LightTable(small)
    p = np.zeros((3, 100_000))
    for imp in (None, table.importance(p, lambda w: np.maximum(w[2], 0.0))):
        tri, y, pdf = table.sample_direct(p, make_rng(3).random((3, p.shape[1])), imp)
        w, dist, radiance, cos_y = table.connection(p, tri, y)
        e = radiance[1] * np.maximum(w[2], 0.0) * cos_y / (dist * dist * pdf)  # lx-like, cd/m^2 sr
        d = math.hypot(40.0, 100.0)
        cos = 100.0 / d
        expected = 1e6 * 0.04 * cos * cos / d**2
        assert e.mean() == pytest.approx(expected, rel=1e-4)


def test_quadrature_weights_cover_every_light():
    table = LightTable(LIGHTS)
    pts, normals, weights, radiance, two, size = table.quadrature(4)
    assert weights.sum() == pytest.approx(sum(o.area_mm2 for o in LIGHTS), rel=1e-12)
    assert pts.shape[1] == len(weights) == radiance.shape[1] == len(two) == normals.shape[1] == len(size)
    # Cells similar to their triangle, a quarter of its edges: the longest edge over 4, area over 16.
    t = table.tris
    longest = np.maximum.reduce([np.linalg.norm(e, axis=0) for e in (t.e1, t.e2, t.e2 - t.e1)])
    np.testing.assert_allclose(np.sort(size), np.sort(np.repeat(longest / 4, 16)), rtol=1e-12)


def test_chi2_cosine_emission():
    """The Lambertian emission sampler through the materials' adapter."""
    from tracer.optics.aimed import CosineEmission

    adapter = SurfaceAdapter(CosineEmission(), (0.0, 0.0, -1.0), (0.3, -0.2, 1.0), mode="importance")
    ok, msg = adapter.test(seed=11).run(0.01, CHI2_TESTS)
    assert ok, msg
    assert adapter.weight_mismatch < 1e-5  # float32 weights and densities (tracer.core.vec)


def test_emission_flux_and_luminance_agree():
    from tracer.core.units import lambertian_flux_lm

    params = parse_block(FieldChecker("t"), {"flux": 1.0}, "emission", EMISSION.fields)
    e = make_emission(params, 4.0, None)  # 4 mm^2 panel, 1 lm
    assert lambertian_flux_lm(e.luminance, 4.0) == pytest.approx(1.0)
    assert e.luminance == pytest.approx(1.0 / (np.pi * 4e-6))
