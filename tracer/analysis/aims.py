"""The aims' coverage: how much of the light that reaches the eye from an aimed object leaves it inside
its aim target (the paper's directed split, sec. 2), told before the first ray and after the render,
so that a render is not spent on rare heavy particles."""

from __future__ import annotations

import numpy as np

from ..transport.chains import aim_coverage, specular_paths
from ..transport.world import World
from .brightness import evenly

#: An aim that leaves more than this share of the light an object sends the eye outside its target is
#: reported to the methods that trace particles (the presets' aims cover 0.992 to 1).
AIM_COVERAGE = 0.98


def aim_warnings(analysis: dict) -> list[str]:
    """A warning for each aimed object of :func:`brightness_theorem`'s ``aim_coverage`` below
    AIM_COVERAGE: its particles' aimed share misses part of the light that reaches the eye from it."""
    return [f"the aim of {name} toward {c['target']} covers {100 * c['coverage']:.3g} % of the light that reaches "
            f"the eye from it (the analysis' rays over the pupil): particles find the rest only by its unaimed share, "
            f"rarely and heavily; aim at the target's image through the optics between them, or enlarge the target"
            for name, c in analysis.get("aim_coverage", {}).items() if c["coverage"] < AIM_COVERAGE]


#: The aims' coverage before the first ray (:func:`aim_preflight`): chains followed from at most this
#: many evenly spaced pixels of the image, each from PREFLIGHT_PUPIL_GRID^2 points over the pupil and
#: the pixel (0.6 s on analytic-disk, whose every chain ends in a quadrature of its emitter, 0.1 s on
#: hud-direct; the presets' figures as the report's, the glass block of tests/analysis/test_aims.py 84.0 %
#: against 85.5 %).
PREFLIGHT_PIXELS = 64


PREFLIGHT_PUPIL_GRID = 4


#: The methods whose light paths follow the aims of emitters and scattering surfaces.
AIMED_METHODS = ("forward", "photon")


def aim_preflight(world: World, method: str, environment: bool = True) -> list[str]:
    """Before the first ray of a method that traces particles (:data:`AIMED_METHODS`), in a scene with
    aims: the aims' coverage (:func:`tracer.transport.chains.aim_coverage`) over the chains that the analysis
    follows from evenly spaced pixels of the whole image (the report's own figure, after the render,
    follows the sections' pixels), as :func:`aim_warnings` words it, so that an aim that leaves part of
    the light outside its target is known before a render is spent on rare heavy particles. Empty
    where every aim covers AIM_COVERAGE, and for other methods and scenes without aims."""
    aimed = any(o.material.aim is not None and o.material.aim.share > 0 for o in world.scene.objects) or any(
        o.emission is not None and o.emission.aim is not None and o.emission.aim.share > 0 for o in world.scene.objects)
    if method not in AIMED_METHODS or not aimed or world.accel is None:
        return []
    pixels = evenly(np.arange(world.eye.width * world.eye.height), PREFLIGHT_PIXELS)
    ends = specular_paths(world, pixels=pixels, pupil_grid=PREFLIGHT_PUPIL_GRID, environment=environment)["ends"]
    return aim_warnings({"aim_coverage": aim_coverage(world, ends)})
