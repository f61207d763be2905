"""The figures of the review of 2026-12-04, from the tests' own scenes.

    .venv/bin/python benchmarks/review_checks.py

- analytic-mirror behind a 20 mm glass block (tests/test_analysis.py): each method's image section
  against the brightness-theorem prediction L R T_slab, and the panel's aim coverage;
- a ring lighting a floor through a coarse smoothed mirror (tests/test_transport.py): backward and
  forward tracing over three seeds, with and without the adjoint factor for shading normals.

About a minute on 2 cores. The tests assert the same things with bounds; this prints the numbers the
README quotes.
"""

from __future__ import annotations

import math
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT), str(ROOT / "tests")]

from test_analysis import _mirror_behind_glass  # noqa: E402
from test_transport import _ring_under_a_smoothed_dome  # noqa: E402

from presets import PRESETS  # noqa: E402
from tracer.integrators import INTEGRATORS, Budget, path  # noqa: E402
from tracer.render import render_scene  # noqa: E402
from tracer.scene import load_scene  # noqa: E402
from tracer.units import Y_WEIGHTS  # noqa: E402
from tracer.world import World  # noqa: E402


def glass_block(tmp: Path):
    folder = _mirror_behind_glass(lambda name, **kw: PRESETS[name].write(tmp / name, **kw))
    print("analytic-mirror behind a glass block, 2,000,000 rays, seed 1:")
    for method in ("forward", "backward", "photon"):
        report = render_scene(load_scene(folder), method, Budget(rays=2_000_000), 1, tmp / method)[0]
        bt = report["brightness_theorem"]
        image = bt["image"]
        print(f"  {method:8s} {image['rendered_cd_m2']:8.2f} +- {image['standard_error_cd_m2']:.2f} against "
              f"{image['predicted_cd_m2']:.2f} cd/m^2: ratio {image['rendered_over_predicted']:.3f}, "
              f"z {image['rendered_minus_predicted_sigma']:+.1f}; aim coverage "
              f"{bt['aim_coverage']['panel']['coverage']:.3f}")


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


def main():
    with tempfile.TemporaryDirectory() as tmp:
        glass_block(Path(tmp))
        smoothed_dome(Path(tmp))


if __name__ == "__main__":
    main()
