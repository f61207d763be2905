"""Each optical surface against closed forms: energy conservation, reciprocity, Fresnel values."""

import numpy as np
import pytest
from conftest import z_bound

from tracer.optics.fresnel import fresnel_unpolarized, reflect, refract
from tracer.optics.surfaces import Interaction, make_surface
from tracer.sampling import make_rng, uniform_sphere
from tracer.scene import Material, SceneObject


def obj(mtype, **params):
    v = np.array([[-1.0, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]])
    f = np.array([[0, 1, 2], [0, 2, 3]])
    return SceneObject("s", 0, v, f, Material(mtype, params, None))


def hits(d):
    n = len(d)
    ng = np.tile([0.0, 0.0, 1.0], (n, 1))
    return Interaction(d, np.zeros((n, 3)), ng, ng, np.full((n, 2), 0.5))


def incoming(theta_deg, n=200_000, from_front=True):
    t = np.radians(theta_deg)
    d = np.array([np.sin(t), 0.0, -np.cos(t) if from_front else np.cos(t)])
    return np.tile(d, (n, 1))


def test_fresnel_closed_forms():
    r, _ = fresnel_unpolarized(np.array([1.0]), 1.52)
    assert r[0] == pytest.approx(((1.52 - 1) / 2.52) ** 2, rel=1e-12)
    # The table of hud-physics.md: R = (Rs + Rp) / 2 at 65 deg is (0.236 + 0.012) / 2.
    r65, _ = fresnel_unpolarized(np.array([np.cos(np.radians(65))]), 1.52)
    assert r65[0] == pytest.approx(0.124, abs=0.002)
    # Reciprocity: the same R from either side for conjugate angles (Stokes relations).
    ci = np.cos(np.radians(np.linspace(0, 80, 9)))
    r1, ct = fresnel_unpolarized(ci, 1.52)
    r2, _ = fresnel_unpolarized(ct, 1 / 1.52)
    np.testing.assert_allclose(r1, r2, rtol=1e-12)
    # Total internal reflection beyond the critical angle inside glass.
    rt, _ = fresnel_unpolarized(np.array([np.cos(np.radians(45))]), 1 / 1.52)
    assert rt[0] == 1.0


def test_refraction_obeys_snell_and_reflection_preserves_angle():
    d = incoming(40, 1)
    n = np.array([[0.0, 0.0, 1.0]])
    ci = np.array([np.cos(np.radians(40))])
    _, ct = fresnel_unpolarized(ci, 1.52)
    t = refract(d, n, 1.52, ci, ct)
    assert np.sin(np.radians(40)) == pytest.approx(1.52 * np.hypot(t[0, 0], t[0, 1]), rel=1e-12)
    r = reflect(d, n)
    assert r[0, 2] == pytest.approx(-d[0, 2])


@pytest.mark.parametrize("theta", [0, 30, 60, 80])
def test_dielectric_splits_energy_by_fresnel(theta):
    s = make_surface(obj("dielectric", ior=1.52, ior_outside=1.0))
    it = hits(incoming(theta))
    d, f, alive = s.scatter(it, make_rng(1, theta), radiance=False)
    reflected = d[:, 2] > 0
    r, _ = fresnel_unpolarized(np.array([np.cos(np.radians(theta))]), 1.52)
    n = len(d)
    sigma = np.sqrt(r[0] * (1 - r[0]) / n)
    assert abs(reflected.mean() - r[0]) < z_bound(4) * sigma
    assert np.all(f == 1.0) and np.all(alive)  # flux mode: the Fresnel choice carries the energy
    # Radiance mode: refracted radiance scales by (n_i / n_t)^2 (Veach 1997, ch. 5).
    d2, fr, _ = s.scatter(it, make_rng(2, theta), radiance=True)
    refracted = d2[:, 2] < 0
    np.testing.assert_allclose(fr[refracted], 1 / 1.52**2, rtol=1e-12)
    np.testing.assert_allclose(fr[~refracted], 1.0)


def test_total_internal_reflection_in_glass():
    s = make_surface(obj("dielectric", ior=1.52, ior_outside=1.0))
    it = hits(incoming(50, 10_000, from_front=False))  # inside the glass, beyond 41.1 deg
    d, f, _ = s.scatter(it, make_rng(3), radiance=True)
    assert np.all(d[:, 2] < 0) and np.all(f == 1.0)


def test_coating_and_mirror_and_absorber_conserve_energy():
    m = make_surface(obj("mirror", reflectance=np.array([0.9, 0.8, 0.7])))
    d, f, _ = m.scatter(hits(incoming(30, 10)), make_rng(4), False)
    np.testing.assert_allclose(f[0], [0.9, 0.8, 0.7])
    assert d[0, 2] == pytest.approx(np.cos(np.radians(30)))
    c = make_surface(obj("coating", reflectance=np.full(3, 0.3), transmittance=np.full(3, 0.5)))
    d, f, _ = c.scatter(hits(incoming(20)), make_rng(5), False)
    mean_r = (f[:, 1] * (d[:, 2] > 0)).mean()
    mean_t = (f[:, 1] * (d[:, 2] < 0)).mean()
    assert mean_r == pytest.approx(0.3, abs=0.005) and mean_t == pytest.approx(0.5, abs=0.005)
    a = make_surface(obj("absorber"))
    _, f, alive = a.scatter(hits(incoming(0, 5)), make_rng(6), False)
    assert not alive.any() and not f.any()


@pytest.mark.parametrize("mtype,params", [
    ("lambertian", {"reflectance": np.array([0.5, 0.6, 0.7])}),
    ("lambertian_transmitter", {"transmittance": np.array([0.6, 0.6, 0.6]), "reflectance": np.array([0.3, 0.3, 0.3])}),
    ("diffuser", {"transmittance": np.full(3, 0.9), "sigma": np.sin(np.radians([4.0, 2.0])),
                  "sigma_deg": np.array([4.0, 2.0])}),
])
def test_scattering_surfaces_conserve_energy_and_match_their_pdf(mtype, params):
    """Hemispherical albedo by sampling (weights) equals the integral of eval_fcos over the sphere
    (uniform-sphere Monte Carlo), and the sampled weight equals eval_fcos / pdf."""
    s = make_surface(obj(mtype, **params))
    it = hits(incoming(25))
    d, f, alive = s.scatter(it, make_rng(7), False)
    albedo_sampled = f[:, 1].mean()
    ok = alive & (s.pdf(it, d) > 0)
    np.testing.assert_allclose(f[ok, 1], s.eval_fcos(it, d)[ok, 1] / s.pdf(it, d)[ok], rtol=1e-9)
    if mtype == "diffuser":
        # Narrow lobe: integrate in direction-cosine space around the straight-through direction.
        g = np.linspace(-0.4, 0.4, 801)
        bx, by = np.meshgrid(g + np.sin(np.radians(25)), g)
        dz = -np.sqrt(np.clip(1 - bx**2 - by**2, 0, None))
        dirs = np.stack([bx, by, dz], -1).reshape(-1, 3)
        it2 = hits(np.tile(incoming(25, 1)[0], (len(dirs), 1)))
        integral = (s.eval_fcos(it2, dirs)[:, 1] / np.abs(dirs[:, 2])).sum() * (g[1] - g[0]) ** 2
    else:
        u = make_rng(8).random((400_000, 2))
        dirs = uniform_sphere(u)
        it2 = hits(np.tile(incoming(25, 1)[0], (len(dirs), 1)))
        integral = s.eval_fcos(it2, dirs)[:, 1].mean() * 4 * np.pi
    expected = {"lambertian": 0.6, "lambertian_transmitter": 0.9, "diffuser": 0.9}[mtype]
    assert integral == pytest.approx(expected, rel=0.01)
    assert albedo_sampled == pytest.approx(expected, rel=0.01)


def test_lambertian_and_lobe_reciprocity():
    """f(a -> b) = f(b -> a) for the Lambertian BRDF and the Gaussian BTDF."""
    rng = make_rng(9)
    a = uniform_sphere(rng.random((1000, 2)))
    b = uniform_sphere(rng.random((1000, 2)))
    a[:, 2] = -np.abs(a[:, 2])  # a arrives from the front
    for mtype, params, b_side in [("lambertian", {"reflectance": np.full(3, 0.7)}, 1),
                                  ("diffuser", {"transmittance": np.full(3, 0.9), "sigma": np.full(2, 0.3),
                                                "sigma_deg": np.full(2, 17.5)}, -1)]:
        s = make_surface(obj(mtype, **params))
        bb = b.copy()
        bb[:, 2] = b_side * np.abs(bb[:, 2])
        f_ab = s.eval_fcos(hits(a), bb)[:, 0] / np.abs(bb[:, 2])
        # Reverse: light arrives along -b and leaves along -a.
        f_ba = s.eval_fcos(hits(-bb), -a)[:, 0] / np.abs(a[:, 2])
        np.testing.assert_allclose(f_ab, f_ba, rtol=1e-9, atol=1e-12)


def test_lcd_transmittance_and_contrast():
    img = np.zeros((2, 2, 3))
    img[0, 0] = 1.0  # top-left clear
    s = make_surface(obj("lcd", image=img, transmittance=np.full(3, 0.05), contrast_ratio=300.0))
    it = hits(incoming(0, 2))
    it.uv = np.array([[0.25, 0.75], [0.75, 0.25]])
    _, f, _ = s.scatter(it, make_rng(10), False)
    np.testing.assert_allclose(f[:, 0], [0.05, 0.05 / 300])


def test_emitter_flux_and_luminance_agree():
    from tracer.scene import emitter_luminance
    from tracer.units import lambertian_flux_lm

    o = obj("emitter", flux=1.0, color=np.ones(3), two_sided=False)
    L = emitter_luminance(o)  # 4 mm^2 panel, 1 lm
    assert lambertian_flux_lm(L, o.area_mm2) == pytest.approx(1.0)
    assert L == pytest.approx(1.0 / (np.pi * 4e-6))
