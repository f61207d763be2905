"""The automatic choice of a method by pilots (``auto``; tracer/methods/pilots.py): the score of a pilot
ranks the pixels of the combined image and takes the worst stratum, and longer renders confirm the choice."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tests.support.scenes import LOW
from tracer.core.units import luminance
from tracer.methods import INTEGRATORS, Budget
from tracer.methods.pilots import PILOT_FLOOR_SECONDS, applicable, combined_image, relative_variances, rule_choice
from tracer.scene import load_scene


def _efficiency_of(method: str, folder, seed: int, rays: int) -> tuple[float, np.ndarray, np.ndarray]:
    res = INTEGRATORS[method](load_scene(folder), seed).render(Budget(rays=rays))
    return res.rays, luminance(res.film.rgb()), res.film.variance_y()


@pytest.mark.slow
@pytest.mark.parametrize("name,expected", [("hud-direct", "backward"), ("hud-direct-condenser", "photon"),
                                           ("hud-screen", "photon")])
def test_auto_picks_on_its_pilots_the_method_a_longer_run_confirms(preset, name, expected):
    """auto chooses by short pilots; renders of every applicable method twice as long as the longest pilot,
    side by side, scored the same way (the median relative variance of the pixels any of them lit, times the
    rays), confirm the choice: backward with next-event estimation where the scatterer sees the LEDs
    (hud-direct), photon maps where a lens stands between them (the condenser, the projection lens). The
    scores differ by 100 times or more (2026-12-07: 4.8e3 against 1.6e6 on hud-direct, 1.0e5 against 1.3e7
    on hud-screen; the others found no light or too little for a variance), so twice is plenty."""
    folder = preset(name, resolution=LOW)
    auto = INTEGRATORS["auto"](load_scene(folder), 2).render(Budget(rays=6_000_000))
    scene = auto.extra["channels"]["scene"]
    assert scene["sources"] == ["emitters"]  # these scenes' environments are black: not a source
    chosen = scene["method"]
    ran = [p for p in scene["pilots"] if p["skipped"] is None]
    longest = max(p["rays"] for p in ran)
    longer = {p["method"]: _efficiency_of(p["method"], folder, 11, 2 * longest) for p in ran}
    methods = list(longer)
    images = [longer[m][1] for m in methods]
    variances = [longer[m][2] for m in methods]
    score = {m: max(relative_variances(images, variances, k).values()) * longer[m][0] for k, m in enumerate(methods)}
    confirmed = min(score, key=score.get)
    assert chosen == confirmed == expected, (chosen, score)
    world = INTEGRATORS["auto"](load_scene(folder), 2).world
    assert rule_choice(applicable(world, lights=True, environment=True))[0] == expected  # what short budgets get


@pytest.mark.slow
@pytest.mark.parametrize("name,expected", [("hud-direct", "backward"), ("hud-screen", "photon")])
def test_a_short_time_budget_chooses_by_the_rules_without_pilots(preset, name, expected):
    """With a time budget whose pilot share is under PILOT_FLOOR_SECONDS, auto runs no pilot (they took 9 s
    of a 2 s budget on hud-screen, leaving the render 0.2 s) and takes the rules' method, the one the pilots
    and longer renders confirm on these presets (above); a longer budget still pilots."""
    folder = preset(name, resolution=LOW)
    integ = INTEGRATORS["auto"](load_scene(folder), 2)
    integ.prepare(Budget(seconds=0.9 * PILOT_FLOOR_SECONDS / float(integ.opts["pilot_share"])))
    (channel,) = integ.channels
    assert channel.chosen == expected and channel.chosen_by.startswith("rules: "), channel.chosen_by
    assert all(p.skipped is not None and p.seconds == 0 for p in channel.pilots), channel.pilots
    assert integ._resolved["scene"]["method"] == expected  # what the workers build
    longer = INTEGRATORS["auto"](load_scene(folder), 2)
    longer.prepare(Budget(seconds=1.1 * PILOT_FLOOR_SECONDS / float(longer.opts["pilot_share"])))
    assert longer.channels[0].chosen_by == "pilots"


def test_the_score_ranks_pixels_in_the_combined_image_and_takes_the_worst_stratum():
    """Two pilots of 100 pixels, 94 at 1 cd/m^2 and a spot of 6 at 100: pilot A is nearly exact on the
    94 and dark on the spot, pilot B lights everything with a relative variance of 1e-2. The combined
    image takes the spot from B alone (a dark pixel carries no weight) and the rest mostly from A; the
    spot falls into the brightest tenth and hundredth (8 pixels, the smallest stratum), where A's
    median is infinite, so A's V is infinite although its lit pixels' median is 1e-6."""
    truth = np.ones(100)
    truth[[3, 17, 42, 55, 68, 91]] = 100.0
    a = np.where(truth > 1, 0.0, truth)
    images, variances = [a, truth.copy()], [1e-6 * a * a, 1e-2 * truth * truth]
    both = combined_image(images, variances)
    np.testing.assert_allclose(both, truth, rtol=1e-12)
    va, vb = relative_variances(images, variances, 0), relative_variances(images, variances, 1)
    assert va["lit"] == pytest.approx(1e-6) and va["brightest_half"] == pytest.approx(1e-6)
    assert va["brightest_tenth"] == math.inf and va["brightest_hundredth"] == math.inf
    assert all(v == pytest.approx(1e-2) for v in vb.values())
    assert relative_variances([np.zeros(4)], [np.zeros(4)], 0) is None


def _lens_spot(folder):
    """A 2 mm LED 60 mm below a glass lens (f = 51 mm) that focuses part of its light into a spot on a
    white screen 90 mm above the lens; the rest of the screen sees the LED directly. The eye looks at
    the screen from the side, past the lens."""
    from presets._build import SceneBuilder, frame_matrix, lens, rectangle

    sb = SceneBuilder(folder, "lens-spot", "LED, lens, screen: a focused spot beside direct light")
    up = [0, 0, 1]
    sb.add("led", rectangle(2, 2)[:2], {"type": "absorber"}, frame_matrix([0, 0, 0], [1, 0, 0], up),
           emission={"luminance": 1e6})
    sb.add("lens", lens(50, 50, 8, 15), {"type": "dielectric", "ior": 1.5}, frame_matrix([0, 0, 60], [1, 0, 0], up),
           smooth=True)
    sb.add("screen", rectangle(200, 200)[:2], {"type": "lambertian", "reflectance": 0.8,
                                               "aim": {"target": "eye", "share": 0.5}},
           frame_matrix([0, 0, 150], [1, 0, 0], [0, 0, -1]))
    pos = np.array([150.0, 0.0, 100.0])
    gaze = np.array([0.0, 0.0, 150.0]) - pos
    return sb.write(eye={"position": pos.tolist(), "gaze": (gaze / np.linalg.norm(gaze)).tolist(), "up": up,
                         "pupil_diameter_mm": 4.0, "focal_length_mm": 16.67,
                         "accommodation_distance_mm": float(np.linalg.norm(gaze)), "resolution": [32, 32],
                         "fov_deg": [14, 14]})


def _auto_on_lens_spot(folder, rays: int):
    """auto on :func:`_lens_spot`: (the method chosen, the pilots that ran by method)."""
    scene = INTEGRATORS["auto"](load_scene(folder), 2).render(Budget(rays=rays)).extra["channels"]["scene"]
    return scene["method"], {p["method"]: p for p in scene["pilots"] if p["skipped"] is None}


@pytest.mark.slow
@pytest.mark.parametrize("rays", [4_000_000, 16_000_000])
def test_auto_judges_the_brightest_pixels_too_not_only_the_typical_one(tmp_path, rays):
    """A lens focuses a small LED into a spot on a screen that the LED also lights directly. Backward
    tracing with next-event estimation gets the directly lit pixels, most of the image, almost
    noise-free, but reaches the spot only by chance through the lens: by the median of the lit pixels
    alone its pilot looks best (the rule before). auto also judges the brightest tenth and hundredth of
    the lit pixels and picks another method, whatever the pilots' length."""
    chosen, ran = _auto_on_lens_spot(_lens_spot(tmp_path / "lens-spot"), rays)
    assert set(ran) == {"backward", "forward", "photon"}
    lit_only = {m: 1.0 / (p["relative_variance_medians"]["lit"] * p["cost"]) for m, p in ran.items()}
    assert max(lit_only, key=lit_only.get) == "backward"
    assert chosen != "backward"


@pytest.mark.slow
def test_longer_renders_confirm_the_choice_on_the_lens_spot(tmp_path):
    """Renders of every method four times as long as the longest pilot, at equal rays, confirm auto's
    choice on :func:`_lens_spot` by the same score, and backward's error of the spot's mean luminance
    (the pixels above a tenth of the 99th percentile, as benchmarks/convergence.py defines the bright
    region) is more than ten times the chosen method's: the rule before would have cost that."""
    folder = _lens_spot(tmp_path / "lens-spot")
    chosen, ran = _auto_on_lens_spot(folder, 4_000_000)
    longer = {m: _efficiency_of(m, folder, 11, 4 * max(p["rays"] for p in ran.values())) for m in ran}
    methods = list(longer)
    images, variances = [longer[m][1] for m in methods], [longer[m][2] for m in methods]
    score = {m: max(relative_variances(images, variances, k).values()) * longer[m][0] for k, m in enumerate(methods)}
    assert min(score, key=score.get) == chosen, score
    both = combined_image(images, variances)
    spot = both > 0.1 * np.percentile(both, 99)
    assert 0.01 * spot.size < spot.sum() < 0.2 * spot.size
    error = {m: math.sqrt(var[spot].sum() * rays_m) / y[spot].sum() for m, (rays_m, y, var) in longer.items()}
    assert error["backward"] > 10 * error[chosen], error  # 22 times on this seed


def test_pilots_of_a_large_retina_run_on_a_coarser_one_of_the_same_field(tmp_path):
    """Issue 31: auto's pilots traced whole passes over the retina (150 s for `--seconds 2` at 1920 x
    1080 on hud-screen). Above PILOT_PIXELS they run on a retina of the same field of view with at most
    that many pixels, its aspect kept; a preset's own retina is piloted as it is."""
    import dataclasses

    from presets import PRESETS
    from tracer.methods.pilots import PILOT_PIXELS, pilot_world
    from tracer.transport.world import World

    world = World(load_scene(PRESETS["hud-screen"].write(tmp_path / "s")))
    assert pilot_world(world) is world
    large = world.with_eye(dataclasses.replace(world.eye.spec, resolution=(1920, 1080)))
    coarse = pilot_world(large).eye
    assert coarse.width * coarse.height <= PILOT_PIXELS and (coarse.width, coarse.height) == (341, 192)
    assert np.array_equal(coarse.spec.fov_deg, large.eye.spec.fov_deg)
    assert np.array_equal(coarse.spec.position, large.eye.spec.position)


@pytest.mark.slow
def test_the_survey_behind_applicable_is_made_once_per_scene_and_eye(preset, tmp_path, monkeypatch):
    """auto and hybrid ask on every render whether a specular object blocks the emitters' light to a
    scattering surface in view (a chief-ray survey through the brightness theorem's chains, which at 4K
    took most of a 2 s budget); F12 after F12 in Blender asked again. The answer is kept by the world's
    key now: the same scene loaded from another folder gets it without a survey; another scene makes
    its own."""
    import shutil

    from tracer.methods import pilots
    from tracer.transport.world import World

    pilots.KEPT_BLOCKED.clear()
    surveys = []
    survey = pilots.specular_paths
    monkeypatch.setattr(pilots, "specular_paths", lambda *a, **k: surveys.append(1) or survey(*a, **k))
    screen = preset("hud-screen")
    copy = shutil.copytree(screen, tmp_path / "copy")
    first = applicable(World(load_scene(screen)), lights=True, environment=False)
    again = applicable(World(load_scene(copy)), lights=True, environment=False)
    assert first == again and first["photon"] is None and len(surveys) == 1
    direct = applicable(World(load_scene(preset("hud-direct"))), lights=True, environment=False)
    assert len(surveys) == 2
    pilots.KEPT_BLOCKED.clear()
    assert applicable(World(load_scene(preset("hud-direct"))), lights=True, environment=False) == direct
