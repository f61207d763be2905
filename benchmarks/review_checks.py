"""The figures of the reviews of 2026-12-04 and 2026-12-05, from the tests' own scenes.

    .venv/bin/python benchmarks/review_checks.py

- analytic-mirror behind a 20 mm glass block (tests/support/scenes.py, tests/analysis/): each method's
  image section against the brightness-theorem prediction L R T_slab, and the panel's aim coverage, after the render
  and before the first ray (with the time that takes on it, hud-direct and analytic-disk);
- a ring lighting a floor through a coarse smoothed mirror (tests/optics/test_bsdf.py): backward and
  forward tracing over three seeds, with and without the adjoint factor for shading normals;
- a diffuse screen over a 200 mm panel (tests/analysis/test_brightness.py): the analysis' quadrature
  against Lambert's contour formula for gaps whose cells are 71 to 0.35 times the distance, and the photon
  method 1 mm over a 100 mm disk (tests/methods/test_photon.py) against tau E / pi;
- a sunlit road under a sky (tests/analysis/test_brightness.py): the prediction against rho (E sin h / pi + L_sky).

About two minutes on 2 cores. The tests assert the same things with bounds; this prints the numbers the
docs/results/ quotes.
"""

from __future__ import annotations

import math
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from presets import PRESETS  # noqa: E402
from tests.analysis.test_brightness import _backlit_screen, _square_view_factor, _sunlit_road  # noqa: E402
from tests.methods.test_photon import _screen  # noqa: E402
from tests.optics.test_bsdf import _ring_under_a_smoothed_dome  # noqa: E402
from tests.support.scenes import mirror_behind_glass  # noqa: E402
from tracer.analysis.aims import aim_preflight  # noqa: E402
from tracer.analysis.brightness import brightness_theorem  # noqa: E402
from tracer.core.units import Y_WEIGHTS  # noqa: E402
from tracer.methods import INTEGRATORS, Budget  # noqa: E402
from tracer.products.render import render_scene  # noqa: E402
from tracer.scene import load_scene  # noqa: E402
from tracer.transport import chains as analysis  # noqa: E402
from tracer.transport import path  # noqa: E402
from tracer.transport.world import World  # noqa: E402


def glass_block(tmp: Path):
    folder = mirror_behind_glass(lambda name, **kw: PRESETS[name].write(tmp / name, **kw))
    print("analytic-mirror behind a glass block, 2,000,000 rays, seed 1:")
    for method in ("forward", "backward", "photon"):
        report = render_scene(load_scene(folder), method, Budget(rays=2_000_000), 1, tmp / method)[0]
        bt = report["brightness_theorem"]
        image = bt["image"]
        print(f"  {method:8s} {image['rendered_cd_m2']:8.2f} +- {image['standard_error_cd_m2']:.2f} against "
              f"{image['predicted_cd_m2']:.2f} cd/m^2: ratio {image['rendered_over_predicted']:.3f}, "
              f"z {image['rendered_minus_predicted_sigma']:+.1f}; aim coverage "
              f"{bt['aim_coverage']['panel']['coverage']:.3f}")
    for name, f in (("the glass block", folder), ("hud-direct", PRESETS["hud-direct"].write(tmp / "hd")),
                    ("analytic-disk", PRESETS["analytic-disk"].write(tmp / "ad"))):
        world = World(load_scene(f))
        t0 = time.perf_counter()
        said = aim_preflight(world, "forward")
        print(f"  before the first ray, {name}: {time.perf_counter() - t0:.2f} s, "
              f"{said[0].split(' of the light')[0] if said else 'no aim warned of'}")


def smoothed_dome(tmp: Path):
    world = World(load_scene(_ring_under_a_smoothed_dome(tmp / "dome")))
    factor = path.adjoint_shading_factor
    print("a ring through a smoothed 2 x 2-cell mirror onto a floor, three seeds:")
    for label, method, rays, adjoint in (("backward", "backward", 10_000_000, True),
                                         ("forward, adjoint factor", "forward", 40_000_000, True),
                                         ("forward, without it", "forward", 40_000_000, False)):
        path.adjoint_shading_factor = factor if adjoint else (lambda it, wo: np.ones(wo.shape[1], np.float32))
        means, errors = [], []
        for seed in (1, 2, 3):
            film = INTEGRATORS[method](world, seed, options=dict(world.scene.method_options(method))).render(
                Budget(rays=rays)).film
            y = film.rgb() @ Y_WEIGHTS
            means.append(float(y.mean()))
            errors.append(math.sqrt(float(film.variance_y().sum())) / y.size)
        path.adjoint_shading_factor = factor
        print(f"  {label:24s} {np.mean(means):.3f} +- {math.sqrt(sum(e * e for e in errors)) / 3:.3f} cd/m^2")


def backlight(tmp: Path):
    zeros = np.zeros((16, 16))
    trust = analysis.QUAD_TRUST
    print("a screen (tau 0.5) over a 200 mm panel of 1000 cd/m^2, its centre: the quadrature (cells of 71 mm) "
          "against Lambert's contour formula")
    analysis.QUAD_TRUST = math.inf  # every section compared, to show the quadrature's own error
    try:
        for gap in (1.0, 30.0, 71.0, 100.0, 141.0, 200.0):
            bt = brightness_theorem(World(load_scene(_backlit_screen(tmp / f"gap{gap:g}", gap))), zeros, zeros)
            exact = 500.0 * _square_view_factor(100.0, gap)
            predicted = bt["image"]["predicted_cd_m2"]
            print(f"  gap {gap:5.0f} mm (cells {70.7 / gap:5.2f} x it): {predicted:8.2f} against {exact:7.2f} cd/m^2, "
                  f"{predicted / exact - 1:+.2%}")
    finally:
        analysis.QUAD_TRUST = trust
    world = World(load_scene(_screen(tmp / "photon", panel_radius=100.0, panel_height=1.0)))
    film = INTEGRATORS["photon"](world, 3, 4096).render(Budget(rays=4_000_000)).film
    print(f"  photon, the screen 1 mm over a 100 mm disk: {float(film.rgb()[0, 0] @ Y_WEIGHTS):.2f} +- "
          f"{math.sqrt(float(film.variance_y()[0, 0])):.2f} against {0.5 * 1000 * 1e4 / (1e4 + 1):.2f} cd/m^2")


def road(tmp: Path):
    report = render_scene(load_scene(_sunlit_road(tmp / "road")), "backward", Budget(rays=1_000_000), 1,
                          tmp / "road-out")[0]
    image = report["brightness_theorem"]["image"]
    exact = 0.2 * (1e5 * math.sin(math.radians(30.0)) / math.pi + 1000.0)
    print(f"a sunlit road under a sky: predicted {image['predicted_cd_m2']:.1f} +- "
          f"{image['predicted_standard_error_cd_m2']:.1f}, rendered {image['rendered_cd_m2']:.1f} +- "
          f"{image['standard_error_cd_m2']:.1f}, rho (E sin h / pi + L_sky) = {exact:.1f} cd/m^2")


def main():
    with tempfile.TemporaryDirectory() as tmp:
        glass_block(Path(tmp))
        smoothed_dome(Path(tmp))
        backlight(Path(tmp))
        road(Path(tmp))


if __name__ == "__main__":
    main()
