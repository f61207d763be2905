"""The hybrid method (tracer/methods/hybrid.py): its image is the sum of its channels and agrees with
backward tracing, the same on one and two processes; channels and methods the scene does not need are
skipped with the reason."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tests.support.render import films_match
from tests.support.scenes import LOW, edit_json, sky
from tests.support.stats import film_dof, t_bound, welch_dof
from tracer.core.units import luminance
from tracer.methods import INTEGRATORS, Budget
from tracer.methods.pilots import applicable
from tracer.runtime.parallel import render_parallel
from tracer.scene import load_scene
from tracer.transport.world import World


def _block_pixels(a: np.ndarray, shape=(4, 8)) -> np.ndarray:
    """The pixels of ``a`` (H, W) as (blocks, pixels per block), the blocks of a shape[0] x shape[1] grid
    in row-major order (the rows and columns left over by the grid are dropped)."""
    h, w = a.shape
    by, bx = h // shape[0], w // shape[1]
    return a[: by * shape[0], : bx * shape[1]].reshape(shape[0], by, shape[1], bx).transpose(0, 2, 1, 3) \
        .reshape(shape[0] * shape[1], by * bx)


def _blocks(y: np.ndarray, var: np.ndarray, shape=(4, 8)):
    """Means of Y over a grid of blocks and their standard errors (independent pixels)."""
    yb, vb = _block_pixels(y, shape), _block_pixels(var, shape)
    return yb.mean(axis=1), np.sqrt(vb.sum(axis=1)) / yb.shape[1]


def _block_dof(parts, shape=(4, 8)):
    """Welch-Satterthwaite degrees of freedom of each block's variance (the blocks of :func:`_blocks`),
    a sum of independent per-pixel variances given as (var (H, W), its degrees of freedom) parts."""
    split = [(_block_pixels(v, shape), dof) for v, dof in parts]
    return np.array([welch_dof(*((b[k], dof) for b, dof in split)) for k in range(len(split[0][0]))])


@pytest.mark.slow
def test_hybrid_is_the_sum_of_its_channels_and_agrees_with_backward(preset):
    """hud-direct against a 1000 cd/m^2 sky: the hybrid's image is the sum of its two channels (and
    their variances add), and it agrees block by block with backward tracing of the whole scene at
    once, a method that converges for every path here: nothing is counted twice, nothing lost."""
    folder = preset("hud-direct", resolution=LOW)
    sky(folder)
    hybrid = INTEGRATORS["hybrid"](load_scene(folder), 3).render(Budget(rays=10_000_000))
    film = hybrid.film
    assert set(film.groups) == {"hud", "environment"}
    np.testing.assert_allclose(film.rgb(), film.rgb("hud") + film.rgb("environment"), rtol=1e-12, atol=0)
    np.testing.assert_allclose(film.variance_y(), film.variance_y("hud") + film.variance_y("environment"),
                               rtol=1e-12, atol=0)
    channels = hybrid.extra["channels"]
    assert channels["hud"]["method"] == "backward" and channels["environment"]["method"] == "backward"
    reference = INTEGRATORS["backward"](load_scene(folder), 4).render(Budget(rays=14_000_000))
    a, sa = _blocks(luminance(film.rgb()), film.variance_y())
    b, sb = _blocks(luminance(reference.film.rgb()), reference.film.variance_y())
    lit = (a > 0) & (b > 0)
    z = (a[lit] - b[lit]) / np.sqrt(sa[lit] ** 2 + sb[lit] ** 2)
    dof = _block_dof([(film.variance_y(g), film.groups[g].count - 1) for g in film.groups]
                     + [(reference.film.variance_y(), film_dof(reference.film))])[lit]
    bounds = np.array([t_bound(int(lit.sum()), f) for f in dof])
    assert lit.sum() >= 24 and np.all(np.abs(z) < bounds), (z, dof)
    # The environment channel alone is what the sky adds: 1000 cd/m^2 through the windshield where the
    # eye sees it directly (Fresnel transmission of a 4.76 mm plate at these angles: 0.7 to 0.92).
    env = luminance(film.rgb("environment"))
    assert 700 < np.median(env[env > 0]) < 920


@pytest.mark.slow
def test_one_and_two_processes_give_the_same_hybrid_image(preset):
    """For a budget in rays the pilots cost rays, not seconds, so the decisions are the same in every
    run; the workers take them from the parent: the same channels, batch sizes and image."""
    folder = preset("hud-direct", resolution=LOW)
    sky(folder)
    one = INTEGRATORS["hybrid"](load_scene(folder), 5).render(Budget(rays=4_000_000))
    two = render_parallel(INTEGRATORS["hybrid"](load_scene(folder), 5), Budget(rays=4_000_000), workers=2)
    assert one.batches == two.batches and films_match(one, two)
    for name in ("hud", "environment"):
        a, b = one.extra["channels"][name], two.extra["channels"][name]
        assert (a["method"], a["batch_size"], a["every"]) == (b["method"], b["batch_size"], b["every"])


@pytest.mark.slow
def test_channels_and_methods_that_the_scene_does_not_need_are_skipped_with_the_reason(preset):
    """Model no more than the scene needs: no environment channel without an environment, no HUD
    channel without an emitter, no photon pass where next-event estimation reaches every scattering
    surface, no forward tracing of the environment; each says why."""
    folder = preset("hud-direct", resolution=LOW)
    dark_sky = INTEGRATORS["hybrid"](load_scene(folder), 1).render(Budget(rays=2_000_000)).extra["channels"]
    assert dark_sky["environment"]["skipped"] == "the environment is off or black"
    hud = dark_sky["hud"]
    assert hud["method"] == "backward" and hud["chosen_by"] == "pilots"
    pilots = {p["method"]: p for p in hud["pilots"]}
    assert pilots["forward"]["skipped"] is None and pilots["forward"]["efficiency"] < pilots["backward"]["efficiency"]
    assert "next-event estimation reaches them" in pilots["photon"]["skipped"]

    sky(folder)
    edit_json(folder, lambda d: [o["emission"].update(luminance=0.0) for o in d["objects"] if "emission" in o])
    no_leds = INTEGRATORS["hybrid"](load_scene(folder), 1).render(Budget(rays=1_000_000))
    ch = no_leds.extra["channels"]
    assert ch["hud"]["skipped"] == "the scene has no emitter"
    assert ch["environment"]["method"] == "backward" and ch["environment"]["chosen_by"] == "the only one that applies"
    assert luminance(no_leds.film.rgb()).max() > 0

    why = applicable(World(load_scene(folder)).channel(lights=False), False, True)
    assert why["backward"] is None and "emits from the scene's emitters only" in why["forward"]
    assert "photons leave the scene's emitters only" in why["photon"]


@pytest.mark.slow
def test_a_method_given_to_a_channel_renders_it_or_the_skip_is_warned_of(preset):
    """hud_method "photon" on hud-direct against a sky: photon maps are not needed there (next-event
    estimation reaches the scatterer), and the HUD channel was skipped, the HUD left out of the image
    with no warning (a hand-built input). The photon method renders it right, so it renders it, and the
    channel's entry notes that backward would do the same faster; its symbols agree with backward
    tracing's HUD channel. A method that cannot render a channel (backward for a black environment)
    skips it with a warning."""
    folder = preset("hud-direct", resolution=LOW)
    sky(folder)
    means = {}
    for hud_method in ("photon", "backward"):
        edit_json(folder, lambda d, m=hud_method: d.update(methods={"hybrid": {"hud_method": m}}))
        res = INTEGRATORS["hybrid"](load_scene(folder), 1).render(Budget(rays=3_000_000))
        hud = res.extra["channels"]["hud"]
        assert hud["method"] == hud_method and hud["skipped"] is None, hud
        assert ("backward would do the same faster" in (hud["note"] or "")) == (hud_method == "photon"), hud["note"]
        means[hud_method] = (hud["mean_cd_m2"], hud["mean_standard_error_cd_m2"], res.film)
        assert not any("skipped" in w for w in res.warnings), res.warnings
    (m1, s1, f1), (m2, s2, f2) = means["photon"], means["backward"]
    dof = welch_dof((s1 * s1, f1.groups["hud"].count - 1), (s2 * s2, f2.groups["hud"].count - 1))
    assert abs(m1 - m2) < t_bound(1, dof) * math.hypot(s1, s2) and m1 > 0, (m1, s1, m2, s2)
    edit_json(folder, lambda d: d.update(environment={"type": "none"},
                                         methods={"hybrid": {"environment_method": "backward"}}))
    res = INTEGRATORS["hybrid"](load_scene(folder), 1).render(Budget(rays=1_000_000))
    assert res.extra["channels"]["environment"]["skipped"] == "the environment is off or black"
    assert "environment channel skipped: the environment is off or black" in res.warnings, res.warnings


def test_a_channel_whose_pilots_find_no_light_is_skipped_with_a_warning_that_says_so(preset):
    """analytic-mirror with the eye turned away from its panel and mirror: the HUD channel's pilots
    (backward, forward) find no light, the channel is skipped and the rest of the budget not spent; the
    warnings say so (the pilots' paths with it), not only that the render traced no path."""
    folder = preset("analytic-mirror")
    edit_json(folder, lambda d: d["eye"].update(gaze=[0.0, -1.0, 0.0]))
    res = INTEGRATORS["hybrid"](load_scene(folder), 1).render(Budget(rays=300_000))
    hud = res.extra["channels"]["hud"]
    assert hud["method"] is None and hud["skipped"].startswith("no pilot found light")
    assert sum(p["paths"] for p in hud["pilots"]) > 0 and res.paths == 0
    said = "hud channel skipped: no pilot found light (backward: "
    assert any(w.startswith(said) for w in res.warnings), res.warnings
    assert not any("environment channel skipped" in w for w in res.warnings)  # skipped by the scene, not by pilots
    pilots = sum(p["paths"] for p in hud["pilots"])
    assert any(w.startswith(f"no light path found: hybrid traced 0 paths (0 rays), its pilots {pilots:,} paths (")
               for w in res.warnings), res.warnings
    assert luminance(res.film.rgb()).max() == 0.0


def test_a_short_time_budget_splits_between_the_channels_that_size_their_own_batches(preset, monkeypatch):
    """Under the rules (a time budget too short for pilots) hybrid has no pilot variances to allocate its
    batches by, so each channel sizes its own batch to a time budget; a hybrid batch is a batch of every
    channel, so each gets its share of the budget (it got the whole: a hybrid batch took twice its
    share of the time). hud-direct under a sky: the HUD channel by the rules, the environment's the only
    method that applies, both fitted to half the budget."""
    from tracer.methods.backward import BackwardTracer
    from tracer.methods.pilots import PILOT_FLOOR_SECONDS

    fitted = []
    original = BackwardTracer.fit_batch

    def record(self, budget):
        fitted.append(budget.seconds)
        return original(self, budget)

    monkeypatch.setattr(BackwardTracer, "fit_batch", record)
    folder = preset("hud-direct", resolution=LOW)
    sky(folder)
    integ = INTEGRATORS["hybrid"](load_scene(folder), 1)
    seconds = 0.5 * PILOT_FLOOR_SECONDS / float(integ.opts["pilot_share"])
    integ.prepare(Budget(seconds=seconds))
    hud, env = integ.channels
    assert hud.chosen == "backward" and hud.chosen_by.startswith("rules: "), hud.chosen_by
    assert env.chosen == "backward" and env.chosen_by == "the only one that applies"
    assert fitted == [seconds / 2, seconds / 2]
