"""Forward tracing per windshield ghost order on hud-direct: how often each order reaches the retina,
what it carries against the brightness-theorem analysis, and how much of it lands on the black
background near the symbols.

    .venv/bin/python benchmarks/ghost_orders.py [--rays N] [--seed K]

Ghost k is the chain with 2 k + 1 windshield events (k = 0: the primary reflection). Forward tracing
is run twice on the same seed, with glass choosing its branch by the unpolarised Fresnel R and by the
even mixture of R and the path's own polarised reflectance (tracer.optics.materials.polarised_share).
For each order the table gives the particles that reached the retina, their flux over the primary's
(against the analysis' ratio over the image) and the relative standard error of that flux
(sqrt(sum w^2) / sum w over the particles); then the same on the pixels where the primary and ghost 1
see black LCD cells (as the brightness theorem's background, tracer.products.render), against the analysis' mean
there. A few particles per run on the background mean that forward's estimate of it is a rare-event
sum: in most runs it misses the higher orders' light, in a few it overshoots, on average it is right.
"""

from __future__ import annotations

import argparse
import math
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from presets import PRESETS  # noqa: E402
from tracer.analysis.sections import erode  # noqa: E402
from tracer.core.units import luminance, luminance3  # noqa: E402
from tracer.core.vec import take  # noqa: E402
from tracer.methods import Budget  # noqa: E402
from tracer.methods.forward import ForwardTracer  # noqa: E402
from tracer.optics import materials  # noqa: E402
from tracer.scene import load_scene  # noqa: E402
from tracer.transport.chains import specular_paths  # noqa: E402
from tracer.transport.world import World  # noqa: E402

ORDERS = 5
#: Rays per pixel side of the analysis' means.
PUPIL_GRID = 3


class CountingForward(ForwardTracer):
    """Forward tracing that counts each particle's events on one object and records, for every
    particle reaching the retina, its count, pixel and luminance contribution (cd/m^2 x particles)."""

    def __init__(self, world, seed, counted):
        super().__init__(world, seed)
        self.counted = counted
        self.events: dict[int, np.ndarray] = {}
        self.arrivals: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []
        self._pilot = False

    def pilot_mean(self, ctx):
        self._pilot = True  # the pilot's particles are not in the film
        try:
            return super().pilot_mean(ctx)
        finally:
            self._pilot = False

    def _counts(self, batch: int, n: int) -> np.ndarray:
        """The event counts of ``batch``'s particles, at least n long (particle ids index it)."""
        count = self.events.get(batch, np.zeros(0, np.int32))
        if len(count) < n:
            count = self.events[batch] = np.concatenate([count, np.zeros(n - len(count), np.int32)])
        return count

    def continue_paths(self, state, it, bsdf, ctx, nxt, sl):
        if bsdf is self.counted and len(state):
            add = np.bincount(state.owner)
            self._counts(ctx.batch, len(add))[:len(add)] += add
        return super().continue_paths(state, it, bsdf, ctx, nxt, sl)

    def sensor(self, state, t, ctx):
        eye = self.eye
        t_eye, lens = eye.pupil_hit(state.o, state.d)
        k = np.flatnonzero(t_eye < t)
        if len(k) and not self._pilot:
            pix = eye.pixel_of(*eye.retina_point(take(lens, k), take(state.d, k)))
            k, pix = k[pix >= 0], pix[pix >= 0]
            arrived = state.take(k)
            value = arrived.beta
            if self.world.polar is not None:
                value = self.world.polar.detect(value, arrived.extra, arrived.d)
            count = self._counts(ctx.batch, int(arrived.owner.max(initial=-1)) + 1)[arrived.owner]
            self.arrivals.append((count, pix, luminance3(value) / eye.extent[pix]))
        return super().sensor(state, t, ctx)


def analysis_by_order(world, dielectric_name: str):
    """(image mean by order (ORDERS,), background mask (H W,), background mean by order), cd/m^2: the
    background where the chief ray's primary and ghost 1 see black LCD cells, eroded by one pixel
    (tracer.analysis.sections.erode); the means over PUPIL_GRID^2 rays per pixel (over the pupil and the
    pixel's area, tracer.transport.chains.specular_paths), since the pupil blurs the strokes' edges."""
    h, w = world.eye.height, world.eye.width
    depth = 2 * ORDERS + 6
    lcd = np.full((2, h * w), np.nan)
    for p in specular_paths(world, stride=1, max_depth=depth)["paths"]:
        k = (p["path"].count(f"{dielectric_name}:") - 1) // 2
        if k < 2 and np.any(np.isfinite(p["lcd"])):
            lcd[k, p["pixel"]] = np.where(np.isfinite(p["lcd"]), p["lcd"], lcd[k, p["pixel"]])
    background = erode(((lcd[0] < 0.5) & (lcd[1] < 0.5)).reshape(h, w)).ravel()
    by_pixel = np.zeros((ORDERS, h * w))
    for p in specular_paths(world, stride=1, max_depth=depth, pupil_grid=PUPIL_GRID, seed=1)["paths"]:
        k = (p["path"].count(f"{dielectric_name}:") - 1) // 2
        if 0 <= k < ORDERS:
            np.add.at(by_pixel[k], p["pixel"], luminance(p["luminance"]))
    return by_pixel.mean(axis=1), background, by_pixel[:, background].mean(axis=1)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--rays", type=float, default=1e8)
    ap.add_argument("--seed", type=int, default=1)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        world = World(load_scene(PRESETS["hud-direct"].write(Path(tmp) / "hud-direct")))
        glass = next(m for m in world.materials if isinstance(m, materials.Dielectric))
        name = glass.objects[0].name
        image_mean, background, bg_mean = analysis_by_order(world, name)
        pixels = world.eye.width * world.eye.height
        print(f"hud-direct, forward, {args.rays:.3g} rays, seed {args.seed}; ghost k = 2 k + 1 events on "
              f"'{name}'; background: {int(background.sum())} pixels")
        for choice in (False, True):
            materials.POLARISED_CHOICE = choice
            try:
                tracer = CountingForward(world, args.seed, glass)
                res = tracer.render(Budget(rays=int(args.rays)))
            finally:
                materials.POLARISED_CHOICE = True
            count = np.concatenate([a[0] for a in tracer.arrivals])
            pix = np.concatenate([a[1] for a in tracer.arrivals])
            value = np.concatenate([a[2] for a in tracer.arrivals])
            order = (count - 1) // 2
            scale = value.sum() / max(float((res.film.rgb() @ [0.2126, 0.7152, 0.0722]).sum()), 1e-300)
            label = "polarised share (default)" if choice else "unpolarised R"
            print(f"\nglass branch by {label}: {res.rays:,} rays")
            print("order | arrivals | flux / primary (analysis) | rel. SE | on background: arrivals, "
                  "cd/m^2 (analysis)")
            primary = value[order == 0].sum()
            for k in range(ORDERS):
                sel = order == k
                flux = value[sel].sum()
                rel_se = math.sqrt(float((value[sel] ** 2).sum())) / flux if flux > 0 else float("nan")
                on_bg = sel & background[pix]
                bg = value[on_bg].sum() / scale / background.sum()
                ratio = image_mean[k] / image_mean[0]
                print(f"{k:5d} | {int(sel.sum()):8,d} | {flux / primary:10.4g} ({ratio:10.4g}) | "
                      f"{rel_se:7.3f} | {int(on_bg.sum()):6,d}, {bg:8.3f} ({bg_mean[k]:8.3f})")
            print(f"(image mean {value.sum() / scale / pixels:.2f} cd/m^2)")


if __name__ == "__main__":
    main()
