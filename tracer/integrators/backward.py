"""Backward stochastic ray tracing from the retina (paper sec. 2, Fig. 2, eq. 3; sec. 4.2).

Each batch sends ``spp`` jittered samples through every retina pixel. A sample picks a point of the
eye pupil, follows the thin lens toward the accommodation plane, and continues through the scene:
specular surfaces reflect or refract (Fresnel choice), the LCD modulates, diffuse surfaces scatter
by their own law, until the path meets an emitter (its luminance is read) or escapes into the
environment. The estimate of a pixel is the apparent luminance defined in :mod:`tracer.eye`.

Eq. (3) stratification: the scene may designate an exit pupil, a disk P in the pupil plane. A share
``w`` of the samples then lands in P (its area A'_p inside the eye pupil) and the rest in the pupil
minus P; each stratum is weighted by its area over its sampling probability, so the answer does
not depend on w while its noise does. The paper's weight (the ratio N/M of ray counts) is
w / (1 - w).
"""

from __future__ import annotations

import math

import numpy as np

from ..sampling import uniform_disk_concentric
from ..units import luminance
from ..vec import dot, max3, rows
from .base import DEFAULT_BATCH, ROULETTE_DEPTH, ROULETTE_WEIGHT, Integrator, register


def circle_overlap_area(r1: float, r2: float, d: float) -> float:
    """Area (mm^2) of the intersection of two disks of radii r1, r2 whose centres are d apart."""
    if d >= r1 + r2:
        return 0.0
    if d <= abs(r1 - r2):
        return math.pi * min(r1, r2) ** 2
    a1 = r1 * r1 * math.acos((d * d + r1 * r1 - r2 * r2) / (2 * d * r1))
    a2 = r2 * r2 * math.acos((d * d + r2 * r2 - r1 * r1) / (2 * d * r2))
    k = 0.5 * math.sqrt((-d + r1 + r2) * (d + r1 - r2) * (d - r1 + r2) * (d + r1 + r2))
    return a1 + a2 - k


@register
class BackwardTracer(Integrator):
    name = "backward"
    summary = "retina -> pupil -> optics -> sources (paper sec. 2, eq. 3 strata)"

    def __init__(self, scene, seed, batch_size=DEFAULT_BATCH):
        super().__init__(scene, seed, batch_size)
        self.max_depth = scene.backward["max_depth"]
        npix = self.eye.width * self.eye.height
        self.spp = max(1, self.batch_size // npix)
        self.strata = None
        ep = scene.backward.get("exit_pupil")
        a = self.eye.pupil_radius
        if ep is not None and ep.share > 0:
            dist = float(np.linalg.norm(ep.center_mm))
            inside = circle_overlap_area(a, ep.radius_mm, dist)
            if inside <= 0:
                self.warnings.append("backward.exit_pupil lies outside the eye pupil: stratification ignored")
            else:
                rest = self.eye.pupil_area - inside
                # A stop that covers the whole pupil leaves no second stratum: all samples go to it.
                share = ep.share if rest > 1e-12 * self.eye.pupil_area else 1.0
                self.strata = (ep.center_mm, ep.radius_mm, share, inside, max(rest, 0.0))

    def lens_samples(self, rng: np.random.Generator, n: int):
        """Pupil points (n, 2) in eye coordinates (mm) and their area weights (n,) (mm^2): the pupil
        area for plain sampling, or stratum area / stratum probability with eq. (3) strata."""
        a = self.eye.pupil_radius
        if self.strata is None:
            return a * uniform_disk_concentric(rng.random((n, 2))), np.full(n, self.eye.pupil_area)
        c, r, share, area_p, area_rest = self.strata
        in_p = rng.random(n) < share
        xy = np.empty((n, 2))
        todo = np.arange(n)
        while len(todo):  # rejection: P from its own disk, the rest from the pupil
            ip = in_p[todo]
            cand = uniform_disk_concentric(rng.random((len(todo), 2)))
            cand = np.where(ip[:, None], c + r * cand, a * cand)
            in_pupil = dot(cand, cand) <= a * a
            in_stop = dot(cand - c, cand - c) <= r * r
            ok = np.where(ip, in_pupil, ~in_stop)
            xy[todo[ok]] = cand[ok]
            todo = todo[~ok]
        weight = np.where(in_p, area_p / share, area_rest / (1.0 - share) if area_rest > 0 else 0.0)
        return xy, weight

    def run_batch(self, rng, film):
        eye, accel, env = self.eye, self.accel, self.scene.environment
        w, h = eye.width, eye.height
        pix = np.tile(np.arange(w * h), self.spp)
        n = len(pix)
        jit = rng.random((n, 2))
        sx = (2 * ((pix % w) + jit[:, 0]) / w - 1) * eye.half_x
        sy = (1 - 2 * ((pix // w) + jit[:, 1]) / h) * eye.half_y
        lens, lens_weight = self.lens_samples(rng, n)
        origins, dirs, geo = eye.generate_rays(sx, sy, lens)
        thr = np.repeat((geo * eye.pixel_area * lens_weight / eye.extent[pix])[:, None], 3, axis=1)
        radiance = np.zeros((n, 3))
        found = np.zeros(n, bool)
        idx = np.arange(n)
        if accel is None:  # nothing but the environment
            self.rays_without_geometry += n
            radiance += thr * env.radiance(dirs)
            found |= luminance(radiance) > 0
            idx = idx[:0]
        for depth in range(self.max_depth):
            if len(idx) == 0:
                break
            hits = accel.intersect(origins, dirs)
            miss = ~hits.hit
            if np.any(miss) and not env.is_black:
                le = env.radiance(dirs[miss])
                radiance[idx[miss]] += thr[miss] * le
                found[idx[miss]] |= luminance(le) > 0
            next_o, next_d, next_t, next_i = [], [], [], []
            for slot, sel in hits.by_object():
                surf = self.surfaces[slot]
                it = self.interaction(slot, hits, sel, dirs)
                if surf.emits:
                    le = surf.emitted(it)
                    radiance[idx[sel]] += thr[sel] * le
                    found[idx[sel]] |= luminance(le) > 0
                if surf.terminal:
                    continue
                d_out, factor, alive = surf.scatter(it, rng, radiance=True)
                t_new = rows(thr, sel) * factor
                alive &= max3(t_new) > 0
                if depth >= ROULETTE_DEPTH:
                    q = np.clip(max3(t_new) / ROULETTE_WEIGHT, 0.0, 1.0)
                    survive = rng.random(len(sel)) < q
                    alive &= survive
                    t_new = t_new / np.where(alive, q, 1.0)[:, None]
                keep = np.nonzero(alive)[0]
                d_keep = rows(d_out, keep)
                next_o.append(accel.spawn(rows(it.p, keep), rows(it.ng, keep), d_keep))
                next_d.append(d_keep)
                next_t.append(rows(t_new, keep))
                next_i.append(idx[sel[keep]])
            if not next_i:
                idx = np.zeros(0, np.int64)
                break
            origins, dirs = np.concatenate(next_o), np.concatenate(next_d)
            thr, idx = np.concatenate(next_t), np.concatenate(next_i)
        self.truncated += len(idx)
        contributing = np.nonzero(max3(radiance) > 0)[0]
        film.add(pix[contributing], radiance[contributing])
        film.samples += self.spp
        return n, int(found.sum())

    def finish(self, result):
        super().finish(result)
        result.extra["samples_per_pixel"] = result.film.samples
        if self.strata is not None:
            c, r, share, area_p, area_rest = self.strata
            result.extra["exit_pupil"] = {"center_mm": [float(c[0]), float(c[1])], "radius_mm": r, "share": share,
                                          "area_inside_pupil_mm2": area_p, "area_rest_mm2": area_rest,
                                          "paper_w": share / (1 - share)}
        if result.paths and self.truncated / result.paths > 1e-3:
            result.warnings.append(f"{self.truncated:,} paths were cut at backward.max_depth = {self.max_depth}: "
                                   "the image is biased low; raise max_depth")
