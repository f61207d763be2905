"""Forward stochastic ray tracing from the light sources into the eye (paper sec. 2, Fig. 3; sec. 4.2).

Particles leave the emitters (an emitter triangle is chosen with probability proportional to its
flux, a point uniformly on it, a direction from the Lambertian law) and carry flux through the
optics. A particle that crosses the eye pupil from the front is imaged by the thin lens onto the
retina and adds its flux to one pixel; flux over the pixel's geometric extent is the apparent
luminance (:mod:`tracer.eye`), so forward and backward estimate the same number.

The paper's directed split (sec. 2): an emitter or a scattering surface with an ``aim`` draws, with
probability w, a direction toward its target aperture (the eye pupil where it is in direct view, an
optical system's entrance pupil, the LCD) and otherwise from its own law. The particle's weight is
f cos / (w p_target + (1 - w) p_own), the one-sample mixture estimator (Veach & Guibas 1995,
doi:10.1145/218380.218498), which is unbiased for every w in [0, 1). The paper's weights
1/(1 - w) and I_p Omega_p / (w I_s) are this estimator for a target cone excluded from the surface's
own sampling.
"""

from __future__ import annotations

import numpy as np

from ..optics.surfaces import Emitter, Surface
from ..sampling import cosine_hemisphere, frame_from_normal, sample_discrete, to_world, uniform_triangle
from ..scene import Aim
from ..units import MM2_TO_M2
from ..vec import axpy, dot, max3, norm, rows, scale
from .base import DEFAULT_BATCH, ROULETTE_DEPTH, ROULETTE_WEIGHT, Integrator, register


@register
class ForwardTracer(Integrator):
    name = "forward"
    summary = "sources -> optics -> pupil -> retina (paper sec. 2, directed split)"

    def __init__(self, scene, seed, batch_size=DEFAULT_BATCH):
        super().__init__(scene, seed, batch_size)
        self.max_depth = scene.forward["max_depth"]
        tris, lum_sides, radiance, group = [], [], [], []
        #: Emitters that sample directions alike (two-sidedness, aim) form one group, traced together.
        self.emitter_groups: list[tuple[bool, Aim | None]] = []
        for slot, surf in enumerate(self.surfaces):
            if not isinstance(surf, Emitter):
                continue
            t = self.objects[slot].triangles
            key = (surf.two_sided, surf.obj.material.aim)
            if key not in self.emitter_groups:
                self.emitter_groups.append(key)
            tris.append(t)
            lum_sides.append(np.full((len(t), 2), (surf.luminance, 2.0 if surf.two_sided else 1.0)))
            radiance.append(np.tile(surf.radiance_rgb, (len(t), 1)))
            group.append(np.full(len(t), self.emitter_groups.index(key)))
        t = np.concatenate(tris) if tris else np.zeros((0, 3, 3))
        self.emitter_v0, self.emitter_e1, self.emitter_e2 = t[:, 0], t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]
        cross = np.cross(self.emitter_e1, self.emitter_e2)
        self.emitter_area = 0.5 * norm(cross)  # mm^2
        self.emitter_normal = cross / np.where(self.emitter_area > 0, 2 * self.emitter_area, 1.0)[:, None]
        lum, sides = (np.concatenate(lum_sides) if lum_sides else np.zeros((0, 2))).T
        self.emitter_power = np.pi * lum * self.emitter_area * sides  # cd/m^2 mm^2 sr = 1e-6 lm
        self.emitter_radiance = np.concatenate(radiance) if radiance else np.zeros((0, 3))  # cd/m^2, RGB
        self.emitter_group = np.concatenate(group) if group else np.zeros(0, np.int64)
        self.total_flux_lm = float(self.emitter_power.sum() * MM2_TO_M2)
        if self.total_flux_lm <= 0:
            self.warnings.append("the scene has no emitter with positive flux: forward tracing has nothing to trace")
        if not self.scene.environment.is_black:
            self.warnings.append("forward tracing does not emit from the environment: render it with the backward "
                                 "method (the hybrid method of a later release merges both)")
        #: When a list, run_batch appends (particle ids (k,), points (k, 3) mm, reached_eye (k,) bool)
        #: for every event, so that tools can draw the sampled light paths.
        self.recorder: list | None = None

    # -- emission --------------------------------------------------------------------------------
    def emit(self, rng: np.random.Generator, n: int):
        """Particles: origins (n, 3) mm, directions (n, 3), flux (n, 3) in cd/m^2 mm^2 sr, alive (n,)."""
        tri, pmf = sample_discrete(self.emitter_power, rng.random(n))
        b = uniform_triangle(rng.random((n, 2)))
        points = axpy(b[:, 1], rows(self.emitter_e2, tri), axpy(b[:, 0], rows(self.emitter_e1, tri),
                                                                  rows(self.emitter_v0, tri)))
        normal = rows(self.emitter_normal, tri)
        pdf_pos = pmf / self.emitter_area[tri]
        dirs = np.empty((n, 3))
        pdf_dir = np.empty(n)
        group = self.emitter_group[tri]
        for g, (two_sided, aim) in enumerate(self.emitter_groups):
            sel = np.flatnonzero(group == g) if len(self.emitter_groups) > 1 else np.arange(n)
            nrm = rows(normal, sel)
            if two_sided:
                flip = rng.random(len(sel)) < 0.5
                nrm = np.where(flip[:, None], -nrm, nrm)
                pdf_pos[sel] *= 0.5
                normal[sel] = nrm
            dirs[sel], pdf_dir[sel] = self._directions(rng, aim, rows(points, sel), nrm)
        cos = dot(dirs, normal)
        alive = (cos > 0) & (pdf_dir > 0)
        flux = scale(rows(self.emitter_radiance, tri), np.where(alive, cos / np.where(alive, pdf_pos * pdf_dir, 1.0),
                                                                 0.0))
        origins = self.accel.spawn(points, normal, dirs) if self.accel else points
        return origins, dirs, flux, alive

    def _directions(self, rng, aim: Aim | None, points: np.ndarray, normal: np.ndarray):
        """Directions (m, 3) and their solid-angle pdf (m,) from the Lambertian law, mixed with the
        emitters' aim target when they have one."""
        m = len(points)
        t, b, nn = frame_from_normal(normal)
        d = to_world(cosine_hemisphere(rng.random((m, 2))), t, b, nn)
        if aim is None or aim.share == 0:
            return d, np.maximum(dot(d, normal), 0.0) / np.pi
        d, _, p_t = self._directed_split(aim, points, d, rng)
        p_cos = np.maximum(dot(d, normal), 0.0) / np.pi
        return d, aim.share * p_t + (1 - aim.share) * p_cos

    def _directed_split(self, aim, origins: np.ndarray, d_own: np.ndarray, rng):
        """Replace a share ``aim.share`` of the directions ``d_own`` (m, 3) by directions toward
        (or, for mode "away", from) the aim target. Returns (directions, aimed (m,) bool, target pdf
        per sr of every returned direction (m,))."""
        m = len(origins)
        target = self.target(aim.target)
        sign = -1.0 if aim.mode == "away" else 1.0
        aimed = rng.random(m) < aim.share
        d_t, p_t = target.sample(origins, rng.random((m, 3)))
        d = np.where(aimed[:, None], sign * d_t, d_own)
        own = ~aimed
        p_t[own] = target.pdf(origins[own], sign * d[own])
        return d, aimed, p_t

    # -- transport -------------------------------------------------------------------------------
    def _scatter_aimed(self, surf: Surface, it, rng):
        """Directed split at a scattering surface: one-sample mixture of the surface's own sampling
        and sampling toward its target. Returns (directions, weight factor (m, 3), alive)."""
        aim = surf.obj.material.aim
        d_own, factor, alive = surf.scatter(it, rng, radiance=False)
        if aim is None or aim.share == 0:
            return d_own, factor, alive
        d, aimed, p_t = self._directed_split(aim, it.p, d_own, rng)
        mix = aim.share * p_t + (1 - aim.share) * surf.pdf(it, d)
        fcos = surf.eval_fcos(it, d)
        ok = np.where(aimed, p_t > 0, alive) & (mix > 0)
        weight = np.where(ok[:, None], fcos / np.where(ok, mix, 1.0)[:, None], 0.0)
        return d, weight, ok & (max3(weight) > 0)

    def run_batch(self, rng, film):
        n = self.batch_size
        if self.total_flux_lm <= 0 or self.accel is None:
            film.samples += n
            return n, 0
        eye = self.eye
        origins, dirs, flux, alive = self.emit(rng, n)
        pid = np.nonzero(alive)[0]
        origins, dirs, flux = rows(origins, pid), rows(dirs, pid), rows(flux, pid)
        flux0 = max3(flux)
        found = 0
        self._record(pid, origins, np.zeros(len(pid), bool))
        for depth in range(self.max_depth):
            if len(flux) == 0:
                break
            t_eye, lens = eye.pupil_hit(origins, dirs)
            hits = self.accel.intersect(origins, dirs)
            at_eye = t_eye < hits.t
            if self.recorder is not None:
                eye_points = origins + np.where(at_eye, t_eye, 0)[:, None] * dirs
                self._record(pid, np.where(at_eye[:, None], eye_points, hits.points), at_eye)
            if np.any(at_eye):
                sx, sy = eye.retina_point(lens[at_eye], dirs[at_eye])
                pix = eye.pixel_of(sx, sy)
                ok = pix >= 0
                found += int(ok.sum())
                film.add(pix[ok], flux[at_eye][ok] / eye.extent[pix[ok]][:, None])
            hit = hits.hit & ~at_eye
            next_o, next_d, next_f, next_0, next_id = [], [], [], [], []
            for slot, sel in hits.by_object(hit):
                surf = self.surfaces[slot]
                if surf.terminal:
                    continue
                it = self.interaction(slot, hits, sel, dirs)
                if surf.scattering:
                    d_out, factor, ok = self._scatter_aimed(surf, it, rng)
                else:
                    d_out, factor, ok = surf.scatter(it, rng, radiance=False)
                f_new = rows(flux, sel) * factor
                ok &= max3(f_new) > 0
                if depth >= ROULETTE_DEPTH:
                    q = np.clip(max3(f_new) / flux0[sel] / ROULETTE_WEIGHT, 0.0, 1.0)
                    ok &= rng.random(len(sel)) < q
                    f_new = f_new / np.where(ok, q, 1.0)[:, None]
                k = np.nonzero(ok)[0]
                d_keep = rows(d_out, k)
                next_o.append(self.accel.spawn(rows(it.p, k), rows(it.ng, k), d_keep))
                next_d.append(d_keep)
                next_f.append(rows(f_new, k))
                next_0.append(flux0[sel[k]])
                next_id.append(pid[sel[k]])
            if not next_o:
                flux = np.zeros((0, 3))
                break
            origins, dirs = np.concatenate(next_o), np.concatenate(next_d)
            flux, flux0, pid = np.concatenate(next_f), np.concatenate(next_0), np.concatenate(next_id)
        self.truncated += len(flux)
        film.samples += n
        return n, found

    def _record(self, pid: np.ndarray, points: np.ndarray, at_eye: np.ndarray):
        if self.recorder is not None:
            self.recorder.append((pid.copy(), points.copy(), at_eye.copy()))

    def light_paths(self, particles: int, only_to_eye: bool = True, seed_batch: int = 0) -> list[np.ndarray]:
        """Sample ``particles`` light paths and return them as polylines ((k, 3) arrays, mm, from the
        emitter to the last event), only those that reached the eye pupil by default."""
        from ..sampling import make_rng
        from .base import Film

        self.recorder = []
        saved, self.batch_size = self.batch_size, particles
        try:
            self.run_batch(make_rng(self.seed, seed_batch), Film(self.eye.width, self.eye.height))
        finally:
            self.batch_size = saved
            events, self.recorder = self.recorder, None
        ids = np.concatenate([e[0] for e in events])
        pts = np.concatenate([e[1] for e in events])
        eye_hit = np.concatenate([e[2] for e in events])
        order = np.argsort(ids, kind="stable")  # events of one particle stay in time order
        ids, pts, eye_hit = ids[order], pts[order], eye_hit[order]
        starts = np.flatnonzero(np.r_[True, ids[1:] != ids[:-1]])
        ends = np.r_[starts[1:], len(ids)]
        return [pts[a:b] for a, b in zip(starts, ends, strict=True) if not only_to_eye or eye_hit[b - 1]]

    def finish(self, result):
        super().finish(result)
        result.extra["emitted_flux_lm"] = self.total_flux_lm
        if result.paths and self.truncated / result.paths > 1e-3:
            result.warnings.append(f"{self.truncated:,} particles were cut at forward.max_depth = {self.max_depth}: "
                                   "the image is biased low; raise max_depth")
