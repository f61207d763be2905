"""What every light-transport method shares: options, the budget, the batch driver, the report data.

A method is a subclass of :class:`Integrator` registered by name (:func:`register`); its scene.json
options are :data:`tracer.scene.methods.METHOD_OPTIONS` under the same name (the scene loader validates
them, the Blender add-on draws them). It declares its film components and traces one batch at a time
on the path loop
(:mod:`tracer.transport.path`) over a render world (:class:`tracer.transport.world.World`).

Batches are seed-addressed: batch k draws its random numbers from ``make_rng(seed, k)`` only and
fills its own film, whose sums merge exactly, so the same seeds give the same image however batches
are distributed (over processes, over machines). Progress and cancellation cross into the tracer as
two callables, ``progress(fraction, message)`` and ``should_stop()``, checked between batches; a
viewer that shows the image while it converges (Blender's Render Result) may pass a third,
``preview(film)``, called with the merged film at most every :data:`PREVIEW_SECONDS`.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from ..core.film import Film, Splats, batch_arrays
from ..core.kept import KeptResults
from ..core.sampling import TriangleSet, cosine_hemisphere, frame_from_normal, make_rng, to_world
from ..core.units import luminance
from ..core.vec import dot, norm, take
from ..scene.methods import MAX_DEPTH
from ..transport.path import CUT_KEY, PROBE_DEPTH, PROBE_KEY, STILL_KEY, Context, Roulette, Timers
from ..transport.world import World

#: Paths per batch: the unit of work that is seed-addressed, distributed and merged.
DEFAULT_BATCH = 1 << 17
#: Paths traced together through the loop (one Embree call per bounce): a batch runs in waves of this
#: many, so that the planes of a wave stay in the processor's caches (large waves made every
#: elementwise operation stream from memory, and two processes contend for it).
WAVE = 1 << 16
#: The random stream of a method's pilot (the roulette's reference luminance): (seed, PILOT_STREAM).
PILOT_STREAM = 2**31 - 1
#: The random stream of batch k's probe of paths cut at max_depth: (seed, k, PROBE_STREAM).
PROBE_STREAM = 1
#: Paths in a pilot.
PILOT_PATHS = 1 << 14
#: The roulette pilots' results by what they depend on (:attr:`Integrator.reference_luminance`): a few
#: scenes' methods and seeds, in each process (the parent's, every worker's).
KEPT_PILOTS = KeptResults(32)
#: Replicates a pixel needs for its error bar (their spread); a render that stops with fewer says so.
MIN_REPLICATES = 2
#: With a budget in seconds and no batch size given, a batch is sized from the pilot's pace to take
#: at most this share of the budget, so that the render ends within a few percent of it (a batch is
#: never cut short: it is the unit that is seed-addressed and merged).
BATCH_SHARE_OF_TIME = 0.02
#: The smallest batch that sizing chooses, paths (the backward method also traces at least one sample
#: per pixel per batch).
MIN_BATCH = 1 << 12
#: The largest batch, paths (its planes must fit in memory many times over).
MAX_BATCH = 1 << 24
#: The smallest batch that may be asked for, paths: below it a batch costs more in fixed overhead
#: (a pass of numpy calls per bounce) than in tracing (forward, --batch-size 1: 40,000 rays in 46 s).
SMALLEST_BATCH = 1 << 10

Progress = Callable[[float, str], None]
ShouldStop = Callable[[], bool]
Preview = Callable[[Film], None]
#: A ``preview`` callable is given the merged film at most this often (seconds of wall time), so that
#: showing it costs a small share of the render.
PREVIEW_SECONDS = 1.0


#: How a render's warning about a scene without any light source begins (the add-on adds Blender's terms).
NO_LIGHT_SOURCE = "the scene has no light source"

#: Rays per side of an emitter with which :func:`facing_hint` looks at what each side sees.
FACING_RAYS = 256


def _side_sees(world, o, side: float) -> bool:
    """Whether side ``side`` (+1 the front, -1 the back) of emitter ``o`` sees anything that could pass
    its light on: the eye, unoccluded, in front of one of its faces (direct view), or, of
    :data:`FACING_RAYS` rays from points on its faces (by area) cosine-distributed about that side's
    normal (seed 0), one that hits a surface of another object whose material does not absorb
    everything."""
    tris = TriangleSet(o.triangles)
    if not tris.area.sum() > 0:
        return False
    normal = side * tris.normal
    centre = tris.v0 + (tris.e1 + tris.e2) / 3
    to_eye = np.asarray(world.eye.position, dtype=np.float64)[:, None] - centre
    facing = dot(to_eye, normal) > 0
    if facing.any():
        if world.accel is None:
            return True
        dist = norm(to_eye[:, facing])
        d = to_eye[:, facing] / dist
        o_ = world.accel.spawn(centre[:, facing], normal[:, facing], d)
        if not world.accel.occluded(o_, d.astype(np.float32), dist * (1 - 1e-9)).all():
            return True
    if world.accel is None:
        return False
    rng = make_rng(0)
    face = rng.choice(len(tris), FACING_RAYS, p=tris.area / tris.area.sum())
    p = tris.point(face, rng.random((2, FACING_RAYS)))
    n = take(normal, face)
    d = to_world(cosine_hemisphere(rng.random((2, FACING_RAYS))), *frame_from_normal(n))
    f = world.accel.intersect(world.accel.spawn(p, n, d), d.astype(np.float32)).face
    other = (f >= 0) & (world.accel.face_slot[np.maximum(f, 0)] != o.slot)
    return bool(np.any(other & (world.face_group[f] >= 0)))


def _faces_away(world, o) -> bool:
    """Whether one-sided emitter ``o`` faces the wrong way. One aimed at a target ("toward") does where
    the target's centre lies behind every one of its faces; another where its front sees nothing that
    could pass its light on while its back does (:func:`_side_sees`)."""
    aim = o.emission.aim
    if aim is not None and aim.mode == "toward":
        target = world.eye.position if aim.target == "eye" else \
            world.scene.object(aim.target).triangles.reshape(-1, 3).mean(axis=0)
        tris = TriangleSet(o.triangles)
        centre = tris.v0 + (tris.e1 + tris.e2) / 3
        return bool(np.all(dot(np.asarray(target, np.float64)[:, None] - centre, tris.normal) <= 0))
    return not _side_sees(world, o, 1.0) and _side_sees(world, o, -1.0)


def facing_hint(world) -> str:
    """Where no light was found: the one-sided emitters that face the wrong way (:func:`_faces_away`), a
    likely cause ("" where none does). In a HUD the LEDs face the optics, away from the eye: what
    decides is what the emitter is aimed at or what each of its sides sees, not where the eye is."""
    away = [o.name for o in world.scene.objects if o.emission is not None and o.emission.luminance > 0
            and not o.emission.two_sided and _faces_away(world, o)]
    if not away:
        return ""
    names = ", ".join(repr(n) for n in away)
    one = len(away) == 1
    return (f"; {names} emit{'s' if one else ''} from the front side only (where the vertices run "
            f"counter-clockwise), and {'its' if one else 'their'} front faces away from "
            f"{'its' if one else 'their'} aim or from all that could pass the light on: turn "
            f"{'it' if one else 'them'}, or give {'its' if one else 'their'} emission \"two_sided\": true")


@dataclass
class Budget:
    """Stop after ``rays`` ray segments or ``seconds`` of wall time, whichever comes first. ``since``:
    the ``time.perf_counter()`` from which the seconds count (the command line's start, so that the
    interpreter's start and the scene's loading are part of the time the user gave); by default, when
    the render begins."""

    rays: int | None = None
    seconds: float | None = None
    since: float | None = None

    def __post_init__(self):
        if self.rays is None and self.seconds is None:
            raise ValueError("a budget needs rays or seconds")
        if self.rays is not None and self.rays <= 0:
            raise ValueError("rays must be positive")
        if self.seconds is not None and not (self.seconds > 0 and math.isfinite(self.seconds)):
            raise ValueError("seconds must be positive and finite")

    def fraction(self, rays: int, seconds: float) -> float:
        parts = []
        if self.rays is not None:
            parts.append(rays / self.rays)
        if self.seconds is not None:
            parts.append(seconds / self.seconds)
        return min(1.0, max(parts))


@dataclass
class BatchResult:
    """One traced batch: its film's arrays and its figures (what workers send back)."""

    index: int
    film: tuple
    paths: int
    found: int
    rays: int
    truncated: int
    seconds: float
    stages: dict
    extra: dict = field(default_factory=dict)


@dataclass
class RenderResult:
    """The outcome of one render: the film plus the figures that go into report.json."""

    method: str
    seed: int
    film: Film
    rays: int
    paths: int
    found: int
    seconds: float
    partial: bool
    batches: int
    warnings: list[str] = field(default_factory=list)
    extra: dict = field(default_factory=dict)
    stages: dict = field(default_factory=dict)

    @property
    def efficiency(self) -> float:
        """Paths that carried light to the retina (forward) or found a source (backward) / paths."""
        return self.found / self.paths if self.paths else 0.0

    @property
    def rays_per_second(self) -> float:
        return self.rays / self.seconds if self.seconds > 0 else 0.0


INTEGRATORS: dict[str, type[Integrator]] = {}


def register(cls):
    """Class decorator: make a method available by its ``name`` (CLI, scene files, add-on)."""
    INTEGRATORS[cls.name] = cls
    return cls


class Integrator:
    """Base of all methods. Subclasses set ``name``, ``summary``, ``components`` and implement
    :meth:`run_batch`; their options are the scene's (``METHOD_OPTIONS[name]``).

    Parameters
    ----------
    world : the render world (or a Scene, from which one is built).
    seed : the user's seed. batch_size : paths per batch. options : validated options (default:
    the scene's own for this method).
    """

    name = ""
    summary = ""
    #: Film components: name -> what normalises it.
    components: dict[str, str] = {}
    #: What "efficiency" counts, for the report.
    efficiency_definition = ""
    #: The end of the noise warning: when another method would suit the scene better (", or ...").
    noise_advice = ""
    #: Whether the method's image includes light from the environment (the brightness-theorem
    #: analysis predicts only what the method renders).
    renders_environment = True

    def __init__(self, world, seed: int, batch_size: int | None = None, options: dict | None = None):
        if not isinstance(world, World):
            world = World(world)
        if batch_size is not None and not SMALLEST_BATCH <= int(batch_size) <= MAX_BATCH:
            raise ValueError(f"batch size must lie in [{SMALLEST_BATCH}, {MAX_BATCH}], got {batch_size}")
        if not 0 <= int(seed) < 2**63:
            raise ValueError(f"seed must lie in [0, 2^63), got {seed}")
        self.world = world
        self.scene = world.scene
        self.eye = world.eye
        self.seed = int(seed)
        #: None given: DEFAULT_BATCH, or smaller for a short time budget (:meth:`fit_batch`).
        self.auto_batch = batch_size is None
        self.batch_size = DEFAULT_BATCH if batch_size is None else int(batch_size)
        self.pilot_seconds = 0.0
        self.opts = options if options is not None else self.scene.method_options(self.name)
        self.max_depth = self.opts.get("max_depth", MAX_DEPTH.default)  # methods of methods have none
        self.warnings: list[str] = []
        self.truncated = 0
        self._reference = None
        self.pilot_rays = 0
        #: Hears, where given (``notice(message)``), what the method finds before its first batch and
        #: also puts in ``warnings``: the command line prints it at once, Blender reports it.
        self.notice = None

    def warn_early(self, message: str):
        """A warning known before the first batch: into ``warnings`` (the report) and to ``notice``."""
        self.warnings.append(message)
        if self.notice is not None:
            self.notice(message)

    # -- the batch -------------------------------------------------------------------------------
    def run_batch(self, ctx: Context) -> tuple[int, int, dict[str, int], int]:
        """Trace one batch into ``ctx.splats``; return (paths, paths that found light, the batch's
        normaliser total per component, number of replicates)."""
        raise NotImplementedError

    def pilot_mean(self, ctx: Context) -> float:
        """An unbiased estimate of the image's mean luminance (cd/m^2) from a pilot batch of
        ``batch_size`` = :data:`PILOT_PATHS` paths traced without roulette into ``ctx``."""
        raise NotImplementedError

    @property
    def reference_luminance(self) -> float:
        """The roulette's reference (cd/m^2): the image's mean luminance estimated by a pilot of
        :data:`PILOT_PATHS` paths without roulette, on the seed's own pilot stream (the same in every
        process, so batches stay seed-addressed). The pilot depends on the scene (its hash), the eye,
        the method, its options and the seed alone, so a process keeps it (:data:`KEPT_PILOTS`, with
        what it set: :attr:`PILOT_STATE`, its warnings, its time and rays) for the next render of the
        same (F12 after F12 in Blender, a worker's next render)."""
        if self._reference is None:
            key = (*self.world.key, type(self).__qualname__, self.seed, repr(sorted(self.opts.items())))
            kept = KEPT_PILOTS.get(key, self._run_pilot)
            self._reference, self.pilot_seconds, self.pilot_rays, state, warnings = kept
            for name, value in state.items():
                setattr(self, name, value)
            self.warnings += [w for w in warnings if w not in self.warnings]
        return self._reference

    @property
    def has_reference(self) -> bool:
        """Whether this integrator has its roulette reference already (traced or kept)."""
        return self._reference is not None

    #: The attributes a method's pilot sets besides the reference (kept and restored with it).
    PILOT_STATE: tuple[str, ...] = ()

    def _run_pilot(self) -> tuple:
        """Run the pilot: (reference cd/m^2, its seconds, its rays, :attr:`PILOT_STATE`'s values, the
        warnings it added)."""
        saved, truncated, warned = self.batch_size, self.truncated, len(self.warnings)
        self.batch_size = PILOT_PATHS
        rays0 = self.world.rays_traced
        t0 = time.perf_counter()
        try:
            ctx = Context(self.world, make_rng(self.seed, PILOT_STREAM), Timers(), Splats(), None)
            reference = self.pilot_mean(ctx)
        finally:
            self.batch_size, self.truncated = saved, truncated
        return (reference, time.perf_counter() - t0, self.world.rays_traced - rays0,
                {name: getattr(self, name) for name in self.PILOT_STATE}, list(self.warnings[warned:]))

    def new_film(self) -> Film:
        """An empty film for this method's components (a batch's, or the render's)."""
        return Film(self.eye.width, self.eye.height, self.components)

    def prepare(self, budget: Budget) -> Budget:
        """Everything a render decides once, before its first batch, in the process that drives it
        (never in a worker): the batch size for a time budget (:meth:`fit_batch`); a method that runs
        pilots to choose (tracer.methods.auto) does so here. Returns the budget the batches may
        spend (what its pilots already spent taken off)."""
        self.fit_batch(budget)
        return budget

    def worker_options(self) -> dict:
        """The options with which a worker process builds an integrator that traces this render's very
        batches (after :meth:`prepare`: what it decided is in them)."""
        return self.opts

    def fit_batch(self, budget: Budget):
        """With a budget in seconds and no batch size given, size batches from the pilot's pace (paths
        per second, without roulette: an underestimate) so that one takes at most
        :data:`BATCH_SHARE_OF_TIME` of the budget; between :data:`MIN_BATCH` and :data:`DEFAULT_BATCH`."""
        if not self.auto_batch or budget.seconds is None:
            return
        self.reference_luminance  # noqa: B018  (runs and times the pilot once)
        pace = PILOT_PATHS / max(self.pilot_seconds, 1e-6)
        fitted = int(pace * budget.seconds * BATCH_SHARE_OF_TIME)
        self.batch_size = int(min(DEFAULT_BATCH, max(MIN_BATCH, fitted)))

    def trace_batch(self, index: int) -> BatchResult:
        """Trace batch ``index`` into a film of its own: what :func:`drive` merges, in this process or
        in a worker."""
        reference = self.reference_luminance
        t0 = time.perf_counter()
        timers = Timers()
        ctx = Context(self.world, make_rng(self.seed, index), timers, Splats(), Roulette(reference),
                      probe_rng=make_rng(self.seed, index, PROBE_STREAM), batch=index)
        rays_before, truncated_before = self.world.rays_traced, self.truncated
        paths, found, norms, reps = self.run_batch(ctx)
        with timers("film"):
            film = batch_arrays(list(self.components), self.eye.width * self.eye.height, ctx.splats, reps, norms)
        seconds = time.perf_counter() - t0
        return BatchResult(index, film, paths, found, self.world.rays_traced - rays_before,
                           self.truncated - truncated_before, seconds, timers.report(seconds), dict(ctx.store))

    def render(self, budget: Budget, progress: Progress | None = None, should_stop: ShouldStop | None = None,
               preview: Preview | None = None) -> RenderResult:
        """Render in this process: the batches run one at a time through the same driver, and the
        same merge, as on several processes (tracer.runtime.parallel) or a cluster (tracer.runtime.distributed)."""
        started = time.perf_counter() if budget.since is None else budget.since
        budget = self.prepare(budget)
        return drive(self, budget, LocalExecutor(self), 1, progress, should_stop, started=started, preview=preview)

    def merge_extra(self, total: dict, batch: dict):
        """Fold a batch's ``extra`` figures into the render's (default: add numbers)."""
        for k, v in batch.items():
            total[k] = total.get(k, 0) + v

    def traced(self, result: RenderResult) -> str:
        """What the render traced, for its warnings: "<method> traced P paths (R rays)"."""
        return f"{result.method} traced {result.paths:,} paths ({result.rays:,} rays)"

    def finish(self, result: RenderResult):
        """Add method-specific warnings and figures to a finished result."""
        result.extra["roulette"] = {"reference_luminance_cd_m2": self.reference_luminance,
                                    "threshold_cd_m2": Roulette(self.reference_luminance).threshold,
                                    "pilot_rays": self.pilot_rays}
        dark = self.world.dark
        if result.found == 0 and dark:
            result.warnings.append(
                f"{NO_LIGHT_SOURCE} (no object with an emission block of positive luminance, no lit "
                "environment): the image is black because the scene is dark")
        elif result.found == 0:
            result.warnings.append(
                f"no light path found: {self.traced(result)} and none {self.found_what} (efficiency "
                f"{result.efficiency:.3g}): the scene has light, so either none of it reaches the eye or this "
                "method cannot find it (try the other method, or more rays)" + facing_hint(self.world))
        elif result.found < 100:
            result.warnings.append(
                f"only {result.found} of {result.paths:,} paths found light (efficiency {result.efficiency:.3g}): "
                "the image is dominated by noise")
        film = result.film
        # a scene without a light source stops after one batch (drive): more samples would not help it
        counts = film.sample_counts() if result.batches and not dark else None
        if counts is not None and counts.min() < MIN_REPLICATES:  # batches covered part of the image
            few = int((counts < MIN_REPLICATES).sum())
            none = int((counts == 0).sum())
            result.warnings.append(
                f"the render stopped at {float(counts.mean()):.2f} samples per pixel: {few:,} of {counts.size:,} "
                f"pixels hold fewer than {MIN_REPLICATES}, so their Y_var reads 0 and the standard errors leave "
                "them out"
                + (f"; {none:,} hold none and show their nearest sampled neighbour's value" if none else "")
                + "; render longer for error bars on every pixel")
        elif result.batches and not dark and film.groups and film.fewest_replicates < MIN_REPLICATES:  # stopped early
            result.warnings.append(
                f"the error bars are not measured: the film holds {film.fewest_replicates} replicate(s) where their "
                f"spread needs {MIN_REPLICATES}, so every standard error and Y_var reads 0; render longer")
        self._report_cut(result)

    def _report_cut(self, result: RenderResult):
        """The light of paths cut at max_depth, as the probe measured it (tracer.transport.path.probe_cut),
        in ``extra["max_depth_cut"]``; a warning where it exceeds twice the image mean's standard error."""
        cut = result.extra.pop(CUT_KEY, 0)
        still = result.extra.pop(STILL_KEY, 0)
        sums = {k.split(":", 1)[1]: result.extra.pop(k) for k in list(result.extra) if k.startswith(PROBE_KEY + ":")}
        if not cut:
            return
        film = result.film
        npix = film.width * film.height
        counts = {c: film.count_summary(c)[0] if c in film.norm else 0.0 for c in sums}  # the mean per pixel
        missing = sum(v / counts[c] for c, v in sums.items() if counts[c] > 0) / npix
        mean = float(luminance(film.rgb()).mean())
        se = film.mean_standard_error()
        result.extra["max_depth_cut"] = {
            "paths": int(cut), "probe_segments": PROBE_DEPTH, "still_going_after_probe": int(still),
            "missing_luminance_cd_m2": missing, "missing_share_of_mean": missing / mean if mean > 0 else None,
            "missing_is_lower_bound": still > 0, "image_mean_standard_error_cd_m2": se}
        if missing > 2 * se:
            share = f" ({missing / mean:.2%} of it)" if mean > 0 else ""
            against = f", {missing / se:.1f} times its standard error" if se > 0 else ""
            trapped = (f"; {still:,} of them were still going after those segments (trapped, as between the faces "
                       "of glass or the walls of a closed room), so the bias may be larger" if still else "")
            result.warnings.append(
                f"{cut:,} {self.probed_paths} were cut at methods.{self.name}.max_depth = {self.max_depth}; followed "
                f"{PROBE_DEPTH} segments further they add {'at least ' if still else ''}{missing:.3g} cd/m^2 to the "
                f"image mean{share}{against}: the image "
                f"is biased low; raise max_depth{trapped}")

    found_what = "found light"
    #: What the max-depth probe follows (its warning's noun).
    probed_paths = "paths"


class LocalExecutor:
    """Batches traced in this process, one at a time, when the driver asks for them."""

    def __init__(self, integrator: Integrator):
        self.integrator = integrator

    def submit(self, index: int):
        return index

    def wait(self, handles: dict, timeout: float | None) -> list[int]:
        k = min(handles)
        handles[k] = self.integrator.trace_batch(k)
        return [k]

    def result(self, handle):
        return handle


def drive(local: Integrator, budget: Budget, executor, in_flight: int, progress: Progress | None = None,
          should_stop: ShouldStop | None = None, label: str = "", started: float | None = None,
          preview: Preview | None = None) -> RenderResult:
    """Hand out batch indices in increasing order to ``executor`` (``submit(k)`` -> handle,
    ``wait(handles, timeout)`` -> indices done, ``result(handle)`` -> BatchResult), keep at most
    ``in_flight`` running, and merge the contiguous prefix of finished batches in batch order until
    the budget is met. Each batch fills its own film and films are added in batch order, so one
    process, several, or a cluster give the same image for a budget in rays.

    No batch is issued that cannot land within the budget: with a budget in seconds, none once the
    time left is shorter than a batch takes; with a budget in rays, none beyond the rays that the
    merged and running batches will already bring (estimated from the finished ones). When the
    budget is met, batches still running are dropped, not awaited; but however short the budget, one
    batch is merged, so that an image is never empty for lack of time (a batch may cover part of the
    image: its error bars then hold where pixels have two samples, and the report says how many do not).
    A time budget counts
    from ``started`` (``time.perf_counter()`` when the render began: the pilot and the workers'
    start-up are part of the wall time the user gave), by default from now. ``preview(film)`` is
    called with the merged film after a merge, at most every :data:`PREVIEW_SECONDS` (not after the
    last: the caller has the result)."""
    method = f"{local.name} {label}" if label else local.name
    done: dict[int, BatchResult] = {}
    pending: dict[int, object] = {}
    film = local.new_film()
    rays = paths = found = truncated = merged = next_index = 0
    stages = Timers()
    extra: dict = {}
    batch_seconds: list[float] = []
    batch_rays: list[int] = []
    issued = None  # seconds from the start when the first batch was handed out
    shown = -math.inf  # when the last preview was shown
    partial = False
    start = time.perf_counter() if started is None else started
    setup = time.perf_counter() - start  # the pilot, the workers' start-up

    workers = getattr(executor, "workers", 1)
    # A scene without any light source: its first batch says so, and the budget would be spent on a black
    # image (Blender's startup scene traced its 10 s)
    dark = local.world.dark

    def short() -> bool:
        """No batch merged yet: a render holds at least one, however short its budget."""
        return merged == 0

    def met() -> bool:
        return not short() and budget.fraction(rays, time.perf_counter() - start) >= 1.0

    def worth_issuing() -> bool:
        if not batch_seconds:
            return next_index < in_flight
        if budget.seconds is not None:
            # A batch issued now starts when the ones ahead of it have run on ``workers`` processes.
            finish = (time.perf_counter() - start) + float(np.median(batch_seconds)) * (len(pending) // workers + 1)
            if finish > budget.seconds:
                return False
        if budget.rays is not None:
            coming = rays + sum(b.rays for b in done.values()) + len(pending) * float(np.median(batch_rays))
            return coming < budget.rays
        return True

    while True:
        if met():
            break  # batches still in flight would land beyond the budget: dropped, not awaited
        if should_stop is not None and should_stop():
            partial = True
            break
        if issued is None:
            issued = time.perf_counter() - start
        while len(pending) < in_flight and worth_issuing():
            pending[next_index] = executor.submit(next_index)
            next_index += 1
        if not pending:
            if budget.seconds is not None and budget.rays is None and not short():
                break  # no batch can finish within the time left
            pending[next_index] = executor.submit(next_index)
            next_index += 1
        left = None if budget.seconds is None else max(0.0, budget.seconds - (time.perf_counter() - start))
        timeout = 0.25 if left is None else min(0.25, left + 1e-3)
        for k in executor.wait(pending, timeout):
            done[k] = executor.result(pending.pop(k))
            batch_seconds.append(done[k].seconds)
            batch_rays.append(done[k].rays)
        while merged in done and not met():
            b = done.pop(merged)
            film.merge_arrays(b.film)
            paths, found, rays, truncated = paths + b.paths, found + b.found, rays + b.rays, truncated + b.truncated
            stages.add(b.stages)
            local.merge_extra(extra, b.extra)
            merged += 1
            if progress is not None:
                el = time.perf_counter() - start
                eff = found / paths if paths else 0.0
                progress(budget.fraction(rays, el), f"{method}: {rays:,} rays, efficiency {eff:.2e}, {el:.1f} s")
        if preview is not None and merged > 0 and not met() and time.perf_counter() - shown >= PREVIEW_SECONDS:
            preview(film)
            shown = time.perf_counter()
        if (rays == 0 or dark) and merged > 0:
            break  # nothing to trace, or no light source to find (the image is black): more batches cannot help
    seconds = time.perf_counter() - start
    result = RenderResult(local.name, local.seed, film, rays, paths, found, seconds, partial, merged,
                          list(local.warnings), dict(extra))
    result.stages = {k: float(v) for k, v in stages.seconds.items()}
    result.extra["setup_seconds"] = setup
    if merged and issued is not None and seconds > issued:  # the tracing's pace, its setup left out
        result.extra["steady_rays_per_second"] = rays / (seconds - issued)
    local.truncated = truncated
    local.finish(result)
    return result
