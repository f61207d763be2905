"""The methods against each other: forward and backward tracing place an LCD's edge alike; forward,
backward with and without next-event estimation agree on every preset, photon and forward on the screen
presets, forward and backward on the polarised variants.

Tolerances are statistical: a deviation must stay inside the Sidak-corrected alpha = 0.01 bound of the
estimators' own reported standard errors."""

import math

import numpy as np
import pytest

from presets import PRESETS, SINGLE_METHOD
from tests.support.render import VARIANTS, image_mean, region_mean, render, render_variant
from tests.support.scenes import lcd_edge_scene
from tests.support.stats import film_dof, t_bound, welch_dof, z_bound
from tracer.core.units import Y_WEIGHTS
from tracer.methods import INTEGRATORS, Budget
from tracer.scene import load_scene
from tracer.transport.world import World

pytestmark = pytest.mark.slow


def _edge_position(y):
    """Sub-pixel column where the row-averaged profile crosses half-way between its plateaus."""
    prof = y.mean(axis=0)
    hi, lo = prof[:8].mean(), prof[-8:].mean()
    half = 0.5 * (hi + lo)
    k = np.nonzero((prof[:-1] >= half) & (prof[1:] < half))[0][0]
    return k + (prof[k] - half) / (prof[k] - prof[k + 1]) + 0.5, hi, lo


def test_forward_and_backward_agree_and_place_edges_alike(tmp_path):
    folder = lcd_edge_scene(tmp_path / "lcd")
    yb, vb, _ = render(folder, "backward", 3_000_000, seed=3)
    yf, vf, _ = render(folder, "forward", 6_000_000, seed=4)
    # Plateaus agree within their combined error, and equal L T and L T / CR.
    left = np.s_[:, :8]
    mb, mf = yb[left].mean(), yf[left].mean()
    sb_, sf = math.sqrt(vb[left].sum()) / vb[left].size, math.sqrt(vf[left].sum()) / vf[left].size
    assert abs(mb - mf) < z_bound(2) * math.hypot(sb_, sf)
    assert mb == pytest.approx(500.0, rel=0.01)
    eb, _, lo_b = _edge_position(yb)
    ef, _, _ = _edge_position(yf)
    assert lo_b == pytest.approx(500.0 / 300, rel=0.05)
    assert abs(eb - ef) < 0.05
    # Geometry: the edge at x = 0.3 mm, 300 mm away, is at column 20 + atan(0.3/300) / pixel angle.
    pixel = math.radians(1.2) / 40
    assert eb == pytest.approx(20 + math.atan(0.3 / 300) / pixel, abs=0.05)


def region_dof(var, mask, res):
    """Degrees of freedom of a region mean's variance: a sum of its pixels' variances, each from the
    spread of the film's replicates (Welch-Satterthwaite)."""
    return welch_dof((var[mask], film_dof(res.film)))


# -- every preset, every method ---------------------------------------------------------------------
RAYS = {"hud-direct": 4_000_000, "analytic-mirror": 1_500_000, "analytic-disk": 1_500_000,
        "analytic-furnace": 1_000_000}
#: Presets that backward tracing cannot render in a test's time (its eye paths must find a 0.2 mm LED
#: through a diffuse screen and a projection lens): photon and forward agree on them instead.
PHOTON_PRESETS = ("hud-screen", "hud-screen-ideal-lcd", "hud-direct-condenser")


# The studies against a panorama (presets.STUDIES) are left out: forward tracing does not render an
# environment; tests/methods/test_hybrid.py checks the hybrid's channels against backward tracing.
@pytest.mark.parametrize("name", [n for n in SINGLE_METHOD if n not in PHOTON_PRESETS])
def test_forward_and_backward_with_and_without_nee_agree(tmp_path, name):
    """The image mean and the bright region's mean (pixels above 10 % of the 99th percentile of the
    backward image) of the three method variants agree pairwise within their combined errors
    (alpha = 0.01, Sidak over presets, regions and pairs)."""
    world = World(load_scene(PRESETS[name].write(tmp_path / name)))
    out = {v: render_variant(world, v, RAYS[name], seed=21) for v in VARIANTS}
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


def test_forward_and_backward_agree_on_the_polarised_variants(preset):
    """Both methods estimate the same symbol luminance on hud-direct-s and hud-direct-film-sunglasses."""
    for name in ("hud-direct-s", "hud-direct-film-sunglasses"):
        world = World(load_scene(preset(name, resolution=(60, 20))))
        means = {m: image_mean(world, m, r, seed=11) for m, r in (("backward", 400_000), ("forward", 3_000_000))}
        (a, sa), (b, sb) = means["backward"], means["forward"]
        assert abs(a - b) < z_bound(2) * math.hypot(sa, sb), (name, means)
