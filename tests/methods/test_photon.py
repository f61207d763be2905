"""The photon method (bidirectional tracing with visibility maps, paper sec. 4.1): closed forms, its bias
against the radius schedule, agreement with backward tracing, no double counting, and stability."""

from __future__ import annotations

import math

import numpy as np
import pytest

from presets._build import SceneBuilder, box, disk, frame_matrix, rectangle, sphere
from tests.support.stats import film_dof, t_bound, welch_dof
from tracer.core.units import Y_WEIGHTS
from tracer.methods import INTEGRATORS, Budget
from tracer.methods.photon import REPLICATES, PhotonGrid, radius_schedule
from tracer.scene import load_scene
from tracer.transport.path import PROBE_KEY
from tracer.transport.world import World

TAU = 0.5
PANEL_L, PANEL_R, PANEL_H = 1000.0, 200.0, 30.0


def run(world, method, rays, seed=3, batch_size=None, **changes):
    integ = INTEGRATORS[method](world, seed, batch_size, options=dict(world.scene.method_options(method)) | changes)
    res = integ.render(Budget(rays=rays))
    y = res.film.rgb() @ Y_WEIGHTS
    return float(y[0, 0]), math.sqrt(float(res.film.variance_y()[0, 0])), res


def _screen(folder, panel_radius=PANEL_R, panel_height=PANEL_H, luminance=PANEL_L, slab=False, facing=1.0):
    """A diffuse transmitter (tau = 0.5) in the plane z = 0, a Lambertian disk emitter under it facing
    up (``facing`` -1: away), seen from above through one pixel of 0.01 deg at its centre. ``slab``
    puts a glass slab under half of the screen (x > 0), between it and the emitter."""
    sb = SceneBuilder(folder, "screen", "a diffuse transmitter over a disk emitter")
    sb.add("screen", rectangle(300.0, 300.0)[:2], {"type": "lambertian_transmitter", "transmittance": TAU})
    sb.add("panel", disk(panel_radius, 256), {"type": "absorber"},
           frame_matrix([0, 0, -panel_height], [1, 0, 0], [0, 0, facing]), emission={"luminance": luminance})
    if slab:
        sb.add("slab", box(150.0, 300.0, 10.0), {"type": "dielectric", "ior": 1.5},
               frame_matrix([75.0, 0, -20.0], [1, 0, 0], [0, 0, 1]))
    return sb.write(eye={"position": [0.0, 0.0, 300.0], "gaze": [0.0, 0.0, -1.0], "up": [0, 1, 0],
                         "pupil_diameter_mm": 4.0, "accommodation_distance_mm": 300.0,
                         "resolution": [1, 1], "fov_deg": [0.01, 0.01]})


@pytest.mark.slow
def test_diffuse_transmitter_shows_tau_e_over_pi(tmp_path):
    """A Lambertian transmitter under illuminance E shows L = tau E / pi; a disk of radius a and
    luminance L_e at height h gives E = pi L_e a^2 / (a^2 + h^2) on its axis. Photons carrying all the
    light (no connections) and the default split (connections for the direct light) both read it,
    within their errors, to 1.5 % (the illuminance varies by 1e-4 over the gather radius). So does a
    backlight: the disk 1 mm under the screen, where connections alone read 3.3 +- 1.6 against 500
    (half the light comes from 1e-4 of the disk's area, right under the point; a hand-built scene):
    there the surface's own samples, weighted against the connections, carry it."""
    for name, (a, h), changes, batch, rays in (("photons", (PANEL_R, PANEL_H), {"next_event": False, "radius_mm": 10.0},
                                                None, 20_000_000),
                                               ("connections", (100.0, 50.0), {}, 1024, 6_000_000),
                                               ("backlight", (100.0, 1.0), {}, 4096, 4_000_000)):
        world = World(load_scene(_screen(tmp_path / name, panel_radius=a, panel_height=h)))
        expected = TAU * PANEL_L * a * a / (a * a + h * h)
        m, se, res = run(world, "photon", rays, batch_size=batch, **changes)
        bound = t_bound(3, film_dof(res.film))
        assert abs(m - expected) < bound * se and se < 0.015 * expected, (name, m, se, expected)
        shares = res.extra["component_shares"]
        assert shares["photon" if changes else "connection"] == pytest.approx(1.0), shares


@pytest.mark.slow
def test_bias_follows_the_radius_schedule_and_falls(tmp_path):
    """Under a small Lambertian source of intensity I_0 at height h the illuminance is E(rho) = I_0 h^2 /
    (h^2 + rho^2)^2, whose mean over a disk of radius r is I_0 / (h^2 + r^2): below the peak I_0 / h^2.
    Photon density estimation has exactly that bias at radius r, and the radius shrinks with the batch
    index, so the render equals the mean over its batches of tau E_r / pi, and more photons come
    clearly closer to the true value."""
    h, a, lum = 20.0, 0.5, 1e6
    world = World(load_scene(_screen(tmp_path / "p", panel_radius=a, panel_height=h, luminance=lum)))
    i0 = lum * math.pi * a * a
    exact = TAU / math.pi * math.pi * lum * a * a / (a * a + h * h)
    out = []
    for rays in (1_500_000, 12_000_000):
        m, se, res = run(world, "photon", rays, next_event=False, radius_mm=8.0)
        r = radius_schedule(8.0, 2.0 / 3.0, np.arange(res.batches))
        predicted = float(np.mean(TAU / math.pi * i0 / (h * h + r * r)))
        assert abs(m - predicted) < t_bound(4, film_dof(res.film)) * se, (rays, m, predicted, se)
        out.append((m, se, exact - predicted, film_dof(res.film)))
    (m1, s1, b1, f1), (m2, s2, b2, f2) = out
    assert b2 < 0.7 * b1  # the predicted bias falls ...
    bound = t_bound(4, welch_dof((s1 * s1, f1), (s2 * s2, f2)))
    assert m2 - m1 > bound * math.hypot(s1, s2)  # ... and the renders show it
    assert exact - m2 < exact - m1


@pytest.mark.slow
def test_no_light_path_is_counted_twice(tmp_path):
    """Half of the screen sees the emitter through a glass slab: there connections are blocked and
    photons carry the light; elsewhere connections carry it and photons (stored only after their first
    event) carry only what the slab reflects back. The photon method, with and without connections,
    equals backward tracing with next-event estimation (which finds the light through glass by its own
    hits) within errors, and both components are at work."""
    folder = _screen(tmp_path / "g", panel_radius=100.0, panel_height=50.0, slab=True)
    world = World(load_scene(folder))
    ref, s_ref, res_ref = run(world, "backward", 3_000_000)
    # Small batches: many eye samples (two per batch), so that the connections' estimate, whose
    # distribution has a long tail under a large emitter, is measured by enough replicates.
    for changes in ({}, {"next_event": False}):
        m, se, res = run(world, "photon", 8_000_000, batch_size=8192, radius_mm=2.0, **changes)
        bound = t_bound(2, welch_dof((se * se, film_dof(res.film)), (s_ref * s_ref, film_dof(res_ref.film))))
        assert abs(m - ref) < bound * math.hypot(se, s_ref), (changes, m, se, ref, s_ref)
        shares = res.extra["component_shares"]
        if not changes:
            assert 0.2 < shares["photon"] < 0.8 and 0.2 < shares["connection"] < 0.8, shares


def test_grid_finds_exactly_the_photons_within_the_radius():
    """The hash grid's pairs equal a brute-force search, with photons on exact cell edges, at exactly the
    radius, on other objects, in other replicates and with other normals among them."""
    rng = np.random.default_rng(5)
    r = 0.5
    lattice = np.stack(np.meshgrid(*[np.arange(-2, 3) * 2 * r] * 2, indexing="ij"), 0).reshape(2, -1)
    p = np.concatenate([rng.uniform(-2, 2, (3, 400)), np.vstack([lattice, np.zeros(lattice.shape[1])])], axis=1)
    x = np.concatenate([rng.uniform(-2, 2, (3, 100)), [[0.0, r, 2 * r], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]]], axis=1)
    n_p, n_x = p.shape[1], x.shape[1]
    slot_p, rep_p = rng.integers(0, 2, n_p), rng.integers(0, 2, n_p)
    slot_x, rep_x = rng.integers(0, 2, n_x), rng.integers(0, 2, n_x)
    slot_x[-3:], rep_x[-3:] = slot_p[-1], rep_p[-1]
    ng_p = np.tile([[0.0], [0.0], [1.0]], n_p)
    ng_p[:, ::7] = [[1.0], [0.0], [0.0]]  # some photons on a perpendicular surface
    ng_x = np.tile([[0.0], [0.0], [1.0]], n_x)
    grid = PhotonGrid(p, np.zeros((3, n_p)), np.ones((3, n_p)), slot_p, ng_p, rep_p, r)
    pt, ph = grid.pairs(x, ng_x, slot_x, rep_x, *grid.candidates(x, rep_x))
    # the grid keeps its photons in its own order: compare them by position (all distinct here)
    found = {(int(i), tuple(np.round(grid.p[:, j], 12))) for i, j in zip(pt, ph, strict=True)}
    expected = set()
    for i in range(n_x):
        for j in range(n_p):
            dd = p[:, j] - x[:, i]
            if (dd @ dd <= r * r and slot_p[j] == slot_x[i] and rep_p[j] == rep_x[i]
                    and ng_p[:, j] @ ng_x[:, i] >= 0.7):
                expected.add((i, tuple(np.round(p[:, j], 12))))
    assert found == expected and len(expected) > 50
    assert len(pt) == len(found)  # no photon counted twice


def test_radius_schedule_is_knaus_zwicker():
    """r_(k+1)^2 / r_k^2 = (k + 1 + alpha) / (k + 2) (Knaus and Zwicker 2011, eq. 15), r_0 at batch 0, and
    the radius falls as k^((alpha - 1) / 2)."""
    r = radius_schedule(2.0, 0.7, np.arange(2000))
    assert r[0] == pytest.approx(2.0)
    k = np.arange(1999)
    assert np.allclose((r[1:] / r[:-1]) ** 2, (k + 1 + 0.7) / (k + 2), rtol=1e-12)
    slope = np.polyfit(np.log(np.arange(1000, 2000)), np.log(r[1000:]), 1)[0]
    assert slope == pytest.approx(-0.15, abs=0.01)
    assert np.all(radius_schedule(2.0, 1.0, np.arange(10)) == 2.0)


def test_stability_where_the_method_cannot_work(tmp_path):
    """Never NaN or Inf, never a silent black: no scattering surface in view (a mirror shows the
    emitter) says so with the efficiency; a screen that no photon reaches (the emitter faces away) says
    so; a radius of 1e-9 mm gathers nothing and stays finite."""
    sb = SceneBuilder(tmp_path / "m", "mirror", "an emitter seen in a mirror")
    sb.add("mirror", rectangle(300.0, 300.0)[:2], {"type": "mirror", "reflectance": 0.9})
    sb.add("panel", disk(50.0, 64), {"type": "absorber"}, frame_matrix([0, 0, 100.0], [1, 0, 0], [0, 0, -1]),
           emission={"luminance": 100.0})
    folder = sb.write(eye={"position": [0.0, 0.0, 50.0], "gaze": [0.0, 0.0, -1.0], "up": [0, 1, 0],
                           "pupil_diameter_mm": 4.0, "accommodation_distance_mm": 150.0,
                           "resolution": [4, 4], "fov_deg": [2.0, 2.0]})
    world = World(load_scene(folder))
    integ = INTEGRATORS["photon"](world, 1)
    res = integ.render(Budget(rays=300_000))
    y = res.film.rgb() @ Y_WEIGHTS
    assert np.all(np.isfinite(y)) and y.mean() == pytest.approx(90.0, rel=0.01)  # R L through the mirror
    assert any("no eye path reached a scattering" in w and "efficiency" in w for w in res.warnings)

    dark = World(load_scene(_screen(tmp_path / "d", facing=-1.0)))
    m, se, res = run(dark, "photon", 400_000)
    assert m == 0.0 and any("no photon reached a scattering surface" in w for w in res.warnings)
    assert any("no light path found" in w for w in res.warnings)

    lit = World(load_scene(_screen(tmp_path / "t")))
    m, se, res = run(lit, "photon", 400_000, next_event=False, radius_mm=1e-9)
    assert np.isfinite(m) and np.isfinite(se) and m >= 0.0
    assert res.extra["photon"]["final_radius_mm"] > 0


@pytest.mark.slow
def test_paths_cut_at_max_depth_are_named_as_the_cause(tmp_path):
    """hud-direct with methods.photon.max_depth = 3: no eye path gets past the windshield and mirror to
    the scatterer. The warnings name max_depth as the cause of the cut eye paths (whose light is not
    measured: they never reached a visibility point), not the scene (\"use the forward or backward
    method\"); the photon paths cut there are probed, and with no visibility point to gather their
    photons they add nothing, so nothing is said of them. At the default depth nothing is cut and
    nothing is said."""
    from presets import PRESETS

    folder = PRESETS["hud-direct"].write(tmp_path / "s", resolution=(32, 16))
    scene = load_scene(folder)
    options = dict(scene.method_options("photon")) | {"max_depth": 3}
    shallow = INTEGRATORS["photon"](scene, 1, options=options).render(Budget(rays=400_000))
    said = " ".join(shallow.warnings)
    assert "eye paths (from 1,024 samples, split at glass) were cut at methods.photon.max_depth = 3" in said, said
    assert "raise max_depth" in said, said
    assert "the eye paths were cut at methods.photon.max_depth = 3 before any reached one" in said, said
    assert "use the forward or backward method" not in said
    cut = shallow.extra["max_depth_cut"]
    assert cut["paths"] == shallow.extra["photon"]["photon_paths_cut_at_max_depth"] > 0, cut
    assert cut["missing_luminance_cd_m2"] == 0.0 and "photon paths were cut" not in said, (cut, said)
    deep = INTEGRATORS["photon"](load_scene(folder), 1).render(Budget(rays=400_000))
    assert deep.extra["photon"]["eye_paths_cut_at_max_depth"] == 0 and not any("cut" in w for w in deep.warnings)


def _room(folder, rho: float, luminance: float = 10.0):
    """The eye at the centre of a closed sphere (radius 500 mm) whose inside is Lambertian of reflectance
    ``rho`` and emits ``luminance``: a scattering furnace, L = luminance (1 + rho + rho^2 + ...) in
    every direction, where light bounce k (k reflections) brings luminance rho^k."""
    sb = SceneBuilder(folder, "room", "a closed Lambertian room that glows")
    sb.add("wall", sphere(500.0, subdivisions=3, inward=True), {"type": "lambertian", "reflectance": [rho] * 3},
           emission={"luminance": luminance})
    return sb.write(eye={"position": [0.0, 0.0, 0.0], "gaze": [0, 1, 0], "up": [0, 0, 1], "pupil_diameter_mm": 4.0,
                         "resolution": [4, 4], "fov_deg": [10.0, 10.0]})


@pytest.mark.slow
def test_photon_paths_end_by_roulette_and_cut_ones_are_measured(tmp_path):
    """Photons never leave a closed room, so without a roulette every photon path ran to max_depth and
    the warning blamed max_depth whatever the light cut there was worth (a hand-built scene). In a
    room of reflectance 0.5 the path loop's roulette ends them: under 0.1 % reach the default depth,
    and the image reads the furnace's L_e / (1 - rho). With max_depth 4 in a room of 0.8, the image
    holds bounces 0 to 4, L_e (1 - rho^5) / (1 - rho), the probe's photons (the cut paths followed
    16 segments further) gather the next sixteen, L_e rho^5 (1 - rho^16) / (1 - rho), each batch an
    unbiased estimate of it, and the warning gives that figure as a lower bound."""
    lum = 10.0
    bound = lambda dof: t_bound(3, dof)  # noqa: E731  (three comparisons in this test)
    res = INTEGRATORS["photon"](load_scene(_room(tmp_path / "half", 0.5, lum)), 3, 8192).render(Budget(rays=2_000_000))
    mean, se = float(res.film.rgb().mean(axis=(0, 1)) @ Y_WEIGHTS), res.film.mean_standard_error()
    assert abs(mean - lum / 0.5) < bound(film_dof(res.film)) * se, (mean, se)
    photon = res.extra["photon"]
    assert photon["photon_paths_cut_at_max_depth"] < 1e-3 * photon["photons_emitted"], photon
    assert not any("cut at" in w for w in res.warnings), res.warnings

    rho, depth = 0.8, 4
    world = World(load_scene(_room(tmp_path / "bright", rho, lum)))
    options = dict(world.scene.method_options("photon")) | {"max_depth": depth}
    integ = INTEGRATORS["photon"](world, 3, 8192, options=options)
    res = integ.render(Budget(rays=1_000_000))
    mean, se = float(res.film.rgb().mean(axis=(0, 1)) @ Y_WEIGHTS), res.film.mean_standard_error()
    assert abs(mean - lum * (1 - rho ** (depth + 1)) / (1 - rho)) < bound(film_dof(res.film)) * se, (mean, se)
    cut = res.extra["max_depth_cut"]
    assert cut["paths"] == res.extra["photon"]["photons_emitted"] and cut["missing_is_lower_bound"], cut
    assert any(w.startswith(f"{cut['paths']:,} photon paths were cut at methods.photon.max_depth = 4") and
               "add at least" in w for w in res.warnings), res.warnings
    per_pixel = REPLICATES * world.eye.width * world.eye.height  # the photon component's samples in a batch
    missing = np.array([integ.trace_batch(k).extra[f"{PROBE_KEY}:photon"] / per_pixel for k in range(24)])
    expected = lum * rho ** (depth + 1) * (1 - rho ** 16) / (1 - rho)
    se = missing.std(ddof=1) / math.sqrt(len(missing))
    assert abs(missing.mean() - expected) < bound(len(missing) - 1) * se and se < 0.03 * expected, (missing, expected)


@pytest.mark.slow
def test_a_scene_of_glass_alone_is_not_blamed_on_max_depth(tmp_path):
    """A glass block against a uniform sky, no scattering surface anywhere: some eye paths are trapped in
    the block and cut, and the warning said they were cut "before any reached one [a scattering
    surface]: raise it", where there is none to reach (a hand-built scene). It says what the image
    holds, and names the backward method."""
    sb = SceneBuilder(tmp_path / "g", "glass", "a glass block in a uniform sky")
    sb.add("block", box(40.0, 40.0, 40.0), {"type": "dielectric", "ior": 1.5}, frame_matrix([0, 100.0, 0], [1, 0, 0],
                                                                                           [0.3, -1, 0.2]))
    folder = sb.write(environment={"type": "uniform", "luminance": 1000.0},
                      eye={"position": [0.0, 0.0, 0.0], "gaze": [0, 1, 0], "up": [0, 0, 1], "pupil_diameter_mm": 4.0,
                           "resolution": [8, 8], "fov_deg": [20.0, 20.0]})
    scene = load_scene(folder)
    options = dict(scene.method_options("photon")) | {"max_depth": 4}
    said = " ".join(INTEGRATORS["photon"](scene, 1, options=options).render(Budget(rays=200_000)).warnings)
    assert "no eye path reached a scattering (non-specular) surface" in said and "backward method" in said, said
    assert "before any reached one" not in said, said


@pytest.mark.slow
def test_batches_merge_exactly_across_processes(tmp_path):
    """Batches are independent replicates addressed by seed: two worker processes give the image of one
    process bit for bit."""
    from tracer.runtime.parallel import render_parallel

    folder = _screen(tmp_path / "s", slab=True)
    one = INTEGRATORS["photon"](load_scene(folder), 9).render(Budget(rays=1_500_000))
    two = render_parallel(INTEGRATORS["photon"](load_scene(folder), 9), Budget(rays=1_500_000), workers=2)
    assert one.batches == two.batches and np.array_equal(one.film.rgb(), two.film.rgb())


@pytest.mark.slow
def test_a_given_radius_far_beyond_the_automatic_one_is_warned_of_before_the_pilot(tmp_path):
    """radius_mm = 10 on hud-screen (107 pixel footprints on its screen) made every visibility point gather
    4,487 photons: a render of 200,000 rays took 500 s and a stop waited minutes for the running batch,
    with no word (a hand-built input). A radius beyond twice the widest automatic one (24 footprints)
    is warned of before the pilot, through the render's notice and in its warnings; the automatic
    radius and a moderate one are not."""
    from presets import PRESETS

    folder = PRESETS["hud-screen"].write(tmp_path / "s")
    for radius, warned in ((0.0, False), (1.0, False), (10.0, True)):
        scene = load_scene(folder)
        integ = INTEGRATORS["photon"](scene, 1, options=dict(scene.method_options("photon")) | {"radius_mm": radius})
        heard = []
        integ.notice = heard.append
        if radius:
            integ._check_given_radius(np.random.default_rng(1))
        else:
            integ.reference_luminance  # noqa: B018  (the pilot, which measures the automatic radius)
        said = [w for w in integ.warnings if w.startswith(f"methods.photon.radius_mm = {radius:g} is ")]
        assert (len(said) == 1) == warned and heard == said, (radius, integ.warnings, heard)
        if warned:
            footprints = float(said[0].split(" is ")[1].split(" pixel")[0])
            assert 90 < footprints < 130, said


def _retina(folder, resolution, fov_deg):
    """The scene of ``folder`` with the eye's retina set to ``resolution`` over ``fov_deg``."""
    import json

    raw = json.loads((folder / "scene.json").read_text())
    raw["eye"]["resolution"], raw["eye"]["fov_deg"] = list(resolution), list(fov_deg)
    (folder / "scene.json").write_text(json.dumps(raw))
    return folder


def test_a_short_budget_on_a_large_retina_cuts_a_pass_into_batches(tmp_path):
    """Issue 31: a photon batch was its photons and two passes over every pixel, so `--seconds 2` at
    1920 x 1080 took 36 s (auto 150 s). For a time budget whose share a whole batch would overrun,
    a batch now covers part of one pass (one sample per pixel of its part) with its photons cut in the
    same proportion; a budget in rays, or a small retina, keeps whole batches."""
    from tracer.methods.base import DEFAULT_BATCH, MIN_BATCH

    folder = _retina(_screen(tmp_path / "s"), (1920, 1080), (2.0, 1.125))
    short = INTEGRATORS["photon"](World(load_scene(folder)), 1)
    short.fit_batch(Budget(seconds=0.5))
    npix = 1920 * 1080
    assert MIN_BATCH <= short.eye_batch < npix and MIN_BATCH <= short.batch_size < DEFAULT_BATCH
    assert short.worker_options()["_eye_batch"] == short.eye_batch
    rays = INTEGRATORS["photon"](World(load_scene(folder)), 1)
    rays.fit_batch(Budget(rays=10**9))
    assert rays.eye_batch is None and rays.batch_size == DEFAULT_BATCH


@pytest.mark.slow
def test_batches_of_part_of_a_pass_read_the_closed_form_and_merge_exactly(tmp_path):
    """Batches of 64 eye samples over a 16 x 16 retina at the screen's centre (each pixel a replicate
    of its own samples): the image reads tau E / pi within its error bars (alpha 0.01, Sidak over the
    pixels' mean), and two worker processes give the image of one bit for bit."""
    from tracer.runtime.parallel import render_parallel

    folder = _retina(_screen(tmp_path / "s"), (16, 16), (0.5, 0.5))
    world = World(load_scene(folder))
    opts = dict(world.scene.method_options("photon")) | {"_eye_batch": 64}
    one = INTEGRATORS["photon"](world, 5, 4096, opts).render(Budget(rays=3_000_000))
    film = one.film
    counts = film.sample_counts()
    assert counts is not None and counts.min() >= 2 and one.batches > 4 * 256 // 64
    y = film.rgb() @ Y_WEIGHTS
    mean, se = float(y.mean()), math.sqrt(float(film.variance_y().sum())) / y.size
    expected = TAU * PANEL_L * PANEL_R**2 / (PANEL_R**2 + PANEL_H**2)
    assert abs(mean - expected) < t_bound(1, int(counts.min()) - 1) * se and se < 0.03 * expected, (mean, se)
    two = render_parallel(INTEGRATORS["photon"](World(load_scene(folder)), 5, 4096, opts), Budget(rays=3_000_000),
                          workers=2)
    assert one.batches == two.batches and np.array_equal(one.film.rgb(), two.film.rgb())
