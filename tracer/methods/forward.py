"""Forward stochastic ray tracing from the light sources into the eye (paper sec. 2, Fig. 3; sec. 4.2).

Particles leave the lights (a light triangle is chosen with probability proportional to its flux, a
point uniformly on it, a direction from the Lambertian law) and carry flux through the optics on the
path loop (:mod:`tracer.transport.path`). A particle that crosses the eye pupil from the front is
imaged by the thin lens onto the retina and adds its flux to one pixel; flux over the pixel's
geometric extent is the apparent luminance (:mod:`tracer.transport.eye`), so forward and backward estimate the
same number.

The paper's directed split (sec. 2): an emitter or a scattering surface with an ``aim`` draws, with
probability w, a direction toward its target aperture and otherwise from its own law, with the
one-sample mixture weight (:class:`tracer.optics.aimed.Aimed`), unbiased for every w in [0, 1).
"""

from __future__ import annotations

import numpy as np

from ..core.units import luminance3
from ..core.vec import F32, take
from ..optics.aimed import Aimed, CosineEmission
from ..optics.bsdf import IMPORTANCE, Interaction
from ..transport.path import PathMethod, PathState, continue_by_sampling, trace
from .base import WAVE, Integrator, facing_hint, register

#: Replicates per batch: particles are dealt round-robin into this many groups (tracer.core.film).
REPLICATES = 8
#: An emitter that a render's particles, emitted in proportion to flux, leave with fewer than this
#: many is named in a warning: beside a source 1e18 times as bright, a panel renders black, 0 +- 0.
STARVED_PARTICLES = 100


class Particles:
    """Particles leaving the lights, and the samplers that carry them on (forward tracing, the photon
    pass): a light triangle chosen with probability proportional to its flux, a point uniformly on it,
    a direction from the Lambertian law, and the paper's directed split (sec. 2) where an emitter or a
    scattering surface has an ``aim`` (:class:`tracer.optics.aimed.Aimed`)."""

    def __init__(self, world):
        self.world = world
        self.lights = world.lights
        slots = len(world.scene.objects)
        self._sampler = world.aimed_samplers(lambda o: o.material.aim)
        aims = {o.slot: (world.target(o.emission.aim.target), o.emission.aim.share, o.emission.aim.mode)
                for o in self.lights.objects if o.emission.aim is not None and o.emission.aim.share > 0}
        self.emission = Aimed(CosineEmission(), aims, slots)

    def sampler(self, bsdf):
        """The sampler of material ``bsdf`` for particles: the material, or its aimed mixture."""
        return self._sampler[id(bsdf)]

    def emit(self, rng: np.random.Generator, n: int, first: int, replicates: int) -> tuple[PathState, np.ndarray]:
        """n particles numbered from ``first``, dealt round-robin into ``replicates``: a state with flux
        weights (cd/m^2 mm^2 sr) and the particles' starting points (3, k) mm; particles whose direction
        sample failed are dropped."""
        lights = self.lights
        tri, points, normal, pdf_pos = lights.sample_emission(rng.random((4, n)))
        it = Interaction(-normal, points, normal, normal, None, lights.slot[tri])
        s = self.emission.sample(it, rng.random((self.emission.dims, n), F32), IMPORTANCE)
        beta = (take(lights.radiance, tri) * (np.pi * s.weight / pdf_pos)).astype(F32)
        alive = np.flatnonzero((s.flags != 0) & (luminance3(beta) > 0))
        wo = take(s.wo, alive)
        start = take(points, alive)
        o = self.world.accel.spawn(start, take(normal, alive), wo)
        pid = first + alive
        beta = take(beta, alive)
        polar = self.world.polar
        extra = polar.start_light(beta, wo, lights.slot[tri[alive]]) if polar is not None else {}
        state = PathState(o, wo, beta, pid, pid % replicates, s.pdf[alive], np.zeros(len(alive), bool), extra)
        return state, start


@register
class ForwardTracer(Integrator, PathMethod):
    name = "forward"
    noise_advice = (", or use the backward method, whose next-event estimation suits sources that a scattering "
                    "surface sees directly")
    renders_environment = False
    summary = "sources -> optics -> pupil -> retina (paper sec. 2, directed split)"
    components = {"light": "particles emitted"}
    mode = IMPORTANCE
    efficiency_definition = "particles that reached the retina / particles emitted"
    found_what = "reached the retina"

    #: What the pilot measures besides the reference: its efficiency (:meth:`pilot_mean`).
    PILOT_STATE = ("pilot_efficiency",)

    def __init__(self, world, seed, batch_size=None, options=None):
        super().__init__(world, seed, batch_size, options)
        w = self.world
        self.lights = w.lights
        if self.lights.total_flux_lm <= 0 and not w.environment.is_black:
            self.warnings.append("the scene's only light is its environment, which forward tracing does not emit "
                                 "from: the image stays black; render it with the backward method")
        elif not w.environment.is_black:
            self.warnings.append("forward tracing does not emit from the environment: render it with the backward "
                                 "method, or with the hybrid method, which adds it to this method's HUD channel")
        self.particles = Particles(w)
        self.min_extent = self.eye.smallest_extent
        #: Particles on the retina per particle emitted in the pilot (tracer.methods.base).
        self.pilot_efficiency = 0.0
        #: When a list, the sensor stage appends (particle ids (k,), points (3, k) mm, reached_eye (k,)
        #: bool) for every event, so that tools can draw the sampled light paths.
        self.recorder: list | None = None

    # -- emission --------------------------------------------------------------------------------
    def emit(self, rng: np.random.Generator, n: int, first: int = 0) -> PathState:
        """n particles leaving the lights, numbered from ``first`` (:meth:`Particles.emit`)."""
        state, points = self.particles.emit(rng, n, first, REPLICATES)
        self._record(state.owner, points, np.zeros(len(state), bool))
        return state

    def run_batch(self, ctx):
        n = self.batch_size
        if self.lights.total_flux_lm <= 0 or self.world.accel is None:
            return n, 0, {"light": n}, REPLICATES
        for a in range(0, n, WAVE):
            state = self.emit(ctx.rng, min(WAVE, n - a), a)
            self.truncated += trace(self, state, ctx, self.max_depth)
        return n, ctx.found, {"light": n}, REPLICATES

    def pilot_mean(self, ctx) -> float:
        """The image's mean luminance (cd/m^2) from a batch of ``batch_size`` particles; also keeps the
        pilot's efficiency (particles on the retina per particle emitted) for :meth:`potential`."""
        n, found, _, _ = self.run_batch(ctx)
        self.pilot_efficiency = found / n
        _, _, values = ctx.splats.gather("light")
        return float(luminance3(values).sum()) / (n * self.eye.width * self.eye.height)

    # -- hooks of the path loop --------------------------------------------------------------------
    def sensor(self, state, t, ctx):
        eye = self.eye
        t_eye, lens = eye.pupil_hit(state.o, state.d)
        at = t_eye < t
        if self.recorder is not None:
            end = np.where(at, t_eye, np.where(np.isfinite(t), t, 0.0))
            self._record(state.owner, state.o + end * state.d, at)
        k = np.flatnonzero(at)
        if len(k):
            sx, sy = eye.retina_point(take(lens, k), take(state.d, k))
            pix = eye.pixel_of(sx, sy)
            ok = pix >= 0
            k, pix = k[ok], pix[ok]
            ctx.found += len(k)
            arrived = state.take(k)
            value = arrived.beta
            polar = self.world.polar
            if polar is not None:  # the eye's detector (and its analyser) takes the Stokes vector
                value = polar.detect(value, arrived.extra, arrived.d)
            ctx.splats.add("light", pix, arrived.rep, value / eye.extent_of(pix))
        return at

    def continue_paths(self, state, it, bsdf, ctx, nxt, sl):
        return continue_by_sampling(state, it, self.particles.sampler(bsdf), ctx, IMPORTANCE, nxt, sl)

    def potential(self, beta):
        """The luminance a particle stands for as a sample of its pixel: landing, it adds at most its flux
        over the smallest pixel extent over the batch's N particles, and a pixel receives about
        N efficiency / pixels of them; so flux x efficiency / (smallest extent x pixels), whatever N."""
        return luminance3(beta) * (self.pilot_efficiency / (self.min_extent * self.eye.width * self.eye.height))

    # -- light paths for display -----------------------------------------------------------------
    def _record(self, pid: np.ndarray, points: np.ndarray, at_eye: np.ndarray):
        if self.recorder is not None:
            self.recorder.append((pid.copy(), np.ascontiguousarray(points.T), at_eye.copy()))

    def light_paths(self, particles: int, only_to_eye: bool = True, seed_batch: int = 0) -> list[np.ndarray]:
        """Sample ``particles`` light paths and return them as polylines ((k, 3) arrays, mm, from the
        emitter to the last event), only those that reached the eye pupil by default."""
        from ..core.film import Splats
        from ..core.sampling import make_rng
        from ..transport.path import Context, Timers

        self.recorder = []
        saved, self.batch_size = self.batch_size, particles
        try:
            self.run_batch(Context(self.world, make_rng(self.seed, seed_batch), Timers(), Splats()))
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

    def no_paths_hint(self) -> str:
        """What to do where none of the sampled light paths reached the eye pupil: an emitter that faces away
        (:func:`tracer.methods.base.facing_hint`), and what to aim its emission at: a Lambertian emitter
        sends about (pupil area) / (pi d^2) of its particles into a pupil at distance d (1e-6 for a 4 mm pupil
        1 m away), and where its light reaches the eye through mirrors or lenses, aiming at the eye misses:
        the first optic on the way is the target (the optic's aperture, or the pupil's image through it)."""
        emitters = [o for o in self.scene.objects if o.emission is not None]
        unaimed = [o.name for o in emitters if o.emission.aim is None]
        to_eye = [o.name for o in emitters if o.emission.aim is not None and o.emission.aim.target == "eye"]
        parts = [facing_hint(self.world).removeprefix("; ")]
        if unaimed:
            parts.append(f"{', '.join(repr(n) for n in unaimed[:5])} emit{'s' if len(unaimed) == 1 else ''} without "
                         "an aim, so about (pupil area) / (pi d^2) of the particles reach a pupil at distance d (one "
                         "in a million for 4 mm at 1 m): give the emission an aim (scene.json emission.aim; in "
                         "Blender the emitter's Emission > Aim)")
        if to_eye or unaimed:
            parts.append("where the light reaches the eye through mirrors or lenses, aim at the first optic on its way "
                         "(its aperture, or the eye pupil's image through it), not at the eye; or render with the "
                         "backward method, which needs no aim")
        return "; ".join(p for p in parts if p)

    def finish(self, result):
        super().finish(result)
        result.extra["emitted_flux_lm"] = self.lights.total_flux_lm
        starved = self.starved_emitters(result.paths)
        if starved:
            names = ", ".join(f"{name} ({share:.2g} of the flux, about {expected:.3g} particles)"
                              for name, share, expected in starved[:5])
            more = f" and {len(starved) - 5} more" if len(starved) > 5 else ""
            result.warnings.append(
                f"forward tracing emits particles in proportion to flux: of its {result.paths:,} particles fewer "
                f"than {STARVED_PARTICLES} came from {names}{more}, so what they light is missing or noisy in the "
                "image, with no error bar to show it; render the scene with the backward method, which finds every "
                "emitter by its own hits")

    def starved_emitters(self, particles: int) -> list[tuple[str, float, float]]:
        """(name, share of the flux, particles expected) of every emitting object that ``particles``
        particles, emitted in proportion to flux, leave with fewer than :data:`STARVED_PARTICLES`."""
        lights = self.lights
        if lights.total_flux_lm <= 0:
            return []
        power = np.bincount(lights.slot, weights=lights.power, minlength=len(self.world.scene.objects))
        share = power / power.sum()
        return [(self.world.scene.objects[s].name, float(share[s]), float(particles * share[s]))
                for s in np.flatnonzero(power > 0).tolist() if particles * share[s] < STARVED_PARTICLES]
