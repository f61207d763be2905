"""The hybrid method and the automatic choice of a method (paper sec. 4.2 and its conclusion: "automate
the process of selecting the optimal ray tracing methods and automatically merge the results").

Channels. The light a pixel receives is a sum over the sources it comes from, and transport is linear
in them, so an image splits exactly into channels by source: the HUD channel (light from the scene's
emitters: LEDs, backlights) and the environment channel (light from the environment: an HDRI panorama,
a uniform sky, a sun, and what scene objects such as a road reflect of it). Each channel is rendered
on a world that holds only its own sources (:meth:`tracer.transport.world.World.channel`: the other sources
are dark, every object still traced), by the method that suits it, on random streams of its own; the
image is the sum of the channels, and their variances add (:class:`tracer.core.film.Film` groups). No
light path can be counted twice or lost: each is counted by the channel of its source, by a method
that is unbiased (or consistent, the photon method) for it.

Choice. For a channel whose method is "auto", every method that applies to it runs a short pilot
(a share ``pilot_share`` of the budget, split between them) on a stream of its own, and is scored by
its efficiency 1 / (V x cost), cost the pilot's seconds (a budget in seconds) or ray segments (a
budget in rays, which also makes the choice reproducible). V is the largest of four medians of a
pixel's relative variance (from the pilot's replicates; a pixel that the method left dark counts as
infinitely noisy): over the pixels some pilot lit, and over the brightest half, tenth and hundredth
of them (at least 8 pixels each) in the pilots' images combined with inverse-variance weights. A
method must be good at every level of the image, the typical pixel (on a HUD, mostly the black
background) as well as the brightest (the symbols, a focused spot): by the lit pixels' median
alone, backward tracing with next-event estimation wins on a screen lit directly by a small LED and,
beside that, through a lens that focuses it into a spot, which backward tracing reaches only by
chance (tests/methods/test_pilots.py). The most efficient method renders the channel with the rest of the
budget; the pilots are reported, not merged into the image. The variance of a pixel falls as 1 / N
for every method here, so V x cost does not depend on the pilot's length. A budget in seconds whose
pilot share is under :data:`tracer.methods.pilots.PILOT_FLOOR_SECONDS` runs no pilot: the rules choose
(:func:`tracer.methods.pilots.rule_choice`), and the channels keep their own batch sizes.

What applies (model no more than the scene needs; the report says what was skipped and why):

- the HUD channel: backward tracing with next-event estimation always; forward tracing where the
  scene has emitters; the photon method only where a scattering surface the eye sees is lit through
  specular optics (the brightness-theorem analysis finds the blockers), which next-event estimation
  cannot connect through; the channel is skipped without emitters, or when no pilot finds light;
- the environment channel: backward tracing (forward tracing and the photon pass emit from the lights
  only); skipped when the environment is off or black;
- the whole scene (``--method auto``, one channel): backward always; forward and photon only with a
  black environment (they do not render it).

A channel given a method (``hud_method``, ``environment_method``) is rendered with it wherever the
method can render it, the photon method included where photon maps are not needed (the channel's
``note`` says so); one that cannot skips the channel with a warning.

Every object stays traced in every channel: an object that no path of a channel reaches costs only
its share of Embree's acceleration structure, and telling exactly which are unreachable would need
the visibility this method is there to compute.

Budget. A hybrid batch is one batch of every channel, with batch sizes in proportion to the paths that
minimise the summed image's variance for the cost, n_c ~ sqrt(V_c / t_c) (V_c the channel's variance
per path, t_c its cost per path, from the pilots; the classic allocation of effort between independent
estimators); batches stay seed-addressed, so workers and clusters merge them exactly.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

import numpy as np

from ..core.film import Film
from ..core.units import luminance3
from ..scene.methods import CANDIDATES
from ..transport.path import CUT_KEY, PROBE_KEY, STILL_KEY
from .base import (
    BATCH_SHARE_OF_TIME,
    DEFAULT_BATCH,
    INTEGRATORS,
    MAX_BATCH,
    SMALLEST_BATCH,
    BatchResult,
    Budget,
    Integrator,
    RenderResult,
    register,
)
from .pilots import (
    PHOTON_NOT_NEEDED,
    PILOT_FLOOR_SECONDS,
    PILOT_SEED,
    Pilot,
    applicable,
    pilot_batch_size,
    pilot_world,
    relative_variances,
    rule_choice,
    run_pilot,
)

#: A channel of the hybrid takes part in at least this many batches of a render's expected number.
MIN_CHANNEL_BATCHES = 4


@dataclass
class Channel:
    """A part of the image by source: its name, the prefix and replicate group of its film components,
    which sources its world keeps, the method asked for ("auto" or a name) and, once prepared, the
    method chosen and the integrator that renders it."""

    name: str
    prefix: str
    world: object
    asked: str
    lights: bool
    environment: bool
    candidates: dict[str, str | None] = field(default_factory=dict)
    skipped: str | None = None
    #: What the report should know of the method given to the channel (it renders, but need not).
    note: str | None = None
    chosen: str | None = None
    chosen_by: str = ""
    integrator: Integrator | None = None
    #: The channel takes part in every ``every``-th batch of the render (its batch index k // every).
    every: int = 1
    pilots: list[Pilot] = field(default_factory=list)

    @property
    def group(self) -> str:
        return self.prefix.rstrip(".")


class _Channels(Integrator):
    """An image made of channels (module docstring); subclasses say which (:meth:`_channels`)."""

    efficiency_definition = "paths that found light / paths, over every channel"
    found_what = "found light in any channel"

    def __init__(self, world, seed, batch_size=None, options=None):
        super().__init__(world, seed, batch_size, options)
        self.channels = self._channels()
        self._resolved = self.opts.get("_resolved")
        self.components: dict[str, str] = {}
        self.groups: dict[str, str] = {}
        if self._resolved is not None:  # a worker: build what the parent decided
            for c in self.channels:
                r = self._resolved[c.name]
                c.skipped, c.chosen, c.chosen_by, c.every = r["skipped"], r["method"], r["chosen_by"], r["every"]
                if c.skipped is None:
                    c.integrator = self._make(c, c.chosen, self._seed(c), r["batch_size"])
            self._collect_components()

    def _channels(self) -> list[Channel]:
        raise NotImplementedError

    def _seed(self, c: Channel, pilot: bool = False) -> int:
        """The seed of channel ``c``'s render (or of its pilots): distinct for every channel."""
        index = self.channels.index(c)
        return (self.seed * 1_000_003 + (index + 1) * (PILOT_SEED if pilot else 1)) % (2**63 - 1)

    def _make(self, c: Channel, method: str, seed: int, batch_size: int | None) -> Integrator:
        return INTEGRATORS[method](c.world, seed, batch_size, self.scene.method_options(method))

    def _collect_components(self):
        self.components, self.groups = {}, {}
        for c in self.channels:
            if c.integrator is not None:
                for k, v in c.integrator.components.items():
                    self.components[c.prefix + k] = v
                    self.groups[c.prefix + k] = c.group

    def new_film(self) -> Film:
        return Film(self.eye.width, self.eye.height, self.components, self.groups)

    @property
    def renders_environment(self) -> bool:
        """Whether a rendered channel carries the environment (the analysis predicts what is rendered)."""
        return any(c.environment and c.integrator is not None and c.integrator.renders_environment
                   for c in self.channels)

    # -- the decisions, once per render (in the process that drives it) --------------------------
    def _unavailable(self, c: Channel) -> str | None:
        """Why channel ``c`` is not rendered at all, before any pilot (None: it may be)."""
        has_lights = c.lights and len(c.world.lights) > 0
        has_env = c.environment and not c.world.environment.is_black
        if not (has_lights or has_env):
            return {(True, False): "the scene has no emitter", (False, True): "the environment is off or black"}.get(
                (c.lights, c.environment), "the scene has no light source")
        return None

    def prepare(self, budget: Budget) -> Budget:
        """Decide, once per render: which channels are rendered, by which method (pilots where there is a
        choice), and with which batch sizes (pilots of every rendered channel where there are several)."""
        if self._resolved is not None:
            return budget
        in_rays = budget.rays is not None
        for c in self.channels:
            c.skipped = self._unavailable(c)
            if c.skipped is not None:
                continue
            c.candidates = applicable(c.world, c.lights, c.environment)
            why = c.candidates.get(c.asked, "it is not a method for this channel")
            if c.asked == "photon" and why == PHOTON_NOT_NEEDED:
                c.note = f"photon was asked for and renders it, though {why} (backward would do the same faster)"
            elif c.asked != "auto" and why is not None:
                c.skipped = f"{c.asked} was asked for, but {why}"
        live = [c for c in self.channels if c.skipped is None]
        pilot_seconds = float(self.opts["pilot_share"]) * budget.seconds if not in_rays else None
        by_rules = pilot_seconds is not None and pilot_seconds < PILOT_FLOOR_SECONDS
        # What to pilot: every method that applies to an "auto" channel, where there is more than one;
        # with several channels, also the method of each channel (the allocation needs their variances).
        # None on a short time budget: the rules choose, and the channels keep their own batch sizes.
        trials = {}
        for c in live:
            ok = [m for m in CANDIDATES if c.candidates.get(m, "") is None]
            methods = ok if c.asked == "auto" else [c.asked]
            trials[c.name] = methods if (len(methods) > 1 or len(live) > 1) and not by_rules else []
            if trials[c.name]:
                continue
            if c.asked == "auto" and len(methods) > 1:
                c.chosen, why = rule_choice(c.candidates)
                c.chosen_by = (f"rules: {why}; the budget's pilot share ({pilot_seconds:.3g} s) is under "
                               f"{PILOT_FLOOR_SECONDS:g} s, too short for pilots")
            else:
                c.chosen, c.chosen_by = methods[0], "given" if c.asked != "auto" else "the only one that applies"
        count = sum(len(t) for t in trials.values()) or 1
        share = float(self.opts["pilot_share"]) / count
        seconds = share * budget.seconds if budget.seconds is not None else None
        rays = int(share * budget.rays) if in_rays else None
        spent_rays = 0
        for c in live:
            c.pilots = [Pilot(m, why) for m, why in c.candidates.items() if why is not None and c.asked == "auto"]
            world = pilot_world(c.world)  # a coarser retina of the same field where the image is large
            for m in trials[c.name]:
                size = pilot_batch_size(m, world.eye.width * world.eye.height)
                integ = INTEGRATORS[m](world, self._seed(c, pilot=True), size, self.scene.method_options(m))
                c.pilots.append(run_pilot(integ, m, seconds, rays, in_rays))
                spent_rays += c.pilots[-1].rays
            ran = [p for p in c.pilots if p.skipped is None]
            for k, p in enumerate(ran):
                medians = relative_variances([q.image for q in ran], [q.variance for q in ran], k)
                v = p.relative_variance = None if medians is None else max(medians.values())
                p.relative_variance_medians = medians
                p.efficiency = 0.0 if (v is None or not math.isfinite(v) or p.found == 0) else \
                    1.0 / max(v * p.cost, 1e-300)
            if c.chosen is None:
                best = max(ran, key=lambda p: p.efficiency)
                if best.efficiency <= 0:
                    tried = ", ".join(f"{p.method}: {p.paths:,} paths" for p in ran)
                    c.skipped = f"no pilot found light ({tried})"
                    continue
                c.chosen, c.chosen_by = best.method, "given" if c.asked != "auto" else "pilots"
        live = [c for c in live if c.skipped is None]
        sizes = self._batch_sizes(live, budget)
        # A hybrid batch is a batch of every channel: channels that size their own batches to a time budget
        # (no pilots to allocate by) share it.
        own = budget if len(live) <= 1 or budget.seconds is None else \
            dataclasses.replace(budget, seconds=budget.seconds / len(live))
        for c in live:
            c.integrator = self._make(c, c.chosen, self._seed(c), sizes[c.name][0])
            c.every = sizes[c.name][1]
            if sizes[c.name][0] is None:
                c.integrator.fit_batch(own)
        self._collect_components()
        self._resolved = {c.name: {"skipped": c.skipped, "chosen_by": c.chosen_by, "method": c.chosen,
                                   "batch_size": c.integrator.batch_size if c.integrator else None,
                                   "every": c.every} for c in self.channels}
        if in_rays:
            return Budget(rays=max(1, budget.rays - spent_rays), seconds=budget.seconds)
        return budget

    def _batch_sizes(self, live: list[Channel], budget: Budget) -> dict[str, tuple[int | None, int]]:
        """(paths per batch, every how many batches) of each channel (module docstring, Budget).

        One channel: the method's own batch (None: its default, or sized to a time budget), every batch.
        Several: n_c ~ sqrt(w_c / t_c) units of work per hybrid batch, which minimises the summed image's
        relative variance for the batch's cost: w_c = sum over pixels of the channel's pilot variance
        times its units, over the square of the pixel's summed luminance (so that a bright sky does not
        starve the HUD's symbols), t_c the cost per unit. The hybrid batch costs a default batch of the
        costliest channel, or a share of a time budget. A channel whose n_c is below its smallest batch
        (a backward batch covers every pixel once; a photon batch keeps its default size, for which its
        gather radius shrinks batch by batch) takes part in every m-th hybrid batch only, m = smallest
        batch / n_c; every channel keeps at least MIN_CHANNEL_BATCHES of the render's expected batches
        (its variance comes from the spread of its replicates)."""
        own = {c.name: ((None if self.auto_batch else self.batch_size), 1) for c in live}
        if len(live) <= 1:
            return own
        pilot = {c.name: next((p for p in c.pilots if p.method == c.chosen and p.skipped is None), None) for c in live}
        if any(p is None or p.cost <= 0 or p.units <= 0 for p in pilot.values()):
            return own
        total = sum(p.image for p in pilot.values())
        weight = np.divide(1.0, total * total, out=np.zeros_like(total), where=total > 0)
        t = {k: p.cost / p.units for k, p in pilot.items()}
        w = {k: float((p.variance * weight).sum()) * p.units for k, p in pilot.items()}
        n = {k: math.sqrt(max(w[k], 1e-300) / t[k]) for k in pilot}
        target = max(t.values()) * DEFAULT_BATCH
        if budget.rays is None:
            target = min(target, BATCH_SHARE_OF_TIME * budget.seconds)
        scale = target / sum(n[k] * t[k] for k in n)
        pixels = self.eye.width * self.eye.height
        out = {}
        for c in live:
            want = n[c.name] * scale
            smallest = {"backward": max(SMALLEST_BATCH, pixels), "photon": DEFAULT_BATCH}.get(c.chosen, SMALLEST_BATCH)
            if c.chosen != "photon" and want >= smallest:
                out[c.name] = (int(min(MAX_BATCH, round(want))), 1)
            else:
                out[c.name] = (smallest, max(1, round(smallest / max(want, 1e-9))))
        left = (budget.rays if budget.rays is not None else budget.seconds) * (1 - float(self.opts["pilot_share"]))
        per_batch = sum(b * t[k] / every for k, (b, every) in out.items())
        cap = max(1, int(left / max(per_batch, 1e-300)) // MIN_CHANNEL_BATCHES)
        return {k: (b, min(every, cap)) for k, (b, every) in out.items()}

    def fit_batch(self, budget: Budget):
        """Channels size their own batches (:meth:`prepare`)."""

    def worker_options(self) -> dict:
        return dict(self.opts) | {"_resolved": self._resolved}

    # -- batches -----------------------------------------------------------------------------------
    @property
    def reference_luminance(self) -> float:
        """The channels' roulette references, summed (each channel's integrator uses its own)."""
        return sum(c.integrator.reference_luminance for c in self.channels if c.integrator is not None)

    def trace_batch(self, index: int) -> BatchResult:
        """Batch ``index`` of every channel, merged into one film (components "<prefix><name>", one
        replicate group per channel); each channel's figures are kept apart in ``extra``."""
        names, sums, norms, sq, groups = [], [], [], [], {}
        total = BatchResult(index, None, 0, 0, 0, 0, 0.0, {}, {})
        for c in self.channels:
            if c.integrator is None or index % c.every:
                continue
            b = c.integrator.trace_batch(index // c.every)
            c_names, c_sums, c_norms, c_sq, c_groups = b.film  # one group, "": the channel's own
            names += [c.prefix + k for k in c_names]
            sums, norms, sq = sums + c_sums, norms + c_norms, sq + c_sq
            groups[c.group] = c_groups[""]
            total.paths += b.paths
            total.found += b.found
            total.rays += b.rays
            total.truncated += b.truncated
            total.seconds += b.seconds
            for k, v in b.stages.items():
                total.stages[k] = total.stages.get(k, 0.0) + v
            for k, v in b.extra.items():
                if k.startswith(PROBE_KEY + ":"):  # the max-depth probe's tally, per component
                    k = f"{PROBE_KEY}:{c.prefix}{k[len(PROBE_KEY) + 1:]}"
                elif k not in (CUT_KEY, STILL_KEY):
                    k = c.prefix + k
                total.extra[k] = total.extra.get(k, 0) + v
            for k, v in (("rays", b.rays), ("paths", b.paths), ("found", b.found), ("seconds", b.seconds)):
                total.extra[f"channel_{k}:{c.name}"] = v
        total.film = (names, sums, norms, sq, groups)
        return total

    def run_batch(self, ctx):
        raise NotImplementedError("channels trace their own batches (trace_batch)")

    # -- the report --------------------------------------------------------------------------------
    def traced(self, result: RenderResult) -> str:
        """The render's paths and its pilots' (not merged into the image, but traced and searched)."""
        pilots = [p for c in self.channels for p in c.pilots]
        paths, rays = sum(p.paths for p in pilots), sum(p.rays for p in pilots)
        said = super().traced(result)
        return f"{said}, its pilots {paths:,} paths ({rays:,} rays)," if paths else said

    def finish(self, result: RenderResult):
        extra, film = result.extra, result.film
        channels = {}
        for c in self.channels:
            entry = {"method": c.chosen if c.skipped is None else None, "asked": c.asked,
                     "chosen_by": c.chosen_by or None, "skipped": c.skipped, "note": c.note,
                     # what the channel's world holds: auto's one channel keeps both, of a scene that may lack one
                     "sources": [s for s, on in (("emitters", c.lights and len(c.world.lights) > 0),
                                                 ("environment", c.environment and not c.world.environment.is_black))
                                 if on],
                     "pilots": [p.summary() for p in c.pilots]}
            if c.integrator is not None:
                # the channel's luminance summed over the film's layout (cd/m^2): the image's sum without
                # making the (H, W) image; divided by every pixel, as the components' means are
                y_sum = float(luminance3(film.layout_rgb(c.group)).sum())
                figures = {k: extra.pop(f"channel_{k}:{c.name}", 0) for k in ("rays", "paths", "found", "seconds")}
                entry |= figures | {"batch_size": c.integrator.batch_size, "every": c.every,
                                    "efficiency": figures["found"] / figures["paths"] if figures["paths"] else 0.0,
                                    "mean_cd_m2": y_sum / film.pixels,
                                    "mean_standard_error_cd_m2": film.mean_standard_error(c.group),
                                    "warnings": list(c.integrator.warnings)}
                result.warnings += [f"{c.name} channel: {w}" for w in c.integrator.warnings]
            elif c.skipped is not None and (c.asked != "auto" or any(p.paths for p in c.pilots)):
                # the method asked for cannot render it, or its pilots ran and found nothing
                result.warnings.append(f"{c.name} channel skipped: {c.skipped}")
            channels[c.name] = entry
        extra["channels"] = channels
        super().finish(result)


@register
class HybridTracer(_Channels):
    """The hybrid method: the HUD channel and the environment channel (module docstring)."""

    name = "hybrid"
    summary = ("channels by source (the HUD's emitters, the environment), each rendered by the method that suits it, "
               "chosen by pilots, summed into one image (paper sec. 4.2)")
    components = {}

    def _channels(self) -> list[Channel]:
        w = self.world
        return [Channel("hud", "hud.", w.channel(environment=False), self.opts["hud_method"], True, False),
                Channel("environment", "environment.", w.channel(lights=False), self.opts["environment_method"],
                        False, True)]


@register
class AutoTracer(_Channels):
    """The method chosen for the whole scene by pilots (module docstring): one channel, every source."""

    name = "auto"
    summary = "the most efficient method for the scene, chosen by short pilots of every method that applies"
    components = {}

    def _channels(self) -> list[Channel]:
        return [Channel("scene", "", self.world, "auto", True, True)]
