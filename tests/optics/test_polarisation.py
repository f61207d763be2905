"""Polarisation and Fresnel's equations (tracer.optics.polar, tracer.optics.fresnel): Stokes vectors and
Mueller matrices against closed forms, the unpolarised Fresnel reflectance and refraction (quiet at grazing
incidence), every method on a windshield-like plate for unpolarised, s and p light, the ghost ratio,
analysers, a half-wave film, depolarisation, coatings given for s and p light, and what needs no
polarisation at all.

Closed forms: Fresnel's s and p reflectances (Born & Wolf, Principles of Optics, sec. 1.5.2, in the
angle form R_s = sin^2(i - t) / sin^2(i + t), R_p = tan^2(i - t) / tan^2(i + t)), Brewster's angle
tan(i_B) = n, the total-internal-reflection phase (sec. 1.5.4, eq. 60), Malus's law, and the flat
plate's incoherent reflectance R + T^2 R / (1 - R^2) for each polarisation, with the ghost-to-primary
ratio [(1-Rs)^2 Rs + (1-Rp)^2 Rp] / (Rs + Rp) for unpolarised light (0.576 at 67 deg, n = 1.52),
(1 - Rs)^2 for s light (0.545) and (1 - Rp)^2 for p light (0.958)."""

import math

import numpy as np
import pytest

from presets._build import SceneBuilder, frame_matrix, rectangle
from tests.support.optics import N_GLASS, fresnel_angles, incoming, plate_total
from tests.support.render import image_mean
from tests.support.scenes import plate_scene
from tests.support.stats import film_dof, t_bound, z_bound
from tracer.core.units import Y_WEIGHTS
from tracer.core.vec import F32, reflect
from tracer.methods import INTEGRATORS, Budget
from tracer.optics import materials, polar
from tracer.optics.bsdf import DELTA, IMPORTANCE, RADIANCE, REFLECTION, TRANSMISSION, Interaction
from tracer.optics.fresnel import fresnel_unpolarized, refract
from tracer.optics.materials import Coating, Dielectric, Mirror
from tracer.scene import load_scene
from tracer.transport.chains import specular_paths
from tracer.transport.world import World


# -- Mueller matrices of single interfaces -----------------------------------------------------------
class _Obj:
    """The least of a scene object a material needs (its parameters and slot)."""

    def __init__(self, params, slot=0):
        self.material = type("M", (), {"params": params})()
        self.slot = slot
        self.local_x = np.array([1.0, 0.0, 0.0])


def _interaction(theta_deg: float, n: int = 1) -> Interaction:
    """Rays arriving at theta_deg on the front of a surface with normal +z, in the x-z plane."""
    t = math.radians(theta_deg)
    d = np.tile(np.array([[math.sin(t)], [0.0], [-math.cos(t)]], F32), (1, n))
    ng = np.tile(np.array([[0.0], [0.0], [1.0]], F32), (1, n))
    return Interaction(d, np.zeros((3, n)), ng, ng, None, np.zeros(n, np.int64))


def _reflect_unpolarised(mat, theta_deg: float):
    """(S0, S1) of unpolarised light of intensity 1 after the reflection lobe, in the s frame."""
    it = _interaction(theta_deg)
    s = mat.sample(it, np.zeros((max(mat.dims, 1), 1), F32), IMPORTANCE)
    lobes = mat.lobes(it, IMPORTANCE)
    wo, weight = lobes[0][0], np.broadcast_to(lobes[0][1], (3, 1))
    m = mat.mueller(it, it.d, wo, np.full(1, DELTA | REFLECTION, np.int8))
    s0, s_ = polar.sp_apply(np.ones((3, 1), F32), np.zeros((3, 3, 1), F32), m.b, m.c, m.d, row=False)
    assert s.flags[0] & REFLECTION
    return float(weight[1, 0] * s0[1, 0]), float(weight[1, 0] * s_[0, 1, 0]), m


@pytest.mark.parametrize("theta", [10.0, 30.0, 45.0, 60.0, 67.0, 80.0])
def test_dielectric_reflects_s_and_p_as_fresnel_says(theta):
    mat = Dielectric([_Obj({"ior": N_GLASS, "ior_outside": 1.0})])
    rs, rp = fresnel_angles(theta)
    s0, s1, m = _reflect_unpolarised(mat, theta)
    # Unpolarised light reflects (Rs + Rp) / 2, polarised by (Rs - Rp) / 2 along s (S1 in the s frame).
    assert s0 == pytest.approx(0.5 * (rs + rp), rel=1e-5)
    assert s1 == pytest.approx(0.5 * (rs - rp), rel=1e-4, abs=1e-7)
    # The s frame is perpendicular to the plane of incidence (x-z): along y.
    assert abs(float(m.x_in[1, 0])) == pytest.approx(1.0, abs=1e-6)
    # s light alone: Rs; p light alone: Rp.
    for sign, expected in ((1.0, rs), (-1.0, rp)):
        s0p, _ = polar.sp_apply(np.ones((3, 1)), np.array([[[sign]] * 3, [[0.0]] * 3, [[0.0]] * 3]), m.b, m.c, m.d,
                                row=False)
        assert 0.5 * (rs + rp) * float(s0p[0, 0]) == pytest.approx(expected, rel=1e-4, abs=1e-7)


def test_brewster_angle_reflects_no_p_light():
    """At tan(i) = n the reflection is fully s-polarised: degree of polarisation 1 (b = 1)."""
    mat = Dielectric([_Obj({"ior": N_GLASS, "ior_outside": 1.0})])
    s0, s1, m = _reflect_unpolarised(mat, math.degrees(math.atan(N_GLASS)))
    assert s1 / s0 == pytest.approx(1.0, abs=1e-5)
    rs, _ = fresnel_angles(math.degrees(math.atan(N_GLASS)))
    assert s0 == pytest.approx(rs / 2, rel=1e-5)


def test_refraction_transmits_one_minus_r_for_each_polarisation():
    for theta in (20.0, 50.0, 67.0):
        rs, rp = fresnel_angles(theta)
        c = math.cos(math.radians(theta))
        _, _, ts, tp = polar.amplitudes(np.array([c]), N_GLASS)
        b, cc, d = polar.sp_from_amplitudes(ts, tp)
        t_unpol = 1 - 0.5 * (rs + rp)
        assert t_unpol * (1 + float(b[0])) == pytest.approx(1 - rs, rel=1e-5)
        assert t_unpol * (1 - float(b[0])) == pytest.approx(1 - rp, rel=1e-5)
        # A non-depolarising element: b^2 + c^2 + d^2 = 1.
        assert float(b[0]) ** 2 + float(cc[0]) ** 2 + float(d[0]) ** 2 == pytest.approx(1.0, abs=1e-5)


def test_total_internal_reflection_keeps_intensity_and_retards_by_born_and_wolf():
    """Inside glass beyond the critical angle |r_s| = |r_p| = 1 and the phase difference delta obeys
    tan(delta / 2) = cos(i) sqrt(sin^2 i - n^2) / sin^2 i, n = 1 / 1.52 (Born & Wolf eq. 1.5 (60)); the
    Fresnel rhomb: two reflections at 54.6 deg in n = 1.51 make a quarter wave."""
    for theta in (45.0, 54.6, 70.0):
        i = math.radians(theta)
        n = 1 / N_GLASS
        rs, rp, _, _ = polar.amplitudes(np.array([math.cos(i)]), n)
        assert abs(rs[0]) == pytest.approx(1.0, abs=1e-12) and abs(rp[0]) == pytest.approx(1.0, abs=1e-12)
        b, c, d = polar.sp_from_amplitudes(rs, rp)
        delta = 2 * math.atan(math.cos(i) * math.sqrt(math.sin(i) ** 2 - n * n) / math.sin(i) ** 2)
        assert float(b[0]) == pytest.approx(0.0, abs=1e-6)
        # c + i d = 2 r_s conj(r_p) / (|r_s|^2 + |r_p|^2): its phase is the retardance.
        assert abs(math.atan2(float(d[0]), float(c[0]))) == pytest.approx(delta, abs=1e-5)
        assert float(c[0]) ** 2 + float(d[0]) ** 2 == pytest.approx(1.0, abs=1e-5)
        # The material's own matrix for a ray inside the glass (arriving on the back of the surface).
        it = _interaction(theta)
        it = Interaction(it.d, it.p, -it.ng, -it.ns, None, it.slot)
        m = Dielectric([_Obj({"ior": N_GLASS, "ior_outside": 1.0})]).mueller(it, it.d, it.d,
                                                                             np.full(1, DELTA | REFLECTION, np.int8))
        assert (float(m.b[0]), float(m.c[0]), abs(float(m.d[0]))) == pytest.approx(
            (float(b[0]), float(c[0]), abs(float(d[0]))), abs=1e-5)
    rs, rp, _, _ = polar.amplitudes(np.array([math.cos(math.radians(54.6))]), 1 / 1.51)
    z = rs[0] * np.conj(rp[0])
    assert 2 * abs(math.atan2(z.imag, z.real)) == pytest.approx(math.pi / 2, abs=0.01)


def test_metal_mirror_follows_the_complex_fresnel_equations():
    """Aluminium (n = 0.96 + 6.69i at 550 nm): R_s and R_p at 45 and 75 deg from the textbook's
    expressions for absorbing media (Born & Wolf sec. 14.2; the form of Heavens), and the mirror's
    reflectance field as its normal-incidence value."""
    eta = complex(0.96, 6.69)
    r_normal = abs((1 - eta) / (1 + eta)) ** 2
    mat = Mirror([_Obj({"reflectance": np.full(3, 0.9), "metal": {"complex_ior": np.array([0.96, 6.69])}})])
    assert mat.polarising
    for theta in (0.0, 45.0, 75.0):
        i = math.radians(theta)
        cos_t = np.sqrt(1 - (math.sin(i) / eta) ** 2)
        rs = abs((math.cos(i) - eta * cos_t) / (math.cos(i) + eta * cos_t)) ** 2
        rp = abs((eta * math.cos(i) - cos_t) / (eta * math.cos(i) + cos_t)) ** 2
        s0, s1, _ = _reflect_unpolarised(mat, theta)
        assert s0 == pytest.approx(0.9 * 0.5 * (rs + rp) / r_normal, rel=1e-5)
        assert s1 == pytest.approx(0.9 * 0.5 * (rs - rp) / r_normal, rel=1e-4, abs=1e-7)
    ideal = Mirror([_Obj({"reflectance": np.full(3, 0.9)})])
    assert not ideal.polarising
    s0, s1, m = _reflect_unpolarised(ideal, 60.0)
    assert (s0, s1, float(m.c)) == pytest.approx((0.9, 0.0, -1.0))


def test_coating_given_for_s_and_p():
    params = {k: np.full(3, v) for k, v in
              {"reflectance_s": 0.3, "reflectance_p": 0.1, "transmittance_s": 0.6, "transmittance_p": 0.85}.items()}
    mat = Coating([_Obj(params)])
    assert mat.polarising
    it = _interaction(60.0)
    for flags, (ts, tp) in ((DELTA | REFLECTION, (0.3, 0.1)), (DELTA | TRANSMISSION, (0.6, 0.85))):
        m = mat.mueller(it, it.d, it.d, np.full(1, flags, np.int8))
        mean = 0.5 * (ts + tp)
        for sign, expected in ((1.0, ts), (-1.0, tp)):
            s0, _ = polar.sp_apply(np.ones((3, 1)), np.array([[[sign]] * 3, [[0.0]] * 3, [[0.0]] * 3]), m.b, m.c,
                                   m.d, row=False)
            assert mean * float(s0[0, 0]) == pytest.approx(expected, rel=1e-6)


@pytest.mark.parametrize("mode", [IMPORTANCE, RADIANCE])
@pytest.mark.parametrize("phi_deg", [0.0, 90.0, 30.0, None])
def test_glass_chooses_its_branch_by_the_paths_polarisation(mode, phi_deg):
    """Light linearly polarised at phi from the s direction (None: unpolarised) meets glass at 67 deg:
    it reflects R_phi = R_s cos^2 phi + R_p sin^2 phi (Fresnel, Born & Wolf sec. 1.5.2). The branch is
    chosen with the even mixture of the unpolarised R and R_phi, and the weight times the Mueller
    factor makes each branch's expectation R_phi and (1 - R_phi) (/ n^2 for radiance); with the choice
    off, the frequency is R. Camera paths carry row vectors, for which the same numbers hold."""
    n = 400_000
    rs, rp = fresnel_angles(67.0)
    r = 0.5 * (rs + rp)
    phi = math.radians(phi_deg) if phi_deg is not None else None
    r_phi = r if phi is None else rs * math.cos(phi) ** 2 + rp * math.sin(phi) ** 2
    mat = Dielectric([_Obj({"ior": N_GLASS, "ior_outside": 1.0})])
    it = _interaction(67.0, n)
    stokes = np.zeros((3, 1, n), F32)
    if phi is not None:
        stokes[0], stokes[1] = math.cos(2 * phi), math.sin(2 * phi)
    it.polar = (stokes, polar.s_frame(it.d, it.ns))
    u = np.random.default_rng(4).random((1, n), dtype=F32)
    s = mat.sample(it, u, mode)
    refl = (s.flags & REFLECTION) != 0
    q = 0.5 * (r + r_phi)
    assert abs(refl.mean() - q) < z_bound(16 * 3) * math.sqrt(q * (1 - q) / n)
    m = mat.mueller(it, it.d, s.wo, s.flags)
    s1 = stokes[0, 0]
    value = s.weight[0] * (1 + m.b * s1)  # S0 after the interaction, per unit S0 before
    t_scale = 1.0 if mode == IMPORTANCE else 1 / N_GLASS**2
    for branch, expected in ((refl, r_phi), (~refl, (1 - r_phi) * t_scale)):
        x = np.where(branch, value, 0).astype(np.float64)
        assert abs(x.mean() - expected) < z_bound(16 * 3) * x.std() / math.sqrt(n) + 1e-6, (branch.mean(), expected)
    # Light paths at a lossless interface: every sample carries its flux unchanged.
    if mode == IMPORTANCE and phi is not None and phi_deg in (0.0, 90.0):
        assert np.allclose(value[refl], r_phi / q, rtol=1e-4) and np.allclose(value[~refl], (1 - r_phi) / (1 - q),
                                                                               rtol=1e-4)
    materials.POLARISED_CHOICE = False
    try:
        assert abs(((mat.sample(it, u, mode).flags & REFLECTION) != 0).mean() - r) < z_bound(16 * 3) * math.sqrt(
            r * (1 - r) / n)
    finally:
        materials.POLARISED_CHOICE = True


def test_frame_rotation_is_a_rotator_of_twice_the_angle():
    k = np.array([[0.0], [0.0], [1.0]], F32)
    x0 = np.array([[1.0], [0.0], [0.0]], F32)
    for deg in (10.0, 30.0, 45.0, 90.0, 135.0):
        a = math.radians(deg)
        x1 = np.array([[math.cos(a)], [math.sin(a)], [0.0]], F32)
        # Light polarised along x0: in frame x1 its axis is at -deg.
        s = polar.rotate(np.array([[[1.0]] * 3, [[0.0]] * 3, [[0.0]] * 3], F32), x0, x1, k)
        assert float(s[0, 0, 0]) == pytest.approx(math.cos(2 * a), abs=1e-6)
        assert float(s[1, 0, 0]) == pytest.approx(-math.sin(2 * a), abs=1e-6)


#: The emitter's polarisation: its local x is the world x, perpendicular to the plane of incidence (s).
LIGHTS = {"unpolarised": None, "s": {"axis_deg": 0.0}, "p": {"axis_deg": 90.0}}


def _expected_plate(light: str) -> float:
    rs, rp = fresnel_angles(67.0)
    ts, tp = plate_total(rs), plate_total(rp)
    return 1000.0 * {"unpolarised": 0.5 * (ts + tp), "s": ts, "p": tp}[light]


@pytest.mark.slow
@pytest.mark.parametrize("light", list(LIGHTS))
def test_every_method_sees_the_plate_reflect_each_polarisation_as_fresnel_says(tmp_path, light):
    """The panel's luminance through the plate, L [R + T^2 R / (1 - R^2)] per polarisation (the mean of
    s and p for unpolarised light), from the brightness-theorem analysis and backward and photon tracing
    (the field is 0.1 deg, over which R varies by 0.1 %), and from forward tracing on a 4 deg field
    against the analysis of that field (a particle lands in the narrow one once in 10^6: a lottery)."""
    pol = LIGHTS[light]
    emitter = {"polarisation": pol} if pol else None
    world = World(load_scene(plate_scene(tmp_path / "p", emitter=emitter)))
    assert world.polarised

    def predicted(w):
        pred = specular_paths(w, pupil_grid=4, seed=2)
        return sum(float((p["luminance"] @ Y_WEIGHTS).sum()) for p in pred["paths"]) / len(pred["pixels"])

    expected = _expected_plate(light)
    assert predicted(world) == pytest.approx(expected, rel=2e-3)
    wide = World(load_scene(plate_scene(tmp_path / "w", emitter=emitter, fov=(4.0, 4.0))))
    # Many small batches: the standard error of the image mean from many replicates (that of the
    # pixels' sum would leave out the photon map's correlations).
    for method, w, rays, target in (("backward", world, 200_000, expected), ("photon", world, 200_000, expected),
                                    ("forward", wide, 1_500_000, predicted(wide))):
        res = INTEGRATORS[method](w, 5, batch_size=4096 if method != "forward" else None).render(Budget(rays=rays))
        assert res.film.replicates >= 30
        m, se = float((res.film.rgb() @ Y_WEIGHTS).mean()), res.film.mean_standard_error()
        assert abs(m - target) < t_bound(3 * 3, film_dof(res.film)) * max(se, 1e-3 * target), (method, m, target, se)


@pytest.mark.slow
@pytest.mark.parametrize("light,ratio", [("unpolarised", None), ("s", None), ("p", None)])
def test_ghost_ratio_of_a_flat_plate(tmp_path, light, ratio):
    """The ghost (refract, reflect at the back, refract) over the primary (reflect) for the same eye ray,
    from the analysis' chain factors: 0.576 for unpolarised light, 0.545 for s and 0.958 for p at 67 deg;
    and the stochastic methods' two images (a strip seen through a 20 mm plate, the images on
    different rows) agree with the analysis' prediction of the same rows."""
    rs, rp = fresnel_angles(67.0)
    closed = {"unpolarised": ((1 - rs) ** 2 * rs + (1 - rp) ** 2 * rp) / (rs + rp), "s": (1 - rs) ** 2,
              "p": (1 - rp) ** 2}[light]
    assert closed == pytest.approx({"unpolarised": 0.576, "s": 0.545, "p": 0.958}[light], abs=1e-3)
    pol = LIGHTS[light]
    world = World(load_scene(plate_scene(tmp_path / "p", emitter={"polarisation": pol} if pol else None)))
    chains = {p["path"]: p for p in specular_paths(world, stride=1)["paths"]}
    primary = chains["plate:reflect > emitter"]
    ghost = chains["plate:refract > plate:reflect > plate:refract > emitter"]
    assert np.array_equal(primary["ray"], ghost["ray"])  # the same rays, each split at the first surface
    y = lambda p: p["luminance"] @ Y_WEIGHTS  # noqa: E731
    assert y(ghost) / y(primary) == pytest.approx(np.full(len(primary["ray"]), closed), rel=2e-3)

    # The images apart: a strip through a thick plate.
    strip = World(load_scene(plate_scene(tmp_path / "s", 20.0, {"polarisation": pol} if pol else None, strip=True,
                                          resolution=(4, 48), fov=(0.4, 6.0))))
    pred = specular_paths(strip, pupil_grid=6, seed=3)
    h, w = strip.eye.height, strip.eye.width
    rows = {}
    for p in pred["paths"]:
        r = pred["pixels"][p["pixel"]] // w
        rows[p["path"]] = np.bincount(r, weights=p["luminance"] @ Y_WEIGHTS, minlength=h)
    prim_rows = rows["plate:reflect > emitter"]
    ghost_rows = rows["plate:refract > plate:reflect > plate:refract > emitter"]
    split = int(np.flatnonzero(prim_rows > 0).max()) + 1
    assert split <= int(np.flatnonzero(ghost_rows > 0).min())  # apart
    # (Not the closed form: the two images see the plate at incidence angles 2 deg apart, and R_p
    # changes by a half over them.)
    predicted = ghost_rows[split:].sum() / prim_rows[:split].sum()
    for method, rays in (("backward", 400_000), ("forward", 4_000_000)):
        res = INTEGRATORS[method](strip, 7).render(Budget(rays=rays))
        img = res.film.rgb() @ Y_WEIGHTS
        var = res.film.variance_y()
        a, b = img[:split].sum(), img[split:].sum()
        va, vb = var[:split].sum(), var[split:].sum()
        got = b / a
        se = got * math.sqrt(va / a**2 + vb / b**2)
        assert abs(got - predicted) < z_bound(3 * 2) * se + 2e-3 * predicted, (method, got, predicted, se)


def _direct_panel(folder, analyser, pol=None, film=None, lambertian=False):
    """The eye looks straight at an emitting panel 200 mm away (or at a Lambertian panel lit by a
    polarised emitter beside the eye), through an optional half-wave film, with an analyser."""
    sb = SceneBuilder(folder, "panel", "a panel seen through an analyser")
    em = {"luminance": 1000.0, "aim": {"target": "eye", "share": 0.9}}
    if pol is not None:
        em["polarisation"] = pol
    extra_eye = {"analyser": analyser} if analyser is not None else {}
    if lambertian:
        sb.add("panel", rectangle(80.0, 80.0)[:2], {"type": "lambertian", "reflectance": 0.8,
                                                     "aim": {"target": "eye", "share": 0.9}},
               frame_matrix([0, 200.0, 0], [1, 0, 0], [0, -1, 0]))
        sb.add("lamp", rectangle(20.0, 20.0)[:2], {"type": "absorber"},
               frame_matrix([0, 100.0, -60.0], [1, 0, 0], [0, 0.6, 0.8]), emission=em | {"aim": {"target": "panel",
                                                                                                  "share": 0.9}})
    else:
        sb.add("panel", rectangle(80.0, 80.0)[:2], {"type": "absorber"},
               frame_matrix([0, 200.0, 0], [1, 0, 0], [0, -1, 0]), emission=em)
    if film is not None:
        sb.add("film", rectangle(60.0, 60.0)[:2], {"type": "retarder", "axis_deg": film},
               frame_matrix([0, 100.0, 0], [1, 0, 0], [0, -1, 0]))
    return sb.write(eye={"position": [0.0, 0.0, 0.0], "gaze": [0, 1, 0], "up": [0, 0, 1], "pupil_diameter_mm": 4.0,
                         "resolution": [4, 4], "fov_deg": [2.0, 2.0]} | extra_eye)


@pytest.mark.slow
def test_malus_law_through_the_analyser(tmp_path):
    """Light polarised at angle a to the analyser's axis passes t_along cos^2 a + t_across sin^2 a
    (Malus), in backward and forward tracing and the analysis; unpolarised light (t_along + t_across) / 2."""
    analyser = {"axis_deg": 0.0, "transmittance_along": 0.9, "transmittance_across": 0.02}
    cases = [(a, 1000.0 * (0.9 * math.cos(math.radians(a)) ** 2 + 0.02 * math.sin(math.radians(a)) ** 2))
             for a in (0.0, 30.0, 60.0, 90.0)] + [(None, 1000.0 * 0.46)]
    for k, (angle, expected) in enumerate(cases):
        folder = _direct_panel(tmp_path / f"m{k}", analyser, {"axis_deg": angle} if angle is not None else None)
        world = World(load_scene(folder))
        pred = specular_paths(world, stride=1)
        assert float(pred["paths"][0]["luminance"] @ Y_WEIGHTS @ np.ones(16) / 16) == pytest.approx(expected, rel=1e-5)
        for method, rays in (("backward", 20_000), ("forward", 300_000)):
            m, se = image_mean(world, method, rays)
            assert abs(m - expected) < z_bound(2 * len(cases)) * se + 1e-5 * expected, (angle, method, m, expected)


def test_half_wave_film_rotates_the_axis(tmp_path):
    """A half-wave film with its fast axis at f turns light polarised at 0 to 2 f: through an analyser at
    b the eye sees L cos^2(2 f - b)."""
    analyser = {"axis_deg": 45.0, "transmittance_along": 1.0, "transmittance_across": 0.0}
    for k, f in enumerate((0.0, 22.5, 45.0, 67.5)):
        world = World(load_scene(_direct_panel(tmp_path / f"h{k}", analyser, {"axis_deg": 0.0}, film=f)))
        expected = 1000.0 * math.cos(math.radians(2 * f - 45.0)) ** 2
        pred = specular_paths(world, stride=1)
        got = sum(float((p["luminance"] @ Y_WEIGHTS).sum()) for p in pred["paths"]) / 16
        assert got == pytest.approx(expected, rel=1e-4, abs=1e-3)
        m, se = image_mean(world, "backward", 20_000)
        assert abs(m - expected) < z_bound(4) * se + 1e-4 * 1000, (f, m, expected)


@pytest.mark.slow
def test_lambertian_surface_depolarises(tmp_path):
    """A Lambertian panel lit by polarised light looks the same through an analyser at any angle: half of
    the unanalysed luminance (next-event estimation, the paths' own hits and forward tracing)."""
    values = {}
    for k, axis in enumerate((None, 0.0, 90.0)):
        analyser = None if axis is None else {"axis_deg": axis}
        world = World(load_scene(_direct_panel(tmp_path / f"l{k}", analyser, {"axis_deg": 0.0}, lambertian=True)))
        assert world.polarised
        values[axis] = {m: image_mean(world, m, r, seed=4 + k)
                        for m, r in (("backward", 40_000), ("forward", 2_000_000))}
    zb = z_bound(4)
    for method in ("backward", "forward"):
        base, se_base = values[None][method]
        assert base > 0
        for axis in (0.0, 90.0):
            m, se = values[axis][method]
            assert abs(m - 0.5 * base) < zb * math.hypot(se, 0.5 * se_base), (method, axis, m, base)


# -- what needs polarisation ----------------------------------------------------------------------
@pytest.mark.slow
def test_scenes_without_a_polarising_element_carry_nothing(preset, tmp_path):
    for name in ("analytic-mirror", "analytic-disk", "hud-screen"):
        scene = load_scene(preset(name))
        if any(o.material.type == "dielectric" for o in scene.objects):
            continue
        assert World(scene).polar is None, name
    # A retarder film alone does nothing to unpolarised light: nothing is carried.
    folder = _direct_panel(tmp_path / "f", None, None, film=30.0)
    assert World(load_scene(folder)).polar is None
    # "off" is the unpolarised Fresnel average of an RGB renderer: the plate reflects (1 - R)^2 ghosts.
    folder = plate_scene(tmp_path / "o", polarisation="off")
    world = World(load_scene(folder))
    assert world.polar is None
    rs, rp = fresnel_angles(67.0)
    r = 0.5 * (rs + rp)
    m, se = image_mean(world, "backward", 100_000)
    assert abs(m - 1000.0 * plate_total(r)) < z_bound(1) * se + 2e-3 * m


@pytest.mark.parametrize("mode", [RADIANCE, IMPORTANCE])
def test_scatter_conserves_the_degree_of_polarisation_bound(mode):
    """|S1..S3| <= S0 after any chain of Fresnel interactions (a physical Stokes vector, or a physical
    detector row), here 50 random reflections and refractions, and the state stays one for the three
    channels (achromatic matrices)."""
    rng = np.random.default_rng(0)
    mat = Dielectric([_Obj({"ior": N_GLASS, "ior_outside": 1.0})])

    class W:  # the least of a world the transport needs
        scene = type("S", (), {"objects": []})()
        materials = [mat]
        eye = type("E", (), {"spec": type("Spec", (), {"analyser": None})()})()

    tr = polar.Transport(W())
    n = 256
    beta = np.ones((3, n), F32)
    d = rng.normal(size=(3, n)).astype(F32)
    d /= np.linalg.norm(d, axis=0)
    extra = {"stokes": np.zeros((3, 1, n), F32), "frame": polar.any_frame(d)}
    extra["stokes"][0] = 0.7  # partly polarised to start (normalised: S1 / S0)
    for _ in range(50):
        ng = rng.normal(size=(3, n)).astype(F32)
        ng /= np.linalg.norm(ng, axis=0)
        ng = np.where((ng * d).sum(axis=0) < 0, ng, -ng)
        it = Interaction(d, np.zeros((3, n)), ng, ng, None, np.zeros(n, np.int64))
        s = mat.sample(it, rng.random((1, n)).astype(F32), mode)
        beta, stokes, frame = tr.scatter(beta, extra, it, mat, s.wo, s.weight, s.flags, mode == IMPORTANCE)
        extra = {"stokes": stokes, "frame": frame}
        d = s.wo
        norm = np.sqrt((stokes * stokes).sum(axis=0))
        assert np.all(norm <= 1 + 1e-4)  # the degree of polarisation
        assert np.all(np.abs((frame * d).sum(axis=0)) < 1e-4)  # the frame stays perpendicular


@pytest.mark.parametrize("method", ["backward", pytest.param("forward", marks=pytest.mark.slow)])
def test_coatings_of_one_s_p_pair_for_all_channels_carry_one_state(tmp_path, method):
    """The periscope below with both coatings achromatic (R_s 0.8, R_p 0.2): paths carry one
    polarisation state for the three channels, which the coating's per-channel s/p rows did not fit
    (every method ended in a broadcast ValueError, found by a hand-built scene). Unpolarised light
    leaves L (R_s^2 + R_p^2) / 2 = 0.34 L, not the unpolarised product 0.25 L."""
    sb = SceneBuilder(tmp_path / "c", "periscope", "two coatings")
    sq = math.sqrt(0.5)
    coat = {"type": "coating", "reflectance_s": 0.8, "reflectance_p": 0.2, "transmittance_s": 0.0,
            "transmittance_p": 0.0}
    sb.add("lower", rectangle(40.0, 40.0)[:2], coat, frame_matrix([0, 100.0, 0], [1, 0, 0], [0, -sq, sq]))
    sb.add("upper", rectangle(40.0, 40.0)[:2], coat, frame_matrix([0, 100.0, 100.0], [1, 0, 0], [0, sq, -sq]))
    sb.add("panel", rectangle(60.0, 60.0)[:2], {"type": "absorber"}, frame_matrix([0, 200.0, 100.0], [1, 0, 0],
                                                                                  [0, -1, 0]),
           emission={"luminance": 1000.0, "aim": {"target": "upper", "share": 0.95}})
    folder = sb.write(eye={"position": [0.0, 0.0, 0.0], "gaze": [0, 1, 0], "up": [0, 0, 1], "pupil_diameter_mm": 4.0,
                           "resolution": [4, 4], "fov_deg": [5.0, 5.0]})
    world = World(load_scene(folder))
    assert world.polar.channels == 1
    expected = 1000.0 * 0.5 * (0.8**2 + 0.2**2)
    res = INTEGRATORS[method](world, 2, options=dict(world.scene.method_options(method))).render(
        Budget(rays=20_000 if method == "backward" else 10_000_000))
    y = res.film.rgb() @ Y_WEIGHTS
    se = math.sqrt(res.film.variance_y().sum()) / y.size
    if method == "backward":
        assert y.mean() == pytest.approx(expected, rel=1e-4)
    else:
        assert abs(y.mean() - expected) < z_bound(2) * se and se < 0.05 * expected, (y.mean(), se)


def test_a_chromatic_coating_keeps_a_state_per_channel(tmp_path):
    """A periscope of two coatings at 45 deg (one plane of incidence): the first with s/p reflectances
    that differ by channel, the second with one pair for all. Unpolarised light leaves, per channel c,
    L (Rs1_c Rs2 + Rp1_c Rp2) / 2, which no single polarisation state for the three channels gives."""
    rs1, rp1, rs2, rp2 = np.array([0.6, 0.3, 0.1]), np.array([0.1, 0.3, 0.5]), 0.8, 0.2
    sb = SceneBuilder(tmp_path / "c", "periscope", "two coatings")
    sq = math.sqrt(0.5)
    coat = lambda r_s, r_p: {"type": "coating", "reflectance_s": np.broadcast_to(r_s, 3).tolist(),  # noqa: E731
                             "reflectance_p": np.broadcast_to(r_p, 3).tolist(), "transmittance_s": 0.0,
                             "transmittance_p": 0.0}
    sb.add("lower", rectangle(40.0, 40.0)[:2], coat(rs2, rp2), frame_matrix([0, 100.0, 0], [1, 0, 0], [0, -sq, sq]))
    sb.add("upper", rectangle(40.0, 40.0)[:2], coat(rs1, rp1), frame_matrix([0, 100.0, 100.0], [1, 0, 0],
                                                                            [0, sq, -sq]))
    sb.add("panel", rectangle(60.0, 60.0)[:2], {"type": "absorber"}, frame_matrix([0, 200.0, 100.0], [1, 0, 0],
                                                                                  [0, -1, 0]),
           emission={"luminance": 1000.0, "color": [1.0, 1.0, 1.0]})
    folder = sb.write(eye={"position": [0.0, 0.0, 0.0], "gaze": [0, 1, 0], "up": [0, 0, 1], "pupil_diameter_mm": 4.0,
                           "resolution": [4, 4], "fov_deg": [1.0, 1.0]})
    world = World(load_scene(folder))
    assert world.polar.channels == 3
    expected = 1000.0 * 0.5 * (rs1 * rs2 + rp1 * rp2)  # (3,) relative to the emitter's RGB
    rgb_emit = world.lights.radiance[:, 0] / 1000.0
    pred = specular_paths(world, stride=1)
    got = sum(p["luminance"].sum(axis=0) for p in pred["paths"]) / 16
    assert got == pytest.approx(expected * rgb_emit, rel=1e-4)
    res = INTEGRATORS["backward"](world, 2).render(Budget(rays=20_000))
    assert res.film.rgb().mean(axis=(0, 1)) == pytest.approx(expected * rgb_emit, rel=1e-4)
    # One state for the three channels would give each channel's luminance-weighted mix instead.
    assert not np.allclose(expected, 0.5 * (rs1 + rp1) * 0.5 * (rs2 + rp2), rtol=0.05)


# -- the unpolarised Fresnel equations (tracer.optics.fresnel) --------------------------------------
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
    d = incoming(40, 1).T
    n = np.array([[0.0], [0.0], [1.0]])
    ci = np.array([np.cos(np.radians(40))])
    _, ct = fresnel_unpolarized(ci, 1.52)
    t = refract(d, n, 1.52, ci, ct)
    assert np.sin(np.radians(40)) == pytest.approx(1.52 * np.hypot(t[0, 0], t[1, 0]), rel=1e-12)
    assert reflect(d, n)[2, 0] == pytest.approx(-d[2, 0])


def test_grazing_fresnel_is_quiet():
    """Fresnel's masked 0/0 at grazing incidence and total internal reflection is quiet (it printed a
    RuntimeWarning): finite reflectances in [0, 1] from either side."""
    from tracer.optics.fresnel import fresnel_unpolarized

    cos_i = np.array([0.0, 1e-12, 1e-6, 0.1, 1.0])
    with np.errstate(all="raise"):
        for eta in (1.5, 1 / 1.5):
            r, cos_t = fresnel_unpolarized(cos_i, eta)
            assert np.all(np.isfinite(r)) and np.all((r >= 0) & (r <= 1)) and np.all(np.isfinite(cos_t))
