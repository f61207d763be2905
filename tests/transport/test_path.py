"""The path loop (tracer.transport.path): glass transmits as Fresnel says (the n^2 law with the eye inside
it), grazing incidence stays finite, the Russian roulette does not starve the LCD's black leak, and the
loop's shortcuts leave the image as it was."""

import math

import numpy as np
import pytest

from presets import PRESETS
from presets._build import SceneBuilder, box, frame_matrix, rectangle
from tests.support.render import region_mean, render, render_variant
from tests.support.stats import z_bound
from tracer.core.imageio import write_png
from tracer.methods import INTEGRATORS, Budget
from tracer.scene import load_scene
from tracer.transport.world import World


def _glass_block(folder, eye_inside=False, grazing=False):
    """A 20 mm glass block in front of a panel; the eye outside, or inside the glass."""
    sb = SceneBuilder(folder, "glass", "a glass block")
    sb.add("glass", box(200.0, 20.0, 200.0), {"type": "dielectric", "ior": 1.5},
           frame_matrix([0, 50, 0], [1, 0, 0], [0, 0, 1]))
    sb.add("panel", rectangle(400.0, 400.0)[:2], {"type": "emitter", "luminance": 100.0},
           frame_matrix([0, 200, 0], [1, 0, 0], [0, -1, 0]))
    gaze = [0, 1, 0] if not grazing else [0.9990482, 0.0436194, 0]  # 87.5 deg from the block's normal
    return sb.write(eye={"position": [0, 50 if eye_inside else 0, 0], "gaze": gaze, "up": [0, 0, 1],
                         "pupil_diameter_mm": 3.0, "accommodation_distance_mm": 500.0,
                         "resolution": [8, 8], "fov_deg": [4.0, 4.0]})


def test_glass_block_transmits_fresnel_and_eye_inside_glass(tmp_path):
    """Through a block (two surfaces at normal incidence) the panel reads L T^2 (plus the small
    inter-reflections); from inside the glass, where the eye sees the panel through one surface,
    radiance is L T n^2 in the glass (the n^2 law, Veach 1997 ch. 5). No NaN at total internal
    reflection or on rays starting on a surface."""
    r = ((1.5 - 1) / 2.5) ** 2
    t = 1 - r
    outside = _glass_block(tmp_path / "outside")
    y, var, _ = render(outside, "backward", 300_000)
    expected = 100.0 * t * t / (1 - r * r)  # incoherent sum of all inter-reflections
    assert y.mean() == pytest.approx(expected, rel=0.01)
    inside = _glass_block(tmp_path / "inside", eye_inside=True)
    y, var, _ = render(inside, "backward", 300_000)
    assert np.all(np.isfinite(y))
    assert y.mean() == pytest.approx(100.0 * t * 1.5**2 / (1 - r * r), rel=0.02)


def test_grazing_incidence_stays_finite(tmp_path):
    folder = _glass_block(tmp_path / "grazing", grazing=True)
    for method in ("backward", "forward"):
        y, var, res = render(folder, method, 200_000)
        assert np.all(np.isfinite(y)) and np.all(np.isfinite(var))


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


@pytest.mark.slow
def test_roulette_does_not_starve_the_black_leak(tmp_path):
    """Forward through six surfaces, with the one roulette rule: the black half reads 1/300 of the clear
    half within its error, its relative error is no worse than the clear half's (as many particles land
    there, each with 1/300 of the weight), and no worse than with roulette switched off. A rule that
    judged paths by their own weight would kill the black half's particles 300 times as often: the
    same check with the threshold raised 300,000-fold (a rule that starves the black half: its
    particles carry 1/300 of the weight and fall below the threshold first) fails."""
    world = World(load_scene(_lcd_chain(tmp_path / "s")))
    rays = 3_000_000
    y, var, res = render_variant(world, "forward", rays, seed=8)
    (c, sc), (b, sb) = _halves(y, var)
    ratio, ratio_se = b / c, (b / c) * math.hypot(sb / b, sc / c)
    assert abs(ratio - 1 / 300) < z_bound(1) * ratio_se
    assert (sb / b) < 1.5 * (sc / c), ((sb / b), (sc / c))
    y0, var0, _ = render_variant(world, "forward", rays, seed=8, reference=0.0)  # roulette off
    (_, _), (b0, sb0) = _halves(y0, var0)
    assert (sb / b) < 1.3 * (sb0 / b0)
    starving = res.extra["roulette"]["reference_luminance_cd_m2"] * 3e5
    ys, vs, _ = render_variant(world, "forward", rays, seed=8, reference=starving)
    (cs, scs), (bs, sbs) = _halves(ys, vs)
    assert (sbs / bs) > 2.0 * (scs / cs)  # the check has the power to see starvation


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
