"""The transport core: next-event estimation against a closed form and against the other methods on
every preset, multiple importance sampling that counts every light path once, connections blocked by
glass, and a Russian roulette that does not starve the LCD's black leak."""

import math

import numpy as np
import pytest
from conftest import edit_json, film_dof, t_bound, welch_dof, z_bound

from presets import PRESETS, SINGLE_METHOD
from presets._build import SceneBuilder, annulus, box, frame_matrix, rectangle
from tracer.core.imageio import write_png
from tracer.core.units import Y_WEIGHTS
from tracer.methods import INTEGRATORS, Budget
from tracer.scene import load_scene
from tracer.transport.world import World

#: The method variants every preset must agree on.
VARIANTS = {"forward": ("forward", {}), "backward": ("backward", {}),
            "backward, no NEE": ("backward", {"next_event": False})}


def run(world, variant, rays, seed, reference=None):
    method, changes = VARIANTS[variant]
    integ = INTEGRATORS[method](world, seed, options=dict(world.scene.method_options(method)) | changes)
    if reference is not None:
        integ.reference_luminance  # noqa: B018  (the pilot runs first: it also measures the efficiency)
        integ._reference = reference  # the roulette's reference luminance (0: no roulette)
    res = integ.render(Budget(rays=rays))
    return res.film.rgb() @ Y_WEIGHTS, res.film.variance_y(), res


def region_mean(y, var, mask):
    k = int(mask.sum())
    return float(y[mask].mean()), math.sqrt(float(var[mask].sum())) / k


def region_dof(var, mask, res):
    """Degrees of freedom of a region mean's variance: a sum of its pixels' variances, each from the
    spread of the film's replicates (Welch-Satterthwaite)."""
    return welch_dof((var[mask], film_dof(res.film)))


# -- a closed form --------------------------------------------------------------------------------
def _small_source(folder):
    """A 0.2 mm Lambertian square (L = 1e6 cd/m^2) 100 mm above a Lambertian floor (rho = 0.5), 40 mm
    to the side of the point the eye looks at through a 0.04 deg field."""
    sb = SceneBuilder(folder, "small-source", "a small source over a Lambertian floor")
    sb.add("floor", rectangle(400.0, 400.0)[:2], {"type": "lambertian", "reflectance": 0.5,
                                                  "aim": {"target": "eye", "share": 0.9}})
    sb.add("led", rectangle(0.2, 0.2)[:2], {"type": "absorber"},
           frame_matrix([40.0, 0.0, 100.0], [1, 0, 0], [0, 0, -1]), emission={"luminance": 1e6})
    return sb.write(eye={"position": [0.0, -300.0, 300.0], "gaze": [0.0, 1.0, -1.0], "up": [0, 0, 1],
                         "pupil_diameter_mm": 4.0, "accommodation_distance_mm": 424.26,
                         "resolution": [3, 3], "fov_deg": [0.04, 0.04]})


def test_lambertian_floor_under_a_small_source(tmp_path):
    """E = I cos(theta) / d^2, I = L A cos(theta_e): the floor reads rho E / pi. Backward with
    next-event estimation reproduces it to 2 % at 300,000 rays; forward (the floor aims at the pupil)
    agrees within its error, which stays large: few particles land on the 0.3 mm of floor the pixels
    see. The paper's plain backward method would need a path to hit a 0.04 mm^2 source from the floor
    (p ~ 4e-7 per path)."""
    world = World(load_scene(_small_source(tmp_path / "s")))
    d2 = 40.0**2 + 100.0**2
    cos = 100.0 / math.sqrt(d2)
    expected = 0.5 / math.pi * 1e6 * 0.04 * cos * cos / d2
    for variant, rays in (("backward", 300_000), ("forward", 3_000_000)):
        y, var, res = run(world, variant, rays, seed=4)
        m, se = region_mean(y, var, np.ones(y.shape, bool))
        assert abs(m - expected) < z_bound(2) * se, (variant, m, expected, se)
        if variant == "backward":
            assert se < 0.02 * expected, (variant, se / expected)
    assert res.efficiency > 0


# -- shading normals ------------------------------------------------------------------------------
def _ring_under_a_smoothed_dome(folder):
    """A ring emitter (1000 cd/m^2, facing up) lights a Lambertian floor only through a concave mirror
    above it (R 0.9, facing down) of 2 x 2 cells, 8 triangles, with smooth normals: the shading
    normals stray up to 25 deg from the faces. The floor sees the ring's dark back, so no connection
    finds light; eye paths reach the ring through the mirror by their own samples."""
    n, half, c = 2, 60.0, 0.0039
    xs = np.linspace(-half, half, n + 1)
    gx, gy = np.meshgrid(xs, xs)
    vertices = np.stack([gx.ravel(), gy.ravel(), 150.0 + c * (gx.ravel() ** 2 + gy.ravel() ** 2)], axis=1)
    faces = []
    for j in range(n):
        for i in range(n):
            a = j * (n + 1) + i
            faces += [[a, a + n + 1, a + 1], [a + 1, a + n + 1, a + n + 2]]  # normals down
    sb = SceneBuilder(folder, "smoothed-dome", "a ring lighting a floor through a smoothed mirror")
    sb.add("floor", rectangle(40.0, 40.0)[:2], {"type": "lambertian", "reflectance": 0.8,
                                                "aim": {"target": "eye", "share": 0.9}})
    sb.add("dome", (vertices, np.array(faces)), {"type": "mirror", "reflectance": 0.9}, smooth=True)
    sb.add("ring", annulus(30.0, 100.0, 64)[:2], {"type": "absorber"}, frame_matrix([0, 0, 50.0], [1, 0, 0], [0, 0, 1]),
           emission={"luminance": 1000.0})
    return sb.write(eye={"position": [0.0, -40.0, 120.0], "gaze": [0.0, 40.0, -120.0], "up": [0, 0, 1],
                         "pupil_diameter_mm": 4.0, "accommodation_distance_mm": 126.5,
                         "resolution": [6, 6], "fov_deg": [14.0, 14.0]})


def test_forward_tracing_through_smoothed_optics_is_the_adjoint_of_backward(tmp_path):
    """Materials weigh samples by cosines to the shading normal; for light paths that needs Veach's
    adjoint factor |d.ns| |wo.ng| / (|d.ng| |wo.ns|) (tracer.optics.bsdf.adjoint_shading_factor).
    Without it forward tracing read this floor 9.5 % above backward tracing (33.50 +- 0.09 against
    30.59 +- 0.04 cd/m^2 over three seeds); with it they agree (30.46 +- 0.08)."""
    world = World(load_scene(_ring_under_a_smoothed_dome(tmp_path / "d")))
    everywhere = np.ones((6, 6), bool)
    (yb, vb, rb), (yf, vf, rf) = (run(world, v, rays, seed=1) for v, rays in (("backward", 2_000_000),
                                                                             ("forward", 10_000_000)))
    (mb, sb), (mf, sf) = region_mean(yb, vb, everywhere), region_mean(yf, vf, everywhere)
    assert rb.extra.get("connection_share", 0.0) == 0.0  # the floor sees only the ring's back
    assert abs(mf - mb) < z_bound(1) * math.hypot(sb, sf) and math.hypot(sb, sf) < 0.02 * mb, (mf, sf, mb, sb)


# -- every preset, every method ---------------------------------------------------------------------
RAYS = {"hud-direct": 4_000_000, "analytic-mirror": 1_500_000, "analytic-disk": 1_500_000,
        "analytic-furnace": 1_000_000}
#: Presets that backward tracing cannot render in a test's time (its eye paths must find a 0.2 mm LED
#: through a diffuse screen and a projection lens): photon and forward agree on them instead.
PHOTON_PRESETS = ("hud-screen", "hud-screen-ideal-lcd", "hud-direct-condenser")


# The studies against a panorama (presets.STUDIES) are left out: forward tracing does not render an
# environment; tests/test_hybrid.py checks the hybrid's channels against backward tracing.
@pytest.mark.parametrize("name", [n for n in SINGLE_METHOD if n not in PHOTON_PRESETS])
def test_forward_and_backward_with_and_without_nee_agree(tmp_path, name):
    """The image mean and the bright region's mean (pixels above 10 % of the 99th percentile of the
    backward image) of the three method variants agree pairwise within their combined errors
    (alpha = 0.01, Sidak over presets, regions and pairs)."""
    world = World(load_scene(PRESETS[name].write(tmp_path / name)))
    out = {v: run(world, v, RAYS[name], seed=21) for v in VARIANTS}
    y_ref = out["backward"][0]
    bright = y_ref > 0.1 * np.percentile(y_ref, 99)
    for mask in (np.ones(y_ref.shape, bool), bright):
        stats = {v: (*region_mean(y, var, mask), region_dof(var, mask, res)) for v, (y, var, res) in out.items()}
        names = list(stats)
        for i in range(3):
            for j in range(i + 1, 3):
                (a, sa, fa), (b, sb, fb) = stats[names[i]], stats[names[j]]
                bound = t_bound(len(RAYS) * 2 * 3, welch_dof((sa * sa, fa), (sb * sb, fb)))
                assert abs(a - b) < bound * math.hypot(sa, sb), (name, names[i], names[j], a, b, sa, sb)


@pytest.mark.parametrize("name", PHOTON_PRESETS)
def test_photon_and_forward_agree_on_screen_presets(tmp_path, name):
    """The image mean of the photon method (whose gather blurs the image by its radius but keeps its
    total light) and of forward tracing agree within their errors (the spread of the replicates' image
    means, honest for the photon method's correlated pixels), and photons carry the image."""
    world = World(load_scene(PRESETS[name].write(tmp_path / name, resolution=(84, 32))))
    means = {}
    # Forward tracing's particles through the condenser carry a heavy tail (rare particles of large weight):
    # it gets more rays there, so that its replicates' spread measures its error.
    forward_rays = 30_000_000 if name == "hud-direct-condenser" else 12_000_000
    for method, rays in (("photon", 6_000_000), ("forward", forward_rays)):
        res = INTEGRATORS[method](world, 5).render(Budget(rays=rays))
        means[method] = (float((res.film.rgb() @ Y_WEIGHTS).mean()), res.film.mean_standard_error(),
                         film_dof(res.film))
        if method == "photon":
            assert res.extra["component_shares"]["photon"] > 0.99
    (a, sa, fa), (b, sb, fb) = means["photon"], means["forward"]
    bound = t_bound(len(PHOTON_PRESETS), welch_dof((sa * sa, fa), (sb * sb, fb)))
    assert abs(a - b) < bound * math.hypot(sa, sb) and max(sa / a, sb / b) < 0.08, means


def test_nee_report_gives_the_share_of_connections(tmp_path):
    """On hud-direct the symbols are the scatterer lit by the LEDs: almost all of the estimate comes
    through connections, and the report's components add up to the image."""
    from tracer.products.render import render_folder

    report, res = render_folder(PRESETS["hud-direct"].write(tmp_path / "s"), "backward", Budget(rays=1_500_000), 3,
                                tmp_path / "out", analyse=False)
    comp = report["components"]
    assert set(comp) == {"hit", "connection"}
    assert comp["connection"]["share"] > 0.95 and report["method_details"]["connection_share"] > 0.95
    assert sum(c["mean_cd_m2"] for c in comp.values()) == pytest.approx(report["luminance"]["mean"], rel=1e-9)
    assert set(report["stage_seconds"]) >= {"intersect", "shade", "shadow", "film", "other"}


# -- connections blocked by glass ------------------------------------------------------------------
def _light_behind_glass(folder):
    """A Lambertian floor lit by a panel through a glass slab: every connection from the floor to the
    panel crosses the slab, a specular surface, and is blocked; the light reaches the floor only along
    the paths' own sampled directions."""
    sb = SceneBuilder(folder, "glass", "a light behind a glass slab")
    sb.add("floor", rectangle(300.0, 300.0)[:2], {"type": "lambertian", "reflectance": 0.6})
    sb.add("slab", box(300.0, 300.0, 5.0), {"type": "dielectric", "ior": 1.5}, frame_matrix([0, 0, 40.0], [1, 0, 0],
                                                                                          [0, 0, 1]))
    sb.add("panel", rectangle(60.0, 60.0)[:2], {"type": "absorber"}, frame_matrix([0, 0, 80.0], [1, 0, 0], [0, 0, -1]),
           emission={"luminance": 1000.0})
    return sb.write(eye={"position": [0.0, -30.0, 20.0], "gaze": [0.0, 1.0, -0.7], "up": [0, 0, 1],
                         "pupil_diameter_mm": 4.0, "accommodation_distance_mm": 40.0,
                         "resolution": [6, 6], "fov_deg": [20.0, 20.0]})


def test_glass_between_vertex_and_light_blocks_the_connection(tmp_path):
    world = World(load_scene(_light_behind_glass(tmp_path / "g")))
    (y1, v1, r1), (y2, v2, r2) = (run(world, v, 2_000_000, seed=5) for v in ("backward", "backward, no NEE"))
    assert r1.extra.get("connection_share", 0.0) == 0.0  # every connection crossed the slab
    m1, s1 = region_mean(y1, v1, np.ones(y1.shape, bool))
    m2, s2 = region_mean(y2, v2, np.ones(y2.shape, bool))
    assert m1 > 0 and abs(m1 - m2) < z_bound(1) * math.hypot(s1, s2)


def test_light_aim_guides_eye_paths_through_glass_without_bias(tmp_path):
    """Eye-side guidance (issue 10, item 3): the floor names the aperture through which its light
    arrives (a window just below the panel, beyond the slab), and backward eye paths draw 80 % of their
    directions toward it (the one-sample mixture with the floor's own law). The estimate is unchanged
    within errors and its standard error falls at least twofold for the same rays."""
    folder = _light_behind_glass(tmp_path / "g")
    plain = World(load_scene(folder))

    def guide(data):
        data["objects"].append({"name": "window", "mesh": "meshes/window.obj", "material": {"type": "aperture"},
                                "transform": {"matrix": frame_matrix([0, 0, 79.0], [1, 0, 0], [0, 0, -1])}})
        data["objects"][0]["material"]["light_aim"] = {"target": "window", "share": 0.8}

    from presets._build import write_obj

    write_obj(folder / "meshes" / "window.obj", *rectangle(60.0, 60.0)[:2])
    edit_json(folder, guide)
    guided = World(load_scene(folder))
    assert guided.scene.objects[0].material.light_aim.target == "window"
    (y1, v1, _), (y2, v2, _) = (run(w, "backward", 1_000_000, seed=6) for w in (plain, guided))
    m1, s1 = region_mean(y1, v1, np.ones(y1.shape, bool))
    m2, s2 = region_mean(y2, v2, np.ones(y2.shape, bool))
    assert abs(m1 - m2) < z_bound(1) * math.hypot(s1, s2), (m1, s1, m2, s2)
    assert s2 < 0.5 * s1, (s1, s2)


# -- roulette and the black leak -------------------------------------------------------------------
def _lcd_chain(folder):
    """A backlight, two glass slabs (four refractions), an LCD of 300:1 (left half clear, right half
    black) and a diffuse screen 1 mm behind it, seen by the eye 300 mm away: a particle meets six
    surfaces, aimed twice (the backlight at the LCD, the screen at the pupil)."""
    folder.mkdir(parents=True)
    img = np.zeros((8, 64, 3), np.uint8)
    img[:, :32] = 255
    write_png(folder / "half.png", img)
    sb = SceneBuilder(folder, "lcd-chain", "backlight, slabs, LCD 300:1, screen")
    sb.add("backlight", rectangle(40.0, 20.0)[:2], {"type": "absorber"}, frame_matrix([0, 0, 0], [1, 0, 0], [0, 1, 0]),
           emission={"luminance": 1e4, "aim": {"target": "lcd", "share": 0.9}})
    for k, y in enumerate((20.0, 40.0)):
        sb.add(f"slab{k}", box(60.0, 5.0, 40.0), {"type": "dielectric", "ior": 1.5},
               frame_matrix([0, y, 0], [1, 0, 0], [0, 0, 1]))
    v, f, uv = rectangle(20.0, 10.0)
    sb.add("lcd", (v, f), {"type": "lcd", "image": "half.png", "transmittance": 0.5, "contrast_ratio": 300.0},
           frame_matrix([0, 69.0, 0], [1, 0, 0], [0, -1, 0]), uv=uv)
    sb.add("screen", rectangle(30.0, 20.0)[:2], {"type": "lambertian_transmitter", "transmittance": 0.8,
                                                 "aim": {"target": "eye", "share": 0.9}},
           frame_matrix([0, 70.0, 0], [1, 0, 0], [0, 1, 0]))
    return sb.write(eye={"position": [0, 370.0, 0], "gaze": [0, -1, 0], "up": [0, 0, 1], "pupil_diameter_mm": 4.0,
                         "accommodation_distance_mm": 300.0, "resolution": [24, 8], "fov_deg": [3.6, 1.2]},
                    methods={"forward": {"max_depth": 32}})


def _halves(y, var):
    """(clear, black) region means and standard errors: columns away from the blurred edge."""
    w = y.shape[1]
    clear, black = np.zeros(y.shape, bool), np.zeros(y.shape, bool)
    clear[:, 2:w // 2 - 3] = True
    black[:, w // 2 + 3:w - 2] = True
    # The image is flipped left-right: the eye looks back along -y, so the slide's left is on the right.
    (a, sa), (b, sb) = region_mean(y, var, clear), region_mean(y, var, black)
    return ((a, sa), (b, sb)) if a > b else ((b, sb), (a, sa))


def test_roulette_does_not_starve_the_black_leak(tmp_path):
    """Forward through six surfaces, with the one roulette rule: the black half reads 1/300 of the clear
    half within its error, its relative error is no worse than the clear half's (as many particles land
    there, each with 1/300 of the weight), and no worse than with roulette switched off. A rule that
    judged paths by their own weight would kill the black half's particles 300 times as often: the
    same check with the threshold raised 300,000-fold (a rule that starves the black half: its
    particles carry 1/300 of the weight and fall below the threshold first) fails."""
    world = World(load_scene(_lcd_chain(tmp_path / "s")))
    rays = 3_000_000
    y, var, res = run(world, "forward", rays, seed=8)
    (c, sc), (b, sb) = _halves(y, var)
    ratio, ratio_se = b / c, (b / c) * math.hypot(sb / b, sc / c)
    assert abs(ratio - 1 / 300) < z_bound(1) * ratio_se
    assert (sb / b) < 1.5 * (sc / c), ((sb / b), (sc / c))
    y0, var0, _ = run(world, "forward", rays, seed=8, reference=0.0)  # roulette off
    (_, _), (b0, sb0) = _halves(y0, var0)
    assert (sb / b) < 1.3 * (sb0 / b0)
    starving = res.extra["roulette"]["reference_luminance_cd_m2"] * 3e5
    ys, vs, _ = run(world, "forward", rays, seed=8, reference=starving)
    (cs, scs), (bs, sbs) = _halves(ys, vs)
    assert (sbs / bs) > 2.0 * (scs / cs)  # the check has the power to see starvation


def test_roulette_reference_comes_from_a_pilot_that_every_process_repeats(tmp_path, preset):
    folder = preset("analytic-mirror")
    a = INTEGRATORS["forward"](load_scene(folder), 3).reference_luminance
    b = INTEGRATORS["forward"](load_scene(folder), 3).reference_luminance
    assert a == b and a == pytest.approx(159.5, rel=0.1)
    edit_json(folder, lambda d: d["objects"][2]["emission"].update(luminance=0.0))
    assert INTEGRATORS["forward"](load_scene(folder), 3).reference_luminance == 0.0


# -- splitting at glass ----------------------------------------------------------------------------
def _plate(folder):
    """A 4.76 mm glass plate met at 67 deg (a windshield) reflecting a large Lambertian panel into the
    eye: the panel reads L (R + T^2 R / (1 - R^2)), the plate's incoherent reflectance (the symbol
    image and all its ghosts), for s and for p light, and the mean of the two for the panel's
    unpolarised light (s and p cross the plate as separate channels; tests/test_polarisation.py), with
    R the Fresnel reflectance at 67 deg (the field is 0.1 deg, over which R varies by 0.1 %)."""
    sb = SceneBuilder(folder, "plate", "a glass plate reflecting a panel")
    theta = math.radians(67.0)
    normal = [0.0, -math.cos(theta), math.sin(theta)]  # the eye looks along +y and meets the plate at 67 deg
    sb.add("plate", box(300.0, 300.0, 4.76), {"type": "dielectric", "ior": 1.52},
           frame_matrix([0.0, 200.0, 0.0], [1, 0, 0], normal))
    reflected = [0.0, 1.0 - 2 * normal[1] * normal[1], -2 * normal[1] * normal[2]]  # the gaze mirrored
    center = np.array([0.0, 200.0, 0.0]) + 150.0 * np.array(reflected)
    sb.add("panel", rectangle(40.0, 40.0)[:2], {"type": "absorber"},  # covers the images, stays above the plate
           frame_matrix(center, [1, 0, 0], -np.array(reflected)), emission={"luminance": 1000.0})
    return sb.write(eye={"position": [0.0, 0.0, 0.0], "gaze": [0, 1, 0], "up": [0, 0, 1], "pupil_diameter_mm": 4.0,
                         "accommodation_distance_mm": 350.0, "resolution": [4, 4], "fov_deg": [0.1, 0.1]})


def test_specular_splits_move_noise_not_answer(tmp_path):
    """Splitting at the plate's surfaces (methods.backward.splits) and choosing a branch by Fresnel
    probability estimate the same closed form; splitting removes the choice's noise (several times
    smaller error for the same rays)."""
    from tracer.optics.polar import amplitudes

    world = World(load_scene(_plate(tmp_path / "p")))
    rs, rp, _, _ = amplitudes(np.array([math.cos(math.radians(67.0))]), 1.52)
    expected = 1000.0 * np.mean([r + (1 - r) ** 2 * r / (1 - r * r) for r in (abs(rs[0]) ** 2, abs(rp[0]) ** 2)])
    se = {}
    for splits in (0, 3):
        opts = dict(world.scene.method_options("backward")) | {"splits": splits}
        res = INTEGRATORS["backward"](world, 3, options=opts).render(Budget(rays=400_000))
        y = res.film.rgb() @ Y_WEIGHTS
        m, se[splits] = region_mean(y, res.film.variance_y(), np.ones(y.shape, bool))
        assert abs(m - expected) < z_bound(2) * se[splits], (splits, m, expected, se[splits])
    assert se[3] < 0.3 * se[0]


def _tilted_plate(folder):
    """A glass plate seen over 40 deg of incidence angles (about 40 to 80 deg): most of the eye's rays
    split at its front face, those nearer normal incidence (smaller branch under SPLIT_MIN) sample a
    branch, in the same bounce; a panel above it is seen in reflection."""
    sb = SceneBuilder(folder, "tilted plate", "a glass plate met at 40-80 deg reflecting a panel")
    theta = math.radians(60.0)
    normal = np.array([0.0, -math.cos(theta), math.sin(theta)])
    sb.add("plate", box(900.0, 900.0, 5.0), {"type": "dielectric", "ior": 1.52},
           frame_matrix([0.0, 200.0, 0.0], [1, 0, 0], normal))
    reflected = np.array([0.0, 1.0, 0.0]) - 2 * normal[1] * normal
    sb.add("panel", rectangle(300.0, 300.0)[:2], {"type": "absorber"},
           frame_matrix(np.array([0.0, 200.0, 0.0]) + 250.0 * reflected, [1, 0, 0], -reflected),
           emission={"luminance": 1000.0})
    return sb.write(eye={"position": [0.0, 0.0, 0.0], "gaze": [0, 1, 0], "up": [0, 0, 1], "pupil_diameter_mm": 4.0,
                         "accommodation_distance_mm": 350.0, "resolution": [8, 8], "fov_deg": [40.0, 40.0]})


@pytest.mark.parametrize("method, module, constant", [
    ("backward", "tracer.methods.backward", "SAMPLE_UNSPLIT_ONLY"),
    ("forward", "tracer.optics.aimed", "EVAL_EVERY_RAY")])
def test_speed_shortcuts_leave_the_image_as_it_was(tmp_path, monkeypatch, method, module, constant):
    """The shortcuts of the path loop compute the same numbers by another route: sampling only the
    glass hits that do not split (backward, on a plate where a bounce has both), evaluating an aimed
    mixture's own law at every ray (forward, hud-direct's LEDs and scatterer). With each one off, a
    fixed-seed render gives the same image to rounding (numpy's vectorised exp may differ in the last
    bit at an array's tail), drawn from the same random stream."""
    import importlib

    folder = _tilted_plate(tmp_path / "p") if method == "backward" else PRESETS["hud-direct"].write(tmp_path / "s")
    world = World(load_scene(folder))
    images = []
    for share in (getattr(importlib.import_module(module), constant), 2.0):  # 2: never taken
        monkeypatch.setattr(importlib.import_module(module), constant, share)
        res = INTEGRATORS[method](world, 5).render(Budget(rays=300_000))
        images.append((res.rays, res.film.rgb()))
    (rays0, a), (rays1, b) = images
    assert rays0 == rays1
    assert np.abs(a).max() > 0
    np.testing.assert_allclose(a, b, rtol=1e-6, atol=1e-9 * np.abs(a).max())


def test_take_and_put_match_numpy_indexing():
    """tracer.core.vec.take and put give what fancy indexing along the last axis gives, for the tracer's
    indices (in range, -1 for the appended miss column), on planes of 1 to 3 dimensions."""
    from tracer.core.vec import put, take

    rng = np.random.default_rng(3)
    for shape in ((7,), (3, 7), (3, 2, 7)):
        a = rng.random(shape)
        idx = np.array([6, 0, -1, 3, 3, 5])
        np.testing.assert_array_equal(take(a, idx), a[..., idx])
        for where in (np.array([5, 1, 2]), slice(2, 5)):
            v = rng.random(a[..., where].shape)
            ours, theirs = a.copy(), a.copy()
            put(ours, where, v)
            theirs[..., where] = v
            np.testing.assert_array_equal(ours, theirs)
        ours = a.copy()
        put(ours, np.array([0, 4]), 2.5)  # a scalar broadcasts
        assert np.all(ours[..., [0, 4]] == 2.5)


def test_batches_travel_as_their_lit_pixels_and_merge_to_the_same_bits(tmp_path):
    """A forward batch lights a few thousand of hud-direct's 65,520 pixels: its film travels as those
    columns (tracer.core.film.Columns), and merging it gives every array of the dense merge, bit for bit
    (sums, per-component and per-group replicate sums and squares). A backward batch's connections
    light most pixels and travel whole; its paths that hit an LED, a few hundred, as columns."""
    import pickle

    from tracer.core.film import SPARSE_SHARE, Columns

    world = World(load_scene(PRESETS["hud-direct"].write(tmp_path / "s")))

    def dense(data):
        names, sums, norms, c_sum, c_sq, groups = data
        full = lambda a: a if not isinstance(a, Columns) else _scatter(a)  # noqa: E731
        return (names, [full(a) for a in sums], norms, [full(a) for a in c_sum], [full(a) for a in c_sq],
                {g: (full(s), full(q), *rest) for g, (s, q, *rest) in groups.items()})

    def _scatter(c):
        out = np.zeros(c.values.shape[:-1] + (world.eye.width * world.eye.height,))
        out[..., c.idx] = c.values
        return out

    def arrays_of(film):
        return ([film.sums[k] for k in film.kinds] + [film.comp_rep_sum[k] for k in film.kinds]
                + [film.comp_rep_sq[k] for k in film.kinds] + [a for g in film.groups.values() for a in (g.sum, g.sq)])

    for method, sparse in (("forward", {"light": True}), ("backward", {"hit": True, "connection": False})):
        integ = INTEGRATORS[method](world, 3)
        batches = [pickle.loads(pickle.dumps(integ.trace_batch(k))) for k in range(3)]  # as from a worker
        for b in batches:
            names, sums = b.film[0], b.film[1]
            assert {k: isinstance(a, Columns) for k, a in zip(names, sums, strict=True)} == sparse, method
            assert all(0 < len(a.idx) < SPARSE_SHARE * world.eye.width * world.eye.height
                       for a in sums if isinstance(a, Columns))
        a, b = integ.new_film(), integ.new_film()
        for batch in batches:
            a.merge_arrays(batch.film)
            b.merge_arrays(dense(batch.film))
        assert a.replicates == b.replicates > 0 and a.norm == b.norm
        for x, y in zip(arrays_of(a), arrays_of(b), strict=True):
            assert np.array_equal(x, y) and x.any(), method
