"""Backward stochastic ray tracing from the retina (paper sec. 2, Fig. 2, eq. 3; sec. 4.2), with
next-event estimation.

Each batch sends ``spp`` jittered samples through every retina pixel. A sample picks a point of the
eye pupil, follows the thin lens toward the accommodation plane, and continues through the scene on
the path loop (:mod:`tracer.transport.path`): specular surfaces reflect or refract (Fresnel choice),
the LCD modulates, other surfaces scatter by their own law, until the path meets an emitter (its
luminance is read) or escapes into the environment. The estimate of a pixel is the apparent
luminance defined in :mod:`tracer.transport.eye`.

Next-event estimation (on by default, ``methods.backward.next_event``): at every vertex with a
non-delta lobe the path also connects to a point on a light, chosen by the light table
(:meth:`tracer.sources.lights.LightTable.sample_direct`: the emitting object by the BSDF toward it times its
power over the squared distance, mixed with its power), and to the environment by its importance
distribution, each with a shadow ray. Connections and the paths' own hits of the same lights are
combined by multiple importance sampling with the power heuristic (Veach 1997, ch. 9,
doi:10.5555/927297), so every light path is counted once. A specular surface between the vertex and
the light blocks the connection: light that reaches a diffuse surface only through glass is left to
the paths' own hits (or to the photon method's maps, tracer.methods.photon). With ``next_event: false`` the
method is the paper's plain backward tracing.

Eq. (3) stratification: the scene may designate an exit pupil, a disk P in the pupil plane. A share
``w`` of the samples then lands in P (its area A'_p inside the eye pupil) and the rest in the pupil
minus P; each stratum is weighted by its area over its sampling probability, so the answer does
not depend on w while its noise does. The paper's weight (the ratio N/M of ray counts) is
w / (1 - w).
"""

from __future__ import annotations

import math

import numpy as np

from ..core.sampling import uniform_disk_concentric
from ..core.units import luminance3
from ..core.vec import F32, dot, put, take
from ..optics.bsdf import IMPORTANCE, RADIANCE, REFLECTION, TRANSMISSION
from ..transport.path import PathMethod, PathState, Shadow, continue_by_sampling, segment_to, trace
from .base import WAVE, Integrator, register

#: Strata whose acceptance by rejection sampling would be below this are not worth stratifying.
MIN_ACCEPTANCE = 1e-3
#: Candidates per round of that rejection sampling (bounds its memory: 16 MiB).
MAX_CANDIDATES = 1 << 20
#: A path splits at a glass surface or coating where the smaller branch carries at least this share
#: of the two branches' flux, and below it with a probability that falls in proportion to the share
#: (:meth:`BackwardTracer.continue_paths`). Bare glass reflects at least 4 % (n = 1.5, normal
#: incidence): it splits at every angle but grazing incidence and the edge of total internal
#: reflection (where T falls below 2 %); a coating that reflects 0.5 % keeps the Fresnel choice 3
#: times in 4. The photon method's eye paths follow the same rule.
SPLIT_MIN = 0.02


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


#: The largest density (1/sr) the MIS weights use: its square stays finite in float64.
MAX_PDF = 1e150


def solid_angle_pdf(pdf_area: np.ndarray, dist: np.ndarray, cos: np.ndarray) -> np.ndarray:
    """An area density (1/mm^2) at distance ``dist`` (mm) seen at |cos| to the surface normal, per
    steradian: pdf dist^2 / |cos|, in float64; infinite where the cosine is 0 (seen edge-on)."""
    cos = np.abs(np.asarray(cos, np.float64))
    num = np.asarray(pdf_area, np.float64) * np.asarray(dist, np.float64) ** 2
    out = np.full(np.broadcast(num, cos).shape, np.inf)
    return np.divide(num, cos, out=out, where=cos > 0)


#: When at least this share of a bounce's hits on glass split, only the others sample a branch;
#: below it every hit samples and the split ones' entries are overwritten (fewer takes). The image is
#: the same either way (tests/transport/test_path.py).
SAMPLE_UNSPLIT_ONLY = 0.5


@register
class BackwardTracer(Integrator, PathMethod):
    name = "backward"
    noise_advice = (", or use the forward method, which suits small sources that scattering surfaces see only "
                    "through lenses, mirrors or glass (next-event estimation cannot connect through them)")
    summary = "retina -> pupil -> optics -> sources, next-event estimation (paper sec. 2, eq. 3 strata)"
    components = {"hit": "samples per pixel", "connection": "samples per pixel"}
    mode = RADIANCE
    #: Connections share the light with the paths' own hits of it (multiple importance sampling); a
    #: method whose camera paths end at the connecting vertex gives connections the full weight.
    mis_with_hits = True
    efficiency_definition = "retina samples whose path reached a source or a lit environment / samples"
    found_what = "reached a source"

    def __init__(self, world, seed, batch_size=None, options=None):
        super().__init__(world, seed, batch_size, options)
        w = self.world
        self.next_event = bool(self.opts["next_event"])
        self.splits = int(self.opts["splits"])
        self.lights = w.lights
        self.env = w.environment
        self.nee_lights = self.next_event and len(self.lights) > 0
        self.nee_env = self.next_event and not self.env.is_black
        self.max_luminance = w.max_luminance
        #: The samplers of eye paths: a material, or its mixture with directions toward the aperture
        #: through which its light arrives ("light_aim"), the paper's directed split on the eye's side.
        self._eye_sampler = w.aimed_samplers(lambda o: o.material.light_aim)
        self.npix = self.eye.width * self.eye.height
        self._pass_step: int | None = None
        self.strata = None
        ep = self.opts.get("exit_pupil")
        a = self.eye.pupil_radius
        if ep is not None and ep["share"] > 0:
            center, radius = np.asarray(ep["center_mm"], dtype=np.float64), float(ep["radius_mm"])
            inside = circle_overlap_area(a, radius, float(np.linalg.norm(center)))
            rest = self.eye.pupil_area - inside
            small = min(a, radius)
            if inside < MIN_ACCEPTANCE * math.pi * small * small:
                self.warnings.append("methods.backward.exit_pupil lies (almost) outside the eye pupil: "
                                     "stratification ignored")
            elif rest < MIN_ACCEPTANCE * self.eye.pupil_area:
                self.warnings.append("methods.backward.exit_pupil covers the eye pupil: every sample is in it, "
                                     "stratification ignored")
            else:
                self.strata = (center, radius, float(ep["share"]), inside, rest)

    # -- camera rays -----------------------------------------------------------------------------
    def _disk_part(self, rng, n: int, center: np.ndarray, radius: float, inside: bool) -> np.ndarray:
        """n uniform points (2, n) of the pupil intersected with (``inside``) or minus the disk
        (``center``, ``radius``): rejection from the smaller of the two disks (or from the pupil),
        drawing enough candidates per round that one or two rounds suffice."""
        a = self.eye.pupil_radius
        from_stop = inside and radius < a
        area = math.pi * (radius if from_stop else a) ** 2
        target = self.strata[3] if inside else self.strata[4]
        accept = target / area
        out = np.empty((2, 0))
        while out.shape[1] < n:
            k = min(int((n - out.shape[1]) / accept * 1.2) + 16, MAX_CANDIDATES)
            cand = uniform_disk_concentric(rng.random((2, k)))
            cand = center[:, None] + radius * cand if from_stop else a * cand
            in_pupil = cand[0] * cand[0] + cand[1] * cand[1] <= a * a
            dx, dy = cand[0] - center[0], cand[1] - center[1]
            in_stop = dx * dx + dy * dy <= radius * radius
            ok = (in_pupil & in_stop) if inside else ~in_stop
            out = np.concatenate([out, cand[:, ok]], axis=1)
        return out[:, :n]

    def lens_samples(self, rng: np.random.Generator, n: int):
        """Pupil points (2, n) in eye coordinates (mm) and their area weights (n,) (mm^2): the pupil
        area for plain sampling, or stratum area / stratum probability with eq. (3) strata."""
        a = self.eye.pupil_radius
        if self.strata is None:
            return a * uniform_disk_concentric(rng.random((2, n))), np.full(n, self.eye.pupil_area)
        center, radius, share, area_p, area_rest = self.strata
        in_p = rng.random(n) < share
        k = int(in_p.sum())
        xy = np.empty((2, n))
        xy[:, in_p] = self._disk_part(rng, k, center, radius, True)
        xy[:, ~in_p] = self._disk_part(rng, n - k, center, radius, False)
        return xy, np.where(in_p, area_p / share, area_rest / (1.0 - share))

    def camera_paths(self, rng: np.random.Generator, pix: np.ndarray, rep: np.ndarray, first: int = 0) -> PathState:
        """One sample through each of the pixels ``pix`` (n,), in replicates ``rep`` (n,); the samples are
        numbered from ``first``."""
        eye = self.eye
        w, h = eye.width, eye.height
        n = len(pix)
        jit = rng.random((2, n))
        sx = (2 * ((pix % w) + jit[0]) / w - 1) * eye.half_x
        sy = (1 - 2 * ((pix // w) + jit[1]) / h) * eye.half_y
        lens, lens_weight = self.lens_samples(rng, n)
        o, d, geo = eye.generate_rays(sx, sy, lens)
        beta = np.broadcast_to((geo * (eye.pixel_area * lens_weight / eye.extent_of(pix))).astype(F32), (3, n)).copy()
        extra = {"sample": np.arange(first, first + n), "splits": np.zeros(n, np.int8)}
        if self.world.polar is not None:  # the row vector of the eye's detector (and analyser)
            beta, pol = self.world.polar.start_camera(beta, d)
            extra |= pol
        return PathState(o, d, beta, pix, rep, np.zeros(n), np.ones(n, bool), extra)

    def _run(self, ctx, pix, rep) -> int:
        """Trace one sample through each of ``pix``, in waves of :data:`WAVE`; the samples that found light."""
        ctx.sample_found = np.zeros(len(pix), bool)
        for a in range(0, len(pix), WAVE):
            b = min(a + WAVE, len(pix))
            state = self.camera_paths(ctx.rng, pix[a:b], rep[a:b], a)
            self.truncated += trace(self, state, ctx, self.max_depth)
        return int(ctx.sample_found.sum())

    def run_batch(self, ctx):
        """A batch of at least as many paths as pixels: ``batch_size // pixels`` samples through every
        pixel, each pass a replicate. A smaller batch: one sample through each pixel of its part of a
        pass (:meth:`batch_pixels`), so that a render of a large retina can stop after any batch, with
        fewer than one sample per pixel."""
        if self.batch_size < self.npix:
            pix = self.batch_pixels(ctx.batch)
            found = self._run(ctx, pix, np.zeros(len(pix), np.int64))
            return len(pix), found, {"hit": pix, "connection": pix}, 1
        spp = self.batch_size // self.npix
        pix = np.tile(np.arange(self.npix), spp)
        rep = np.repeat(np.arange(spp), self.npix)
        found = self._run(ctx, pix, rep)
        return len(pix), found, {"hit": spp, "connection": spp}, spp

    def batch_pixels(self, index: int, size: int | None = None) -> np.ndarray:
        """The pixels (k,) of batch ``index`` where a batch of ``size`` samples (default ``batch_size``)
        is smaller than the image: a pass over the pixels is cut into ceil(pixels / size) equal parts,
        batch k takes part k mod parts of pass k // parts, and the pass visits the pixels in the order
        i * step mod pixels (step near the golden section of the pixel count and prime to it), so that
        the batches merged so far cover the image evenly, a render stopped early has its samples spread
        over the whole retina, and batch k's pixels depend on k alone (seed-addressed)."""
        n = self.npix
        parts = -(-n // (size or self.batch_size))
        size = -(-n // parts)
        if self._pass_step is None:
            step = int(round(n * 0.6180339887498949))
            while math.gcd(step, n) != 1:
                step += 1
            self._pass_step = step
        part = index % parts
        return (np.arange(part * size, min((part + 1) * size, n), dtype=np.int64) * self._pass_step) % n

    def pilot_mean(self, ctx) -> float:
        """The image's mean luminance (cd/m^2) from one sample at each of ``batch_size`` random pixels."""
        n = self.batch_size
        pix = ctx.rng.integers(0, self.npix, n)
        self._run(ctx, pix, np.zeros(n, np.int64))
        total = sum(float(luminance3(ctx.splats.gather(c)[2]).sum()) for c in self.components)
        return total / n

    # -- hooks of the path loop --------------------------------------------------------------------
    def _add(self, ctx, component: str, owner, rep, sample, value):
        lit = np.flatnonzero(luminance3(value) > 0)
        if len(lit):
            ctx.splats.add(component, owner[lit], rep[lit], take(value, lit))
            ctx.sample_found[sample[lit]] = True

    @staticmethod
    def _power_heuristic(p_a: np.ndarray, p_b: np.ndarray) -> np.ndarray:
        """p_a^2 / (p_a^2 + p_b^2), in float64 (squared densities of small sources exceed float32).
        Densities are capped at MAX_PDF, so that an infinite one (a light seen edge-on) weighs 1
        against any finite other and no square overflows."""
        p_a = np.minimum(np.asarray(p_a, np.float64), MAX_PDF)
        p_b = np.minimum(np.asarray(p_b, np.float64), MAX_PDF)
        a2, b2 = p_a * p_a, p_b * p_b
        s = a2 + b2
        return np.where(s > 0, a2 / np.where(s > 0, s, 1.0), 0.0)

    def escaped(self, state, ctx, component: str = "hit"):
        """The environment behind paths that left the scene, weighted against next-event estimation's
        samples of it (power heuristic) where their last vertex scattered; into ``component``."""
        if self.env.is_black:
            return
        value = state.beta * self.env.radiance(state.d)
        if self.nee_env:
            value = value * np.where(state.specular, 1.0, self._power_heuristic(state.pdf, self.env.pdf(state.d)))
        self._add(ctx, component, state.owner, state.rep, state.extra["sample"], value)

    def emitted(self, state, tri, p, t, ctx, component: str = "hit"):
        """The emission of light triangles ``tri`` that paths hit after a segment of length ``t``,
        weighted against next-event estimation's samples of them (power heuristic) where their last
        vertex scattered; into ``component``."""
        beta = state.beta
        if self.world.polar is not None and "stokes" in state.extra:
            beta = self.world.polar.emitted(beta, state.extra, state.d, self.lights.slot[tri])
        value = beta * self.lights.emitted(tri, state.d)
        if self.nee_lights:
            cos_y = np.abs(dot(state.d, take(self.lights.tris.normal, tri)))
            p_light = solid_angle_pdf(self.lights.pdf_power_area(tri), t, cos_y)
            value = value * np.where(state.specular, 1.0, self._power_heuristic(state.pdf, p_light))
        self._add(ctx, component, state.owner, state.rep, state.extra["sample"], value)

    def connect(self, state, it, bsdf, ctx):
        if not self.next_event:
            return None
        m = len(state)
        parts = []
        rng = ctx.rng
        accel = self.world.accel
        data = lambda ok: {"owner": state.owner[ok], "rep": state.rep[ok], "sample": state.extra["sample"][ok]}  # noqa: E731
        sampler = self._eye_sampler[id(bsdf)]
        if self.nee_lights:
            lights = self.lights
            imp = lights.importance(it.p, lambda w: bsdf.pdf(it, w))
            tri, y, pdf_area = lights.sample_direct(it.p, rng.random((3, m)), imp)
            w, dist, radiance, cos_y = lights.connection(it.p, tri, y)
            f = bsdf.eval(it, w, RADIANCE)
            p_light = solid_angle_pdf(lights.pdf_power_area(tri), dist, cos_y)
            mis = self._power_heuristic(p_light, sampler.pdf(it, w)) if self.mis_with_hits else 1.0
            g = cos_y / np.maximum(dist * dist * pdf_area, 1e-300)
            value = state.beta * f * radiance * (g * mis)
            ok = np.flatnonzero(luminance3(value) > 0)
            if len(ok):
                o, d, tmax = segment_to(accel, take(it.p, ok), take(it.ng, ok),
                                        take(y, ok), it.offset[ok])
                parts.append(Shadow(o, d, tmax, take(value, ok), data(ok)))
        if self.nee_env:
            w, radiance, p_env = self.env.sample(rng.random((2, m)))
            w = w.astype(F32)
            f = bsdf.eval(it, w, RADIANCE)
            mis = self._power_heuristic(p_env, sampler.pdf(it, w)) if self.mis_with_hits else 1.0
            value = state.beta * f * radiance * (mis / np.maximum(p_env, 1e-300))
            ok = np.flatnonzero(luminance3(value) > 0)
            if len(ok):
                w_ok = take(w, ok)
                o = accel.spawn(take(it.p, ok), take(it.ng, ok), w_ok, it.offset[ok])
                parts.append(Shadow(o, w_ok, np.full(len(ok), np.inf), take(value, ok), data(ok)))
        return Shadow.concat(parts) if parts else None

    def deliver(self, shadow, visible, ctx):
        k = np.flatnonzero(visible)
        if len(k):
            d = shadow.data
            self._add(ctx, "connection", d["owner"][k], d["rep"][k], d["sample"][k], take(shadow.value, k))

    def continue_paths(self, state, it, bsdf, ctx, nxt, sl):
        """One sample per path; at a surface with two delta branches (glass, a coating), a path that has
        split fewer than ``splits`` times follows both branches instead, each with its weight (R, and T
        or T (n_i/n_t)^2 for radiance), where the smaller branch carries at least :data:`SPLIT_MIN` of
        the two branches' flux (R against 1 - R for glass), and below that with probability share /
        SPLIT_MIN: this removes the variance of the Fresnel choice (a windshield at 67 deg reflects
        14 %: the symbol and its ghost), and leaves the choice where one branch is negligible. Either
        way the estimate is unbiased (the choice to split does not depend on what the path finds).

        The shares are the flux's, the same into and out of glass. Issue 31: they were the radiance
        weights, T/n^2 into glass and n^2 T out of it, so a plate's exit surface split only above 63
        deg of incidence (its entry at any angle), and the per-pixel error of a panel seen through a
        plate at 60 deg jumped 40-fold between two rows of the same mean; the probability's ramp
        keeps the noise continuous where a share crosses SPLIT_MIN (tests/methods/test_backward.py)."""
        sampler = self._eye_sampler[id(bsdf)]
        if self.splits == 0 or not (bsdf.delta and bsdf.flags & REFLECTION and bsdf.flags & TRANSMISSION):
            return continue_by_sampling(state, it, sampler, ctx, RADIANCE, nxt, sl)
        lobes = bsdf.lobes(it, RADIANCE)  # the branches a sample chooses from (cached by the material)
        m = len(it)
        flux = [luminance3(np.broadcast_to(weight, (3, m))) for _, weight, _, _ in bsdf.lobes(it, IMPORTANCE)]
        share = np.minimum(flux[0], flux[1]) / np.maximum(flux[0] + flux[1], 1e-30)
        both = state.extra["splits"] < self.splits
        ramp = np.flatnonzero(both & (share < SPLIT_MIN))
        if len(ramp):  # (no random numbers drawn where every share is above SPLIT_MIN)
            both[ramp] = ctx.rng.random(len(ramp)) * SPLIT_MIN < share[ramp]
        j = np.flatnonzero(both)
        # The paths that do not split sample a branch: when most split, only those (the split ones'
        # entries are written below; the random numbers are drawn for every hit either way).
        out = continue_by_sampling(state, it, sampler, ctx, RADIANCE, nxt, sl,
                                   np.flatnonzero(~both) if len(j) >= SAMPLE_UNSPLIT_ONLY * m else None)
        if len(j) == 0:
            return out
        p, ng, off = take(it.p, j), take(it.ng, j), it.offset[j]
        beta0 = take(state.beta, j)
        rows = sl.start + j  # the first branch replaces the sampled continuation
        nxt.extra["splits"][rows] += 1
        more = nxt.reserve(len(j))  # the second goes after the bounce's hits
        nxt.owner[more], nxt.rep[more] = nxt.owner[rows], nxt.rep[rows]
        for v in nxt.extra.values():
            v[..., more] = take(v, rows)
        polar = self.world.polar if "stokes" in state.extra else None
        for (wo, weight, flags, _label), at in zip(lobes, (rows, more), strict=True):
            w = take(wo, j)
            if polar is not None:  # on every hit (most split), then the split ones taken
                beta, stokes, frame = polar.scatter(state.beta, state.extra, it, bsdf, wo, weight,
                                                    np.full(m, flags, np.int8), False)
                beta = take(beta, j)
                put(nxt.extra["stokes"], at, take(stokes, j))
                put(nxt.extra["frame"], at, take(frame, j))
            else:
                beta = beta0 * take(np.broadcast_to(weight, (3, m)), j)
            put(nxt.o, at, self.world.accel.spawn(p, ng, w, off))
            put(nxt.d, at, w)
            put(nxt.beta, at, beta)
            nxt.pdf[at], nxt.specular[at], nxt.alive[at] = 0, True, luminance3(beta) > 0
        return out

    def spare(self, bsdf, hits):
        """A glass surface or coating may split every path that hits it."""
        two = bsdf.delta and bsdf.flags & REFLECTION and bsdf.flags & TRANSMISSION
        return hits if self.splits > 0 and two else 0

    def potential(self, beta):
        """A camera sample carries at most its weight times the brightest source."""
        return luminance3(beta) * self.max_luminance

    def finish(self, result):
        super().finish(result)
        mean, fewest, most = result.film.count_summary("hit")
        if isinstance(result.film.norm["hit"], np.ndarray):  # batches smaller than the image: a count per pixel
            result.extra["samples_per_pixel"] = mean
            result.extra["samples_per_pixel_range"] = [fewest, most]
        else:
            result.extra["samples_per_pixel"] = fewest
        result.extra["next_event"] = self.next_event
        film = result.film
        total = sum(float(luminance3(film.sums[c]).sum()) for c in self.components)
        if self.next_event and total > 0:
            result.extra["connection_share"] = float(luminance3(film.sums["connection"]).sum()) / total
        if self.strata is not None:
            c, r, share, area_p, area_rest = self.strata
            result.extra["exit_pupil"] = {"center_mm": [float(c[0]), float(c[1])], "radius_mm": r, "share": share,
                                          "area_inside_pupil_mm2": area_p, "area_rest_mm2": area_rest,
                                          "paper_w": share / (1 - share)}
