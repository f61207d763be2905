"""Renders held in memory, and the figures the tests read off them: a render's image and variance,
a report written by render_folder, a method variant's image, a region's mean and its standard error,
and whether two results hold the same film."""

from __future__ import annotations

import math

import numpy as np

from tracer.core.units import Y_WEIGHTS
from tracer.methods import INTEGRATORS, Budget, RenderResult
from tracer.products.render import render_folder
from tracer.scene import load_scene


def render(scene_dir, method: str, rays: int, seed: int = 1, batch_size: int | None = None, edit=None):
    """Render in memory: (Y (H, W), variance of Y (H, W), RenderResult)."""
    scene = load_scene(scene_dir)
    if edit is not None:
        edit(scene)
    kw = {"batch_size": batch_size} if batch_size else {}
    integ = INTEGRATORS[method](scene, seed, **kw)
    res = integ.render(Budget(rays=rays))
    rgb = res.film.rgb()
    return rgb @ Y_WEIGHTS, res.film.variance_y(), res


def films_match(a: RenderResult, b: RenderResult, rtol: float = 1e-12) -> bool:
    """Whether two results hold the same film up to rounding in the last bits (the determinism
    check of the tests: independent sampling would differ by far more)."""
    fa, fb = a.film, b.film
    fa.make_dense()
    fb.make_dense()
    norms_equal = all(np.array_equal(fa.norm[k], fb.norm[k]) for k in fa.kinds)
    return (norms_equal and fa.replicates == fb.replicates
            and all(np.allclose(fa.sums[k], fb.sums[k], rtol=rtol, atol=0) for k in fa.kinds)
            and np.allclose(fa.rep_sq, fb.rep_sq, rtol=rtol, atol=0))


def render_report(folder, method, rays, tmp_path, seed=1):
    """render_folder's report of ``rays`` rays into tmp_path (its mean and maximum luminance finite)."""
    report, _ = render_folder(folder, method, Budget(rays=rays), seed, tmp_path / f"out-{method}-{seed}")
    assert all(math.isfinite(v) for v in (report["luminance"]["mean"], report["luminance"]["max"]))
    return report


#: The method variants every preset must agree on.
VARIANTS = {"forward": ("forward", {}), "backward": ("backward", {}),
            "backward, no NEE": ("backward", {"next_event": False})}


def render_variant(world, variant, rays, seed, reference=None):
    """A method variant of :data:`VARIANTS` on ``world``: (Y, variance of Y, RenderResult); ``reference``
    replaces the roulette's reference luminance (0: no roulette)."""
    method, changes = VARIANTS[variant]
    integ = INTEGRATORS[method](world, seed, options=dict(world.scene.method_options(method)) | changes)
    if reference is not None:
        integ.reference_luminance  # noqa: B018  (the pilot runs first: it also measures the efficiency)
        integ._reference = reference  # the roulette's reference luminance (0: no roulette)
    res = integ.render(Budget(rays=rays))
    return res.film.rgb() @ Y_WEIGHTS, res.film.variance_y(), res


def region_mean(y, var, mask):
    """The mean of Y over the pixels of ``mask`` and its standard error (independent pixels)."""
    k = int(mask.sum())
    return float(y[mask].mean()), math.sqrt(float(var[mask].sum())) / k


def image_mean(world, method, rays, seed=3):
    """``method``'s image mean on ``world`` and its standard error (independent pixels)."""
    res = INTEGRATORS[method](world, seed).render(Budget(rays=rays))
    y = res.film.rgb() @ Y_WEIGHTS
    return float(y.mean()), math.sqrt(float(res.film.variance_y().sum())) / y.size
