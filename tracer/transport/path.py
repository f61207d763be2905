"""The one path loop: every method (forward, backward, the brightness-theorem analysis) runs on it.

Wavefront style, in the manner of pbrt-v4's wavefront integrator (src/pbrt/wavefront/): the paths of a
batch are a :class:`PathState` of (3, n) planes and (n,) arrays, and each bounce runs the same stages
over all of them:

1. intersect: one Embree call for every path;
2. sensor: the method may end paths that reach its sensor first (forward: the eye pupil);
3. escaped: paths that leave the scene (the environment);
4. emission: paths that hit an emitting object;
5. shade: hits sorted by material type with one stable radix sort, the state permuted once, and each
   material's contiguous slice shaded by its instance (per-object parameters gathered from small
   tables): next-event connections where the material has non-delta lobes, then the continuation
   (a sample of the material, or every delta branch where the method splits);
6. shadow rays: every connection of the bounce in one Embree occlusion call;
7. Russian roulette, with one rule (:class:`Roulette`), and the next state.

A method is an object with the hooks ``sensor``, ``escaped``, ``emitted``, ``connect``,
``deliver`` and ``continue_paths`` (see :class:`PathMethod`). Per-stage wall times accumulate in
:class:`Timers` (intersect, sensor, shade, shadow, film, other).
"""

from __future__ import annotations

import contextlib
import time
from collections import defaultdict
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from ..core.units import luminance3
from ..core.vec import F32, max3, norm, put, take
from ..optics.bsdf import DELTA, IMPORTANCE, adjoint_shading_factor
from .accel import OFFSET_SCALE


class Timers:
    """Wall seconds per stage; ``with timers("shade"): ...``, nested stages count once (the outer)."""

    STAGES = ("intersect", "sensor", "shade", "shadow", "film", "other")

    def __init__(self):
        self.seconds: dict[str, float] = defaultdict(float)
        self._depth = 0
        self._name = ""

    def __call__(self, name: str):
        self._name = name
        return self

    def __enter__(self):
        self._depth += 1
        if self._depth == 1:
            self._stage, self._t0 = self._name, time.perf_counter()
        return self

    def __exit__(self, *exc):
        self._depth -= 1
        if self._depth == 0:
            self.seconds[self._stage] += time.perf_counter() - self._t0

    def add(self, other: dict):
        for k, v in other.items():
            self.seconds[k] += v

    def report(self, total: float) -> dict:
        """Seconds per stage with "other" = ``total`` minus the timed stages."""
        out = {k: float(self.seconds.get(k, 0.0)) for k in self.STAGES if k != "other"}
        out["other"] = max(0.0, total - sum(out.values()))
        return out


@dataclass
class PathState:
    """A batch of paths, structure of arrays.

    o, d : (3, n) ray origins (mm, float64) and unit directions (float32) of the next segment.
    beta : (3, n) float32 RGB path weight (the throughput: radiance weight on camera paths, flux on
    light paths). owner : (n,) int64
    pixel (camera paths) or particle index (light paths). rep : (n,) int64 replicate of the film.
    pdf : (n,) float32 solid-angle pdf with which the last direction was sampled (0 after a delta lobe).
    specular : (n,) bool, the last vertex was a delta lobe (or the path start): what the path finds
    next is counted in full, without a multiple-importance weight. extra : method-specific arrays
    whose last axis is the path ((n,): the analysis' chain codes; (3, 3, n) and (3, n): the Stokes vector
    and its frame of tracer.optics.polar where the world needs them).
    """

    o: np.ndarray
    d: np.ndarray
    beta: np.ndarray
    owner: np.ndarray
    rep: np.ndarray
    pdf: np.ndarray
    specular: np.ndarray
    extra: dict = field(default_factory=dict)

    def __len__(self) -> int:
        return len(self.owner)

    def take(self, idx) -> PathState:
        """The paths ``idx`` (an index array, or a slice for views), in that order."""
        if isinstance(idx, slice):
            return PathState(self.o[:, idx], self.d[:, idx], self.beta[:, idx], self.owner[idx], self.rep[idx],
                             self.pdf[idx], self.specular[idx], {k: v[..., idx] for k, v in self.extra.items()})
        t2 = lambda a: take(a, idx)  # noqa: E731
        return PathState(t2(self.o), t2(self.d), t2(self.beta), self.owner[idx], self.rep[idx], self.pdf[idx],
                         self.specular[idx], {k: take(v, idx) for k, v in self.extra.items()})

    @staticmethod
    def empty(extra_keys=()) -> PathState:
        z = np.zeros(0, np.int64)
        return PathState(np.zeros((3, 0)), np.zeros((3, 0), F32), np.zeros((3, 0), F32), z, z, np.zeros(0, F32),
                         np.zeros(0, bool), {k: z for k in extra_keys})


@dataclass
class Shadow:
    """Connections waiting for their shadow rays: origins (3, m), unit directions (3, m), lengths (m,)
    mm, the value each brings if unoccluded (3, m), and what the method needs to deliver it (the
    state of the connecting paths, or anything else in ``data``)."""

    o: np.ndarray
    d: np.ndarray
    tmax: np.ndarray
    value: np.ndarray
    data: dict

    def __len__(self) -> int:
        return self.o.shape[1]

    def take(self, idx) -> Shadow:
        t2 = lambda a: take(a, idx)  # noqa: E731
        return Shadow(t2(self.o), t2(self.d), self.tmax[idx], t2(self.value),
                      {k: take(v, idx) for k, v in self.data.items()})

    @staticmethod
    def concat(parts: list[Shadow]) -> Shadow:
        if len(parts) == 1:
            return parts[0]
        c = lambda a: np.concatenate(a, axis=-1)  # noqa: E731
        return Shadow(c([p.o for p in parts]), c([p.d for p in parts]), c([p.tmax for p in parts]),
                      c([p.value for p in parts]), {k: c([p.data[k] for p in parts]) for k in parts[0].data})


def segment_to(accel, p: np.ndarray, ng: np.ndarray, y: np.ndarray, offset: np.ndarray | None = None):
    """Shadow rays from surface points ``p`` (normals ``ng``, spawn offsets ``offset``) to points ``y`` on
    lights (all (3, n)): (origins, unit directions, lengths). The origin is spawned off the surface
    toward ``y``, the direction aims from it at ``y``, and the length stops short of ``y`` by a margin
    that scales with the coordinates (as the spawn offset does), so the light's own surface never
    occludes it."""
    o = accel.spawn(p, ng, y - p, offset)
    v = y - o
    dist = norm(v)
    margin = 2.0 * OFFSET_SCALE * (1.0 + max3(np.abs(y - accel.center_col)))
    return o, (v * (1.0 / np.maximum(dist, 1e-300))).astype(F32), np.maximum(dist - margin, 0.0)


class Roulette:
    """Russian roulette by the luminance a path can still add to the image (Arvo & Kirk 1990,
    doi:10.1145/97880.97886; a weight window in the sense of Vorba & Krivanek 2016,
    doi:10.1145/2897824.2925912, with the image's reference luminance in place of their adjoint).

    A method states, for each path, the most luminance (cd/m^2) it can still carry as one sample of a
    pixel (``potential``: a camera path's weight times the brightest source; a particle's flux over
    the smallest pixel extent, scaled by the share of the batch's particles that land in one pixel).
    A path whose potential falls below ``EPSILON`` times the reference luminance of the image (a pilot
    estimate, the same in every process) survives with probability potential / (EPSILON reference)
    and its weight is divided by that probability; all others continue untouched. Nothing depends on
    the batch size. The rule judges a path against the picture, not against its own
    start: light through the LCD's black cells (1/300 of the symbols) or in a ghost (0.1 to 0.7 of
    them), or a particle whose weight an aimed sample made small but which is headed for the pupil, is
    always far above the threshold; only paths that could not change a pixel by EPSILON of the image's
    luminance are thinned. The brightness-theorem analysis applies the same rule without randomness:
    it drops such branches. With no reference (a pilot that found no light), nothing is thinned.
    """

    EPSILON = 1e-4

    def __init__(self, reference_cd_m2: float):
        self.threshold = self.EPSILON * reference_cd_m2 if reference_cd_m2 > 0 else 0.0

    def survival(self, potential: np.ndarray) -> np.ndarray:
        """(n,) survival probabilities in [0, 1] (1 everywhere without a reference)."""
        if self.threshold <= 0:
            return np.ones(len(potential))
        return np.minimum(potential / self.threshold, 1.0)

    def keep(self, potential: np.ndarray) -> np.ndarray:
        """The deterministic form (the analysis): paths at or above the threshold."""
        return self.survival(potential) >= 1.0


class PathMethod:
    """Hooks of a method on the path loop; the defaults do nothing (see the module docstring)."""

    #: Transport mode of its paths: tracer.optics.bsdf.RADIANCE or IMPORTANCE.
    mode = None

    def sensor(self, state: PathState, t: np.ndarray, ctx) -> np.ndarray | None:
        """Paths whose segment reaches the method's sensor before the scene (at distance ``t``):
        record them and return their mask, or None."""
        return None

    def escaped(self, state: PathState, ctx):
        """Paths that left the scene."""

    def emitted(self, state: PathState, tri: np.ndarray, p: np.ndarray, t: np.ndarray, ctx):
        """Paths that hit light triangles ``tri`` at points ``p`` after a segment of length ``t``."""

    def connect(self, state: PathState, it, bsdf, ctx) -> Shadow | None:
        """Connections from non-delta vertices (next-event estimation)."""
        return None

    def deliver(self, shadow: Shadow, visible: np.ndarray, ctx):
        """What unoccluded connections bring."""

    def continue_paths(self, state: PathState, it, bsdf, ctx, nxt: Next, sl: slice) -> list[PathState]:
        """The paths that leave the vertices of ``it``, before roulette: one per vertex written into
        ``nxt[sl]`` (the default ends them all), further paths into entries reserved in ``nxt``, or
        returned (they are appended)."""
        return []

    def spare(self, bsdf, hits: int) -> int:
        """How many further paths ``hits`` hits of ``bsdf`` may add in one bounce (splitting)."""
        return 0

    def potential(self, beta: np.ndarray) -> np.ndarray:
        """The most luminance (cd/m^2) each path of weight ``beta`` (3, n) can still add to one pixel
        (for :class:`Roulette`)."""
        return np.full(beta.shape[1], np.inf)

    def probe(self, state: PathState, ctx) -> None:
        """Measure what the paths ``state``, cut at max_depth, would still have carried (default:
        :func:`probe_cut`, into ``ctx.store``)."""
        probe_cut(self, state, ctx)


@dataclass
class Context:
    """What one batch's trip through the loop shares: the world, the random stream, the timers and
    whatever the method collects (``splats``, leaves of the analysis)."""

    world: object
    rng: np.random.Generator
    timers: Timers
    splats: object = None
    roulette: Roulette | None = None
    store: dict = field(default_factory=dict)
    #: Paths that found light (the method's efficiency numerator), or a flag per camera sample.
    found: int = 0
    sample_found: np.ndarray | None = None
    #: The random stream of the probe of paths cut at max_depth (:func:`probe_cut`); None: no probe.
    probe_rng: np.random.Generator | None = None
    #: The batch's index (methods whose parameters follow a schedule over batches: the photon radius).
    batch: int = 0


@dataclass
class Next:
    """The continuation of one bounce's hits, in their sorted order: each material writes the slice of
    its hits (new origins, directions, weights, pdf, whether the lobe was delta, whether the path goes
    on), a method that splits paths adds the extra branches after them (:meth:`reserve`), and the loop
    compacts the survivors once (:func:`trace`). owner, rep and extra start as the hits' own."""

    o: np.ndarray
    d: np.ndarray
    beta: np.ndarray
    pdf: np.ndarray
    specular: np.ndarray
    alive: np.ndarray
    owner: np.ndarray
    rep: np.ndarray
    extra: dict
    used: int

    @staticmethod
    def for_hits(st: PathState, spare: int) -> Next:
        """Room for the ``len(st)`` hits' continuations and ``spare`` extra branches."""
        m = len(st)
        n = m + spare

        def like(a):
            out = np.empty(a.shape[:-1] + (n,), a.dtype)
            out[..., :m] = a
            return out

        return Next(np.empty((3, n)), np.empty((3, n), F32), np.zeros((3, n), F32), np.empty(n, F32),
                    np.empty(n, bool), np.zeros(n, bool), like(st.owner), like(st.rep),
                    {k: like(v) for k, v in st.extra.items()}, m)

    def reserve(self, count: int) -> slice:
        """Entries for ``count`` further paths (their owner, rep and extra are the caller's to fill)."""
        if self.used + count > len(self.alive):
            raise ValueError("more split branches than the bounce reserved room for")
        sl = slice(self.used, self.used + count)
        self.used += count
        return sl

    def append(self, state: PathState):
        """Add whole paths (a method's further paths)."""
        sl = self.reserve(len(state))
        self.o[:, sl], self.d[:, sl], self.beta[:, sl] = state.o, state.d, state.beta
        self.pdf[sl], self.specular[sl], self.alive[sl] = state.pdf, state.specular, True
        self.owner[sl], self.rep[sl] = state.owner, state.rep
        for k, v in state.extra.items():
            self.extra[k][..., sl] = v


#: The arrays of a :class:`CompactedState` that stay in the bounce's :class:`Next` until needed.
_DEFERRED = ("beta", "owner", "rep", "pdf", "specular", "extra")


class CompactedState(PathState):
    """The paths that go on after a bounce (:func:`_compact`): their origins and directions gathered at
    once (the next Embree call needs them), everything else left in the bounce's :class:`Next` until
    the paths are next taken (the sort by material), so that each of those arrays is gathered once per
    bounce instead of twice. Reading one of them gathers them all (a hook that needs the whole state)."""

    def __init__(self, o: np.ndarray, d: np.ndarray, source: Next, index: np.ndarray):
        self.o, self.d = o, d
        self._source, self._index = source, index

    def __len__(self) -> int:
        return len(self._index)

    def _deferred(self, j: np.ndarray) -> tuple:
        """The deferred arrays (in the order of :data:`_DEFERRED`) of the source's entries ``j``."""
        src = self.__dict__["_source"]
        return (take(src.beta, j), take(src.owner, j), take(src.rep, j), take(src.pdf, j), take(src.specular, j),
                {k: take(v, j) for k, v in src.extra.items()})

    def __getattr__(self, name):  # only for attributes not yet set: the deferred ones
        if name not in _DEFERRED:
            raise AttributeError(name)
        self.__dict__.update(zip(_DEFERRED, self._deferred(self.__dict__["_index"]), strict=True))
        return self.__dict__[name]

    def take(self, idx) -> PathState:
        if "beta" in self.__dict__:
            return PathState.take(self, idx)
        o, d = (self.o[:, idx], self.d[:, idx]) if isinstance(idx, slice) else (take(self.o, idx), take(self.d, idx))
        return PathState(o, d, *self._deferred(self._index[idx]))


def continue_by_sampling(state: PathState, it, sampler, ctx, mode, nxt: Next, sl: slice,
                         rows: np.ndarray | None = None) -> list[PathState]:
    """The default continuation: one sample of ``sampler`` (a material or an aimed mixture) per path,
    written into ``nxt[sl]``; absorbed samples end. Returns no further paths. With ``rows`` (indices
    into the hits), only those paths sample, into their own entries of ``nxt``; the random numbers are
    drawn for every hit all the same, so that the stream does not depend on which."""
    u = ctx.rng.random((sampler.dims, len(it)), F32) if sampler.dims else None
    polar = ctx.world.polar
    if polar is not None and "stokes" in state.extra:  # what two-branch materials choose by
        it.polar = (state.extra["stokes"], state.extra["frame"])
    if rows is not None:
        if len(rows) == 0:
            return []
        state, it, u, sl = state.take(rows), it.take(rows), None if u is None else take(u, rows), sl.start + rows
    s = sampler.sample(it, u, mode)
    if it.polar is not None:
        bsdf = getattr(sampler, "own", sampler)  # an aimed mixture scatters by its material's law
        beta, stokes, frame = polar.scatter(state.beta, state.extra, it, bsdf, s.wo, s.weight, s.flags,
                                            mode == IMPORTANCE)
        put(nxt.extra["stokes"], sl, stokes)
        put(nxt.extra["frame"], sl, frame)
    else:
        beta = state.beta * s.weight
    if mode == IMPORTANCE and it.ns is not it.ng:  # smoothed surfaces: the adjoint of the camera paths' law
        beta = beta * adjoint_shading_factor(it, s.wo)
    put(nxt.beta, sl, beta)
    put(nxt.d, sl, s.wo)
    put(nxt.o, sl, ctx.world.accel.spawn(it.p, it.ng, s.wo, it.offset))
    nxt.pdf[sl] = s.pdf
    nxt.specular[sl] = (s.flags & DELTA) != 0
    nxt.alive[sl] = (s.flags != 0) & (luminance3(beta) > 0)
    return []


def _compact(method: PathMethod, nxt: Next, ctx) -> PathState:
    """The paths that go on after a bounce: roulette on the living ones of ``nxt``, then one compaction
    into the next state (:class:`CompactedState`)."""
    n = nxt.used
    alive = nxt.alive[:n]
    beta = nxt.beta[:, :n]
    roulette = ctx.roulette if ctx.roulette is not None and ctx.roulette.threshold > 0 else None
    if roulette is not None:
        q = roulette.survival(method.potential(beta))  # the weights of paths that ended are 0
        idx = np.flatnonzero(alive & (q < 1.0))
        if len(idx):
            keep = ctx.rng.random(len(idx)) < q[idx]
            alive[idx[~keep]] = False
            beta[:, idx[keep]] *= 1.0 / np.maximum(q[idx[keep]], 1e-30)
    keep = np.flatnonzero(alive)
    return CompactedState(take(nxt.o, keep), take(nxt.d, keep), nxt, keep)


#: Paths cut at max_depth are followed this many segments further by :func:`probe_cut`.
PROBE_DEPTH = 16
#: ``ctx.store`` keys of the probe's tallies: the luminance the cut paths would have added, per film
#: component (sums of Y, not normalised), and the number of cut paths.
PROBE_KEY, CUT_KEY = "cut_luminance_sum", "cut_paths"
#: ``ctx.store`` key of the cut paths still going after the probe's segments: their light beyond is
#: not in the tally, which is then a lower bound (paths trapped by total internal reflection).
STILL_KEY = "cut_paths_still_going"


def probe_cut(method: PathMethod, state: PathState, ctx: Context):
    """Follow the paths cut at max_depth for :data:`PROBE_DEPTH` more segments on their own random
    stream, into a tally kept out of the image (``ctx.store``): an unbiased estimate of the light those
    segments carry, which the report sets against the image's noise. The image, the efficiency and
    the method's own figures are left as they were."""
    saved = ctx.splats, ctx.found, ctx.rng, dict(ctx.store)
    flags = None if ctx.sample_found is None else ctx.sample_found.copy()
    ctx.splats, ctx.rng = type(saved[0])(), ctx.probe_rng
    try:
        still = trace(method, state, ctx, PROBE_DEPTH, probe=False)
        probed = ctx.splats
    finally:
        ctx.splats, ctx.found, ctx.rng = saved[:3]
        ctx.store.clear()
        ctx.store.update(saved[3])
        if flags is not None:
            ctx.sample_found[:] = flags
    tally_probe(ctx.store, probed)
    tally_cut(ctx.store, len(state), still)


def tally_probe(store: dict, splats) -> None:
    """Add the luminance (sums of Y, not normalised) of a probe's ``splats`` to ``store``, per
    component, under :data:`PROBE_KEY`."""
    for comp in splats.parts:
        key = f"{PROBE_KEY}:{comp}"
        store[key] = store.get(key, 0.0) + float(luminance3(splats.gather(comp)[2]).sum())


def tally_cut(store: dict, cut: int, still: int) -> None:
    """Add ``cut`` paths cut at max_depth, ``still`` of them still going after the probe, to ``store``."""
    store[CUT_KEY] = store.get(CUT_KEY, 0) + cut
    store[STILL_KEY] = store.get(STILL_KEY, 0) + still


def _hooked(method: PathMethod, hook: str) -> bool:
    """Whether ``method`` has its own ``hook``: the loop prepares no paths for one left at
    :class:`PathMethod`'s default, which does nothing (forward tracing ignores paths that escape)."""
    return getattr(type(method), hook) is not getattr(PathMethod, hook)


class BatchAbandoned(Exception):
    """Raised by the path loop inside :func:`abandon_when` once its check is true."""


#: The check of the enclosing :func:`abandon_when`, or None.
_abandon: Callable[[], bool] | None = None


@contextlib.contextmanager
def abandon_when(check: Callable[[], bool]):
    """Within the block, the path loop raises :class:`BatchAbandoned` at its next bounce once ``check()``
    is true: a worker process's batch of a render that has ended, which nobody will merge
    (tracer.runtime.parallel). A batch that runs to its end is the same as without the block."""
    global _abandon
    previous, _abandon = _abandon, check
    try:
        yield
    finally:
        _abandon = previous


def trace(method: PathMethod, state: PathState, ctx: Context, max_depth: int, probe: bool = True) -> int:
    """Run paths through the loop until they end or reach ``max_depth`` segments; returns the number
    of paths still alive at the limit (cut: a bias). With ``probe`` and a ``ctx.probe_rng``, the cut
    paths are followed further into a tally (the method's :meth:`PathMethod.probe`, by default
    :func:`probe_cut`) that measures that bias."""
    world, timers = ctx.world, ctx.timers
    accel = world.accel
    materials = world.materials
    lights = world.lights
    emits = len(lights) > 0 and _hooked(method, "emitted")
    escapes = _hooked(method, "escaped")
    for _ in range(max_depth):
        n = len(state)
        if n == 0:
            return 0
        if _abandon is not None and _abandon():
            raise BatchAbandoned
        if accel is None:  # nothing but the environment (and perhaps the sensor)
            world.rays_without_geometry += n
            with timers("sensor"):
                ended = method.sensor(state, np.full(n, np.inf), ctx)
            rest = np.flatnonzero(~ended) if ended is not None else np.arange(n)
            if len(rest) and escapes:
                with timers("shade"):
                    method.escaped(state.take(rest), ctx)
            return 0
        with timers("intersect"):
            hits = accel.intersect(state.o, state.d)
        face, t = hits.face, hits.t
        with timers("sensor"):
            ended = method.sensor(state, t, ctx)
        with timers("shade"):
            if escapes:
                miss = np.flatnonzero((face < 0) & ~ended if ended is not None else face < 0)
                if len(miss):
                    method.escaped(state.take(miss), ctx)
            if ended is not None:
                face = np.where(ended, -1, face)  # paths at the sensor end here, like misses
            if emits:  # emission, before the emitters' own materials take the paths
                tri = take(lights.face_light_ext, face)
                e = np.flatnonzero(tri >= 0)
                if len(e):
                    se = state.take(e)
                    method.emitted(se, tri[e], se.o + t[e] * se.d, t[e], ctx)
            # Hits grouped by material; misses, paths at the sensor and absorbed paths (group -1) leave.
            mat = take(world.face_group, face)
            order = np.argsort(mat, kind="stable")
            counts = np.bincount(mat.astype(np.int64) + 1, minlength=len(materials) + 1)
            order = order[counts[0]:]
            if len(order) == 0:
                return 0
            st = state.take(order)
            f = face[order]
            th = t[order]
            p = st.o + th * st.d
            ng = take(accel.normal32, f)
            bounds = np.cumsum(counts[1:])
            spare = sum(method.spare(bsdf, int(counts[m + 1])) for m, bsdf in enumerate(materials))
            nxt = Next.for_hits(st, spare)
            shadows = []
            start = 0
            for m, bsdf in enumerate(materials):
                end = int(bounds[m])
                if end == start:
                    continue
                sl = slice(start, end)
                start = end
                it = world.interaction(f[sl], p[:, sl], st.d[:, sl], ng[:, sl], bsdf)
                sub = st.take(sl)
                if not bsdf.delta:
                    sh = method.connect(sub, it, bsdf, ctx)
                    if sh is not None and len(sh):
                        shadows.append(sh)
                for extra in method.continue_paths(sub, it, bsdf, ctx, nxt, sl):
                    nxt.append(extra)
        if shadows:
            sh = Shadow.concat(shadows)
            with timers("shadow"):
                blocked = accel.occluded(sh.o, sh.d, sh.tmax)
            with timers("shade"):
                method.deliver(sh, ~blocked, ctx)
        with timers("shade"):
            state = _compact(method, nxt, ctx)
    if len(state) and probe and ctx.probe_rng is not None:
        method.probe(state, ctx)
    return len(state)
