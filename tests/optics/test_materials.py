"""Every material through its interface (sample / eval / pdf / lobes) against closed forms: energy
conservation and Fresnel's split, reciprocity, the chi-square adapter on every non-delta material, and
the schema that the loader, the add-on and the Mitsuba converter share."""

import numpy as np
import pytest

from tests.support.chi2 import SurfaceAdapter
from tests.support.optics import CHI2_TESTS, incoming, material
from tests.support.stats import z_bound
from tracer.core.sampling import make_rng, uniform_sphere
from tracer.core.schema import check_consistent, parse_block
from tracer.core.validate import FieldChecker
from tracer.optics.bsdf import DELTA, IMPORTANCE, RADIANCE, Interaction
from tracer.optics.fresnel import fresnel_unpolarized
from tracer.optics.materials import MATERIALS
from tracer.scene import Material, SceneObject
from tracer.sources.lights import EMISSION


def hits(d):
    """An interaction of rays along rows ``d`` (n, 3) with the plane z = 0 at the origin."""
    n = len(d)
    ng = np.tile([[0.0], [0.0], [1.0]], (1, n))
    return Interaction(np.ascontiguousarray(d.T), np.zeros((3, n)), ng, ng, np.full((2, n), 0.5),
                       np.zeros(n, np.int64))


@pytest.mark.parametrize("theta", [0, 30, 60, 80])
def test_dielectric_splits_energy_by_fresnel(theta):
    s = material("dielectric", ior=1.52)
    it = hits(incoming(theta))
    out = s.sample(it, make_rng(1, theta).random((1, len(it))), IMPORTANCE)
    reflected = out.wo[2] > 0
    r, _ = fresnel_unpolarized(np.array([np.cos(np.radians(theta))]), 1.52)
    n = len(it)
    assert abs(reflected.mean() - r[0]) < z_bound(4) * np.sqrt(r[0] * (1 - r[0]) / n)
    assert np.all(out.weight == 1.0) and np.all(out.pdf == 0) and np.all(out.flags & DELTA)
    # Radiance mode: refracted radiance scales by (n_i / n_t)^2 (Veach 1997, ch. 5).
    out = s.sample(it, make_rng(2, theta).random((1, len(it))), RADIANCE)
    refracted = out.wo[2] < 0
    np.testing.assert_allclose(out.weight[:, refracted], 1 / 1.52**2, rtol=1e-12)
    np.testing.assert_allclose(out.weight[:, ~refracted], 1.0)
    # The deterministic branches carry R and T (T / n^2 for radiance) along the same directions.
    (wr, fr, _, _), (wt, ft, _, _) = s.lobes(hits(incoming(theta, 1)), RADIANCE)
    assert fr[0, 0] == pytest.approx(r[0]) and ft[0, 0] == pytest.approx((1 - r[0]) / 1.52**2)
    assert wr[2, 0] > 0 and (theta == 0 or wt[2, 0] < 0)


def test_total_internal_reflection_in_glass():
    s = material("dielectric", ior=1.52)
    it = hits(incoming(50, 10_000, from_front=False))  # inside the glass, beyond 41.1 deg
    out = s.sample(it, make_rng(3).random((1, len(it))), RADIANCE)
    assert np.all(out.wo[2] < 0) and np.all(out.weight == 1.0)


def test_coating_mirror_lcd_and_absorber():
    m = material("mirror", reflectance=[0.9, 0.8, 0.7])
    out = m.sample(hits(incoming(30, 10)), None, RADIANCE)
    np.testing.assert_allclose(out.weight[:, 0], [0.9, 0.8, 0.7])
    assert out.wo[2, 0] == pytest.approx(np.cos(np.radians(30)))
    c = material("coating", reflectance=0.3, transmittance=0.5)
    out = c.sample(hits(incoming(20)), make_rng(5).random((1, 200_000)), RADIANCE)
    mean_r = (out.weight[1] * (out.wo[2] > 0)).mean()
    mean_t = (out.weight[1] * (out.wo[2] < 0)).mean()
    assert mean_r == pytest.approx(0.3, abs=0.005) and mean_t == pytest.approx(0.5, abs=0.005)
    a = material("absorber")
    assert a.flags == 0 and not a.sample(hits(incoming(0, 5)), None, RADIANCE).flags.any()


def test_lcd_transmittance_and_contrast(tmp_path):
    from tracer.core.imageio import write_png

    img = np.zeros((2, 2, 3), np.uint8)
    img[0, 0] = 255  # top-left clear
    write_png(tmp_path / "s.png", img)
    params = parse_block(FieldChecker("test"), {"image": "s.png", "transmittance": 0.05}, "m",
                         MATERIALS["lcd"].schema.fields, tmp_path)
    v = np.array([[-1.0, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]])
    o = SceneObject("lcd", 0, v, np.array([[0, 1, 2], [0, 2, 3]]), Material("lcd", params))
    s = MATERIALS["lcd"]([o])
    it = hits(incoming(0, 2))
    it.uv = np.array([[0.25, 0.75], [0.75, 0.25]])
    out = s.sample(it, None, RADIANCE)
    np.testing.assert_allclose(out.weight[0], [0.05, 0.05 / 300])
    np.testing.assert_allclose(out.wo, it.d)


NON_DELTA = [
    ("lambertian", {"reflectance": [0.5, 0.6, 0.7]}, 25, 0.6),
    ("lambertian_transmitter", {"transmittance": 0.6, "reflectance": 0.3}, 25, 0.9),
    ("diffuser", {"transmittance": 0.9, "sigma_deg": [4.0, 2.0]}, 25, 0.9),
]


@pytest.mark.parametrize("mtype,spec,theta,albedo", NON_DELTA, ids=[m[0] for m in NON_DELTA])
def test_scattering_materials_conserve_energy(mtype, spec, theta, albedo):
    """The sampled weights average to the albedo, which equals the integral of eval over the sphere."""
    s = material(mtype, **spec)
    it = hits(incoming(theta))
    out = s.sample(it, make_rng(7).random((s.dims, len(it))), RADIANCE)
    assert out.weight[1].mean() == pytest.approx(albedo, rel=0.01)
    if mtype == "diffuser":
        # Narrow lobe: integrate in direction-cosine space around the straight-through direction.
        g = np.linspace(-0.4, 0.4, 801)
        bx, by = np.meshgrid(g + np.sin(np.radians(theta)), g)
        dz = -np.sqrt(np.clip(1 - bx**2 - by**2, 0, None))
        dirs = np.stack([bx.ravel(), by.ravel(), dz.ravel()])
        it2 = hits(np.tile(incoming(theta, 1)[0], (dirs.shape[1], 1)))
        integral = (s.eval(it2, dirs, RADIANCE)[1] / np.abs(dirs[2])).sum() * (g[1] - g[0]) ** 2
    else:
        dirs = uniform_sphere(make_rng(8).random((2, 400_000)))
        it2 = hits(np.tile(incoming(theta, 1)[0], (dirs.shape[1], 1)))
        integral = s.eval(it2, dirs, RADIANCE)[1].mean() * 4 * np.pi
    assert integral == pytest.approx(albedo, rel=0.01)


def test_lambertian_and_lobe_reciprocity():
    """f(a -> b) = f(b -> a) for the Lambertian BRDF and the Gaussian BTDF."""
    rng = make_rng(9)
    a = uniform_sphere(rng.random((2, 1000))).T
    b = uniform_sphere(rng.random((2, 1000))).T
    a[:, 2] = -np.abs(a[:, 2])  # a arrives from the front
    for mtype, spec, b_side in [("lambertian", {"reflectance": 0.7}, 1),
                                ("diffuser", {"transmittance": 0.9, "sigma_deg": 17.5}, -1)]:
        s = material(mtype, **spec)
        bb = b.copy()
        bb[:, 2] = b_side * np.abs(bb[:, 2])
        f_ab = s.eval(hits(a), bb.T, RADIANCE)[0] / np.abs(bb[:, 2])
        f_ba = s.eval(hits(-bb), -a.T, RADIANCE)[0] / np.abs(a[:, 2])  # light along -b leaving along -a
        np.testing.assert_allclose(f_ab, f_ba, rtol=1e-9, atol=1e-12)


CHI2_CASES = [
    ("lambertian", {"reflectance": [0.5, 0.6, 0.7]}, (0.3, 0.1, -1.0), None),
    ("lambertian_transmitter", {"transmittance": 0.6, "reflectance": 0.3}, (0.3, 0.1, -1.0), None),
    # The narrow lobe around the straight-through direction (-z): a window near the pole.
    ("diffuser", {"transmittance": 0.9, "sigma_deg": [4.0, 2.0]}, (0.05, 0.02, -1.0),
     ((0.0, 2 * np.pi), (-1.0, -0.95))),
    ("diffuser", {"transmittance": 0.9, "sigma_deg": [40.0, 25.0]}, (0.5, 0.2, -1.0), None),
]


@pytest.mark.parametrize("mtype,spec,d,bounds", CHI2_CASES, ids=["lambertian", "screen", "narrow", "wide"])
def test_chi2_every_non_delta_material(mtype, spec, d, bounds):
    s = material(mtype, **spec)
    adapter = SurfaceAdapter(s, d, (0.0, 0.0, 1.0))
    kw = {"bounds": bounds} if bounds else {}
    ok, msg = adapter.test(seed=hash(mtype) % 1000, **kw).run(0.01, CHI2_TESTS)
    assert ok, msg
    assert adapter.weight_mismatch < 1e-5  # float32 weights and densities (tracer.core.vec)


def test_every_registered_non_delta_material_has_a_chi2_case():
    tested = {c[0] for c in CHI2_CASES}
    assert {name for name, cls in MATERIALS.items() if cls.traced and cls.flags and not cls.flags & DELTA} <= tested


def test_chi2_adapter_rejects_a_wrong_pdf():
    """The adapter has power: a Lambertian whose reported pdf is the uniform hemisphere's fails."""
    s = material("lambertian", reflectance=0.5)

    class Wrong:
        dims = s.dims

        def sample(self, it, u, mode):
            return s.sample(it, u, mode)

        def eval(self, it, wo, mode):
            return s.eval(it, wo, mode)

        def pdf(self, it, wo):
            return np.where(wo[2] > 0, 1 / (2 * np.pi), 0.0)

    ok, _ = SurfaceAdapter(Wrong(), (0.3, 0.1, -1.0), (0.0, 0.0, 1.0)).test(seed=3).run(0.01, CHI2_TESTS)
    assert not ok


def test_one_schema_for_every_material():
    """Every material carries a schema whose fields mean one kind and unit across materials (the
    add-on keeps one property per field name) and whose defaults parse."""
    check_consistent([cls.schema for cls in MATERIALS.values()] + [EMISSION])
    for name, cls in MATERIALS.items():
        assert cls.schema.name == name and cls.schema.label and cls.schema.description
        for f in cls.schema.fields:
            assert f.label and f.description, (name, f.name)
