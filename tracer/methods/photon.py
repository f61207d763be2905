"""Bidirectional stochastic ray tracing with visibility (photon) maps: the paper's method for a HUD with
a diffuse screen (sec. 4.1, Figs. 4 and 7), where the eye sees the screen only through the collimating
optics and the screen sees the LEDs only through the projection lens, the LCD and the condenser.

A batch is ``REPLICATES`` independent replicates, each a complete estimate of the image:

1. Photon pass. ``batch_size`` particles leave the lights (:class:`tracer.methods.forward.Particles`,
   with the emitters' and surfaces' aims) and run through the optics on the path loop; at every
   non-specular vertex a photon is stored (position, arriving direction, flux, object, replicate =
   particle index mod R). Photons are hashed into a grid of cells of side 2r (:class:`PhotonGrid`).
2. Eye pass (the visibility maps). One sample through every pixel per replicate, traced from the
   retina through the pupil along specular chains (splitting at glass as the backward method does)
   to its first non-specular vertex, the visibility point, where the path ends.
3. Gather. A visibility point x of replicate r takes the photons of replicate r within radius r_k on
   the same object: L(x) = sum_p f(x, w_p, w_eye) Phi_p / (pi r_k^2 N_r), N_r the particles emitted for
   the replicate (the density estimate of Jensen, "Realistic Image Synthesis Using Photon Mapping",
   2001, eq. 7.6).

The radius shrinks with the batch index k alone: r_k^2 = r_0^2 prod_{i=1..k} (i + alpha) / (i + 1), the
schedule of probabilistic progressive photon mapping (Knaus and Zwicker 2011,
doi:10.1145/1966394.1966404; the paper cites stochastic PPM, Hachisuka and Jensen 2009,
doi:10.1145/1618452.1618487). Batches therefore stay independent replicates that merge exactly and run
on worker processes and Dask like every other method; the estimate is consistent (its bias falls as
r_k^2 ~ k^(alpha - 1)). r_0 is ``radius_mm``, or where that is 0 (the default) ``FOOTPRINT_RADII`` times the median
distance between the visibility points of neighbouring pixels (the pixel's footprint on the screen),
measured once per render on the pilot's stream.

What each part counts, so that no light path is counted twice (tests/methods/test_photon.py proves it):

- ``hit``: emitters and the environment that eye paths meet along their specular chains;
- ``connection``: light arriving at a visibility point straight from an emitter or the environment, by
  two strategies weighted by the power heuristic: next-event estimation, and one ray in a direction
  drawn from the surface's law (the eye path itself ends at the visibility point);
- ``photon``: light whose last segment before the visibility point leaves another surface (a lens, a
  mirror, the LCD, a diffuse wall): photons are stored only after their first event.

With ``next_event: false`` photons are stored from their first segment on and carry the direct light
too (no connections). Photons leave the lights only: environment light that reaches a scattering
surface after a bounce is not counted (a warning says so where the environment is lit).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..core.film import Splats
from ..core.sampling import make_rng
from ..core.units import luminance3
from ..core.vec import F32, dot, take
from ..optics.bsdf import IMPORTANCE, RADIANCE, Interaction
from ..optics.materials import LCD
from ..transport.path import (
    PROBE_DEPTH,
    CompactedState,
    Context,
    Next,
    PathMethod,
    PathState,
    Timers,
    continue_by_sampling,
    tally_cut,
    tally_probe,
    trace,
)
from .backward import BackwardTracer
from .base import BATCH_SHARE_OF_TIME, DEFAULT_BATCH, MIN_BATCH, PILOT_PATHS, WAVE, register
from .forward import Particles

#: Independent replicates per batch: eye passes over all pixels, each with its own share of photons.
REPLICATES = 2
#: The default initial radius: at least this many pixel footprints on the surface the eye sees...
FOOTPRINT_RADII = 1.5
#: ... and large enough that a visibility point in the light gathers about this many photons from a
#: replicate of a default batch (DEFAULT_BATCH photons), ...
TARGET_PHOTONS = 10.0
#: ... but at most this many footprints (beyond it the image would blur more than it gains).
MAX_FOOTPRINT_RADII = 12.0
#: A radius_mm given above this many times MAX_FOOTPRINT_RADII footprints is warned of before the pilot.
GIVEN_RADIUS_WARN = 2.0
#: Photons count at a visibility point only on the same object with normals at most ~45 deg apart.
MIN_NORMAL_COS = 0.7
#: Candidate (point, photon) pairs examined at once (bounds the gather's memory: ~100 bytes each).
GATHER_PAIRS = 1 << 20
#: Photons (and eye samples) of the pilot that measures the photon density.
PILOT_PHOTONS = 1 << 15
#: The pilots' eye samples: as many as their photons, at most this many per pixel.
PILOT_SAMPLES_PER_PIXEL = 4
#: Pixels sampled (on a grid) to measure the footprint.
FOOTPRINT_PIXELS = 1 << 14
#: The radius never falls below this fraction of r_0 (a guard; the schedule reaches it only after
#: about 10^18 batches).
MIN_RADIUS_FRACTION = 1e-3
#: Eye paths cut at max_depth are warned of above this share of the eye samples (their light is not
#: probed: a cut eye path never reached its visibility point). Photon paths cut there are probed
#: (:meth:`PhotonPass.probe`) and warned of by what they would add, as forward and backward tracing's.
CUT_WARN_SHARE = 1e-3
#: The ctx.store keys of the photon figures (summed over batches); "photon_flux_gathered" is the sum
#: of the luminance of the flux (cd/m^2 mm^2 sr) of every photon gathered, once per gathering point.
STORE_KEYS = ("photons_emitted", "photons_stored", "visibility_points", "photons_gathered", "photon_paths_cut",
              "photon_flux_gathered")


def _tally(ctx, key: str, count: int):
    """Add ``count`` to the batch's figure ``key`` (ctx.store, summed over batches by the driver)."""
    ctx.store[key] = ctx.store.get(key, 0) + count


def radius_schedule(r0: float, alpha: float, k: np.ndarray | int) -> np.ndarray | float:
    """The gather radius (mm) of batch ``k`` (0-based): r_0 sqrt(prod_{i=1..k} (i + alpha) / (i + 1))
    (Knaus and Zwicker 2011, eq. 15, with batch k+1 their pass), never below MIN_RADIUS_FRACTION r_0."""
    k = np.asarray(k, np.float64)
    log_ratio = (np.vectorize(math.lgamma)(k + 1 + alpha) - math.lgamma(1 + alpha)
                 - np.vectorize(math.lgamma)(k + 2))
    r = r0 * np.exp(0.5 * log_ratio)
    out = np.maximum(r, MIN_RADIUS_FRACTION * r0)
    return float(out) if out.ndim == 0 else out


def _cell_hash(cell: np.ndarray, rep: np.ndarray) -> np.ndarray:
    """64-bit keys of integer cells (3, n) and replicates (n,) (the primes of Teschner et al. 2003,
    "Optimized spatial hashing for collision detection of deformable objects"). Two cells may share a
    key; :meth:`PhotonGrid.pairs` compares the cells themselves, so a collision costs time only."""
    c = cell.astype(np.int64).view(np.uint64)
    with np.errstate(over="ignore"):
        return ((c[0] * np.uint64(73856093)) ^ (c[1] * np.uint64(19349663)) ^ (c[2] * np.uint64(83492791))
                ^ (rep.astype(np.uint64) * np.uint64(2654435761)))


class PhotonGrid:
    """Photons of one batch in a spatial hash grid of cells of side 2 ``radius`` (mm): the photons within
    ``radius`` of any point lie in the 2 x 2 x 2 cells around it. Arrays are kept sorted by key:
    p (3, n) mm float64, d (3, n) arriving directions, beta (3, n) flux (cd/m^2 mm^2 sr), slot (n,),
    ng (3, n), rep (n,)."""

    def __init__(self, p, d, beta, slot, ng, rep, radius: float):
        self.radius = float(radius)
        self.h = 2.0 * self.radius
        self.origin = p.min(axis=1, keepdims=True) if p.shape[1] else np.zeros((3, 1))
        cell = self._cell(p)
        key = _cell_hash(cell, rep)
        order = np.argsort(key, kind="stable")
        self.keys = key[order]
        self.order = order  # the arrays' photon k is photon order[k] of those given (for arrays kept beside)
        t = lambda a: take(a, order)  # noqa: E731
        self.p, self.d, self.beta, self.slot, self.ng, self.rep, self.cell = (
            t(p), t(d), t(beta), t(slot), t(ng), t(rep), t(cell))

    def __len__(self) -> int:
        return len(self.keys)

    def _cell(self, p: np.ndarray) -> np.ndarray:
        return np.floor((p - self.origin) / self.h).astype(np.int64)

    def candidates(self, x: np.ndarray, rep: np.ndarray):
        """For points x (3, m) of replicates ``rep``: the 8 cells around each, (3, m, 8) and their
        photon ranges [lo, hi) (m, 8)."""
        base = np.floor((x - self.radius - self.origin) / self.h).astype(np.int64)
        offs = np.array([[i, j, k] for i in (0, 1) for j in (0, 1) for k in (0, 1)]).T  # (3, 8)
        cells = base[:, :, None] + offs[:, None, :]
        keys = _cell_hash(cells.reshape(3, -1), np.repeat(rep, 8)).reshape(-1, 8)
        lo = np.searchsorted(self.keys, keys, side="left")
        hi = np.searchsorted(self.keys, keys, side="right")
        return cells, lo, hi

    def pairs(self, x, ng, slot, rep, cells, lo, hi):
        """(point index, photon index) of every photon of the same replicate and object within the
        radius of points x (3, m) (normals ng, slots, replicates), whose normals agree; the candidate
        ranges from :meth:`candidates`."""
        counts = (hi - lo).reshape(-1)
        total = int(counts.sum())
        if total == 0:
            return np.zeros(0, np.int64), np.zeros(0, np.int64)
        which = np.repeat(np.arange(len(counts)), counts)  # (point, cell) pair of each candidate
        first = np.cumsum(counts) - counts
        ph = lo.reshape(-1)[which] + (np.arange(total) - first[which])
        pt = which // 8
        cell = cells.reshape(3, -1)[:, which]
        ok = np.all(self.cell[:, ph] == cell, axis=0) & (self.rep[ph] == rep[pt]) & (self.slot[ph] == slot[pt])
        pt, ph = pt[ok], ph[ok]
        v = self.p[:, ph] - x[:, pt]
        ok = (dot(v, v) <= self.radius * self.radius) & (dot(self.ng[:, ph], ng[:, pt]) >= MIN_NORMAL_COS)
        return pt[ok], ph[ok]


@dataclass
class Gathered:
    """What the photons of a :class:`PhotonGrid` within its radius of m points send toward them (each
    point's outgoing direction is its interaction's): ``sums`` (3, m) the sums of f Phi_p over the
    photons (f the surface's BSDF, 1/sr; Phi_p the photon's flux, cd/m^2 mm^2 sr), ``found`` (m,) the
    photons gathered, ``squares`` (m,) the sums of Y(f Phi_p)^2 (the density estimate's variance, see
    :meth:`PhotonMap.luminance`), ``pairs`` all of them, and ``flux`` the luminance of the gathered
    photons' flux summed per chunk of pairs (the photon method's roulette scale)."""

    sums: np.ndarray
    found: np.ndarray
    squares: np.ndarray
    pairs: int
    flux: list[float]


def gather(grid: PhotonGrid, it: Interaction, bsdf, rep: np.ndarray, squares: bool = False,
           per_photon: tuple[np.ndarray, np.ndarray] | None = None) -> Gathered:
    """Gather ``grid``'s photons at the points of ``it`` (replicates ``rep``) on surfaces of ``bsdf``:
    photons of the same replicate and object within the radius whose normals agree
    (:meth:`PhotonGrid.pairs`), at most GATHER_PAIRS candidate pairs at a time. Dividing ``sums`` by pi
    r^2 N (N the particles emitted for the replicate) gives the luminance (Jensen 2001, eq. 7.6).
    ``squares`` false leaves :attr:`Gathered.squares` at 0 (the photon method's error bars come from
    its replicates). ``per_photon`` (weights (3, m) of the points, a tally (photons,)): each photon's
    weighted contributions summed over the points, Y, added to the tally (what the variance of a sum
    over many points needs: the points share photons)."""
    m = len(it)
    cells, lo, hi = grid.candidates(it.p, rep)
    per_point = np.cumsum((hi - lo).sum(axis=1))
    out = Gathered(np.zeros((3, m)), np.zeros(m, np.int64), np.zeros(m), 0, [])
    start = 0
    while start < m:
        done = per_point[start - 1] if start else 0
        end = int(np.searchsorted(per_point, done + GATHER_PAIRS, side="right"))
        end = min(max(end, start + 1), m)
        sl = slice(start, end)
        pt, ph = grid.pairs(it.p[:, sl], it.ng[:, sl], it.slot[sl], rep[sl], cells[:, sl], lo[sl], hi[sl])
        start = end
        if len(pt) == 0:
            continue
        pt = pt + sl.start
        out.pairs += len(pt)
        sub = it.take(pt)
        d_ph = grid.d[:, ph]
        cos = np.abs(dot(d_ph, sub.ng))
        fcos = bsdf.eval(sub, -d_ph, RADIANCE)
        f = np.divide(fcos, cos, out=np.zeros(fcos.shape, np.float64), where=cos > 0)
        flux = grid.beta[:, ph]
        contrib = f * flux
        for c in range(3):
            out.sums[c] += np.bincount(pt, weights=contrib[c], minlength=m)
        out.found += np.bincount(pt, minlength=m)
        if squares:
            out.squares += np.bincount(pt, weights=luminance3(contrib) ** 2, minlength=m)
        if per_photon is not None:
            weight, tally = per_photon
            tally += np.bincount(ph, weights=luminance3(contrib * weight[:, pt]), minlength=len(tally))
        out.flux.append(float(luminance3(flux).sum()))
    return out


class PhotonPass(PathMethod):
    """The photon pass's hooks on the path loop: particles carry flux (IMPORTANCE), and every
    non-specular vertex they reach stores a photon (after the particle's first event, or from its
    first segment on when direct light is left to the photons).

    Photons go through the path loop's one Russian roulette (:class:`tracer.transport.path.Roulette`):
    a photon's ``potential`` is its flux's luminance times ``scale``, the image's mean luminance per
    unit of the mean flux of the photons its pilot gathered, so that a photon is thinned where it
    carries less than Roulette.EPSILON of what a typical gathered photon does. Paths cut at max_depth
    are followed further into ``probe_stored`` (:meth:`probe`), whose photons the eye pass gathers
    into a tally kept out of the image."""

    mode = IMPORTANCE

    def __init__(self, particles: Particles, store_direct: bool, scale: float = math.inf, tag_lcd: bool = False):
        self.particles = particles
        self.store_direct = store_direct
        self.scale = scale
        self.stored: list[tuple] = []
        self.probe_stored: list[tuple] = []
        #: With ``tag_lcd``: each stored photon's transmittance relative to a clear cell at the first LCD its
        #: path crossed (NaN: none), in the order of :attr:`stored`.
        self.tag_lcd = tag_lcd
        self.stored_lcd: list[np.ndarray] = []

    def potential(self, beta):
        if math.isinf(self.scale):  # the pilot gathered no photon: nothing to judge a photon against
            return np.full(beta.shape[1], np.inf)
        return luminance3(beta) * self.scale

    def probe(self, state, ctx):
        """Follow the cut paths PROBE_DEPTH more segments on the probe's random stream, storing their
        photons into ``probe_stored``; the cut and still-going counts go to ``ctx.store`` as the
        default probe's do (tracer.transport.path.probe_cut)."""
        rng, stored = ctx.rng, self.stored
        ctx.rng, self.stored = ctx.probe_rng, self.probe_stored
        try:
            still = trace(self, state, ctx, PROBE_DEPTH, probe=False)
        finally:
            ctx.rng, self.stored = rng, stored
        tally_cut(ctx.store, len(state), still)

    def connect(self, state, it, bsdf, ctx):
        keep = np.flatnonzero(state.extra["scattered"] | self.store_direct)
        if len(keep):
            t = lambda a: take(a, keep)  # noqa: E731
            self.stored.append((t(it.p), t(it.d), t(state.beta), it.slot[keep], t(it.ng), state.rep[keep]))
            if self.tag_lcd:
                self.stored_lcd.append(state.extra["lcd"][keep])
        return None

    def continue_paths(self, state, it, bsdf, ctx, nxt, sl):
        out = continue_by_sampling(state, it, self.particles.sampler(bsdf), ctx, IMPORTANCE, nxt, sl)
        nxt.extra["scattered"][sl] = True
        if self.tag_lcd and isinstance(bsdf, LCD):
            first = state.extra["lcd"]
            nxt.extra["lcd"][sl] = np.where(np.isnan(first), luminance3(bsdf.modulation(it)), first)
        return out

    def run(self, ctx, n: int, replicates: int, max_depth: int, probe: bool = True, progress=None) -> int:
        """Emit ``n`` particles dealt into ``replicates`` on ``ctx``'s stream, wave by wave, and trace
        them to ``max_depth``, storing their photons; the paths cut there (followed further into
        ``probe_stored`` where ``probe`` and the context has a probe stream). ``progress(fraction)``
        after every wave."""
        cut = 0
        for a in range(0, n, WAVE):
            state, _ = self.particles.emit(ctx.rng, min(WAVE, n - a), a, replicates)
            state.extra["scattered"] = np.zeros(len(state), bool)
            if self.tag_lcd:
                state.extra["lcd"] = np.full(len(state), np.nan)
            cut += trace(self, state, ctx, max_depth, probe=probe)
            if progress is not None:
                progress(min(a + WAVE, n) / n)
        return cut


def stacked(stored: list[tuple]) -> list[np.ndarray] | None:
    """The photons of :attr:`PhotonPass.stored` (a list of per-wave tuples) as the arrays of a
    :class:`PhotonGrid` (p, d, beta, slot, ng, rep), or None where none was stored."""
    if not stored:
        return None
    return [np.concatenate(parts, axis=-1) for parts in zip(*stored, strict=True)]


#: A :class:`PhotonMap` of MAP_PHOTONS particles gathers about MAP_GATHER photons at a photon of
#: its median density; the count grows as the square root of the particles, so that the relative
#: error and the radius (the blur) both fall as N^(-1/4).
MAP_GATHER = 400
MAP_PHOTONS = 1_000_000
#: An LCD cell passing at least this share of a clear cell's light counts as clear (:meth:`PhotonMap.clear_share`).
CLEAR_CELL = 0.5
#: The fewest LCD photons near a point for :meth:`PhotonMap.clear_share` to tell (some 40 per gather radius at
#: the analysis' 250,000 particles on hud-screen's symbols).
CLEAR_SHARE_PHOTONS = 20
#: A :class:`PhotonMap`'s radius is at most this share of the extent of the photons on their surface.
MAP_MAX_RADIUS_SHARE = 0.05
#: Photons whose neighbours are counted to set a :class:`PhotonMap`'s radius (the median of 500
#: counts of about MAP_GATHER is known to a few per cent).
MAP_RADIUS_PROBES = 500


class PhotonMap:
    """The photon method's photon pass run once, and its photons kept for any number of look-ups: the
    light that reaches scattering surfaces through other surfaces (a projection lens, a condenser, a
    mirror: the paper's sec. 4.1 screen, lit by the LEDs through the LCD and the projection lens), as
    its luminance toward a given direction at given points (:meth:`luminance`). It serves the
    brightness-theorem analysis (:func:`tracer.transport.chains.specular_paths`), whose quadrature
    follows only the light that reaches a scattering surface straight from an emitter: what the
    photons carry complements it exactly, as the photon method's "photon" and "connection" components
    do (photons are stored after their first event only). One map serves every eye position of an
    eyebox scan (:mod:`tracer.scans.eyebox`): the photons do not depend on the eye, and the scan's
    values share their random numbers, so their ratios to the design eye are far less noisy than each.

    ``photons`` particles leave the lights (with their aims, :class:`tracer.methods.forward.Particles`)
    on the random stream (``seed``, ``stream``: a render's batch k draws from stream k, so a map that
    checks a render takes one no batch does); no Russian roulette. The gather radius ``radius_mm`` is set so
    that a photon at the median density gathers about ``gather`` = MAP_GATHER sqrt(photons /
    MAP_PHOTONS) of its neighbours (at most :data:`MAP_MAX_RADIUS_SHARE` of the extent of all the
    stored photons; one radius for every surface, from the median density over all of them): a
    relative standard error of some 5 % at a million particles, and a blur of the order of the
    radius (:meth:`luminance` gives each value's standard error, not the blur's bias). Paths cut at
    ``max_depth`` are counted (``paths_cut``, in :meth:`summary`), not followed further. Raises
    nothing where no photon is stored (a scene whose lights reach no scattering surface through
    optics): every look-up then gives 0."""

    def __init__(self, world, photons: int, seed: int, max_depth: int = 12, progress=None, stream: int = 1):
        self.emitted = int(photons)
        self.seed = int(seed)
        self.stream = int(stream)
        self.gather = MAP_GATHER * math.sqrt(max(self.emitted, 1) / MAP_PHOTONS)
        can_emit = world.accel is not None and world.lights.total_flux_lm > 0
        arrays = None
        self.paths_cut = 0
        tag = any(isinstance(m, LCD) for m in world.materials)
        lcd = None
        if can_emit and photons > 0:
            pp = PhotonPass(Particles(world), store_direct=False, tag_lcd=tag)
            ctx = Context(world, make_rng(seed, stream), Timers(), Splats())
            self.paths_cut = pp.run(ctx, photons, 1, max_depth, probe=False, progress=progress)
            arrays = stacked(pp.stored)
            lcd = np.concatenate(pp.stored_lcd) if tag and pp.stored_lcd else None
        self.stored = 0 if arrays is None else arrays[0].shape[1]
        self.radius_mm = 0.0
        self.grid: PhotonGrid | None = None
        #: Each photon's LCD tag (:attr:`PhotonPass.stored_lcd`), in the grid's order; None without an LCD.
        self.lcd: np.ndarray | None = None
        if self.stored:
            self.radius_mm = self._radius(arrays)
            self.grid = PhotonGrid(*arrays, self.radius_mm)
            if lcd is not None and np.isfinite(lcd).any():
                self.lcd = lcd[self.grid.order]

    def _radius(self, arrays) -> float:
        """The radius (mm) at which a photon at the median density has about ``gather`` neighbours: a
        first guess from the photons' extent, then corrected twice by the neighbours counted at
        MAP_RADIUS_PROBES photons (the count grows as the radius squared on a surface)."""
        p, _, _, slot, ng, rep = arrays
        extent = float(np.max(p.max(axis=1) - p.min(axis=1)))
        largest = max(MAP_MAX_RADIUS_SHARE * extent, 1e-6)
        radius = min(largest, extent * math.sqrt(self.gather / (math.pi * self.stored)) or largest)
        probe = np.linspace(0, self.stored - 1, min(MAP_RADIUS_PROBES, self.stored)).astype(np.int64)
        for _ in range(2):
            grid = PhotonGrid(*arrays, radius)
            x, n_, s_, r_ = p[:, probe], ng[:, probe], slot[probe], rep[probe]
            cells, lo, hi = grid.candidates(x, r_)
            pt, _ = grid.pairs(x, n_, s_, r_, cells, lo, hi)
            median = float(np.median(np.bincount(pt, minlength=len(probe))))
            radius = min(largest, radius * math.sqrt(self.gather / max(median, 1.0)))
        return radius

    def luminance(self, it: Interaction, bsdf, weight: np.ndarray | None = None,
                  tally: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """At the points of ``it`` (on surfaces of ``bsdf``, looked at from ``it``'s outgoing
        direction): (the luminance of the light the photons bring (3, m), cd/m^2; its standard error
        (m,), Y cd/m^2). The density estimate L = sum_p f Phi_p / (pi r^2 N) (Jensen 2001, eq. 7.6);
        the photons gathered are a Poisson sample of the photon paths, so its variance is
        sum_p Y(f Phi_p)^2 / (pi r^2 N)^2 (the radius' bias, a blur over r, is not in it). With a
        ``tally`` ((stored,), the caller's: the map holds no state, so that one map serves several
        analyses), each photon's contributions, times the points' ``weight`` (3, m), are added to it."""
        m = len(it)
        if self.grid is None or m == 0:
            return np.zeros((3, m)), np.zeros(m)
        per_photon = None if tally is None or weight is None else (weight, tally)
        g = gather(self.grid, it, bsdf, np.zeros(m, np.int64), squares=True, per_photon=per_photon)
        return g.sums * self.scale, np.sqrt(g.squares) * self.scale

    def clear_share(self, p: np.ndarray) -> np.ndarray:
        """At points ``p`` (3, m) mm on scattering surfaces: the share of the photons near each (in the
        2 x 2 x 2 cells of side 2 r around it, a span of 4 r) that crossed an LCD through a clear cell
        (transmittance at least CLEAR_CELL of a clear one), among those that crossed an LCD; NaN where
        fewer than CLEAR_SHARE_PHOTONS did (no LCD; off the LCD's image, where a lens ghost's few photons
        land). Photons are counted, not weighed: an LCD passes a photon with its
        cell's transmittance as a weight, so the counts follow where each cell's image falls on the
        screen (its symbols and background), not how bright it is."""
        m = p.shape[1]
        out = np.full(m, np.nan)
        if self.lcd is None or self.grid is None or m == 0:
            return out
        tagged = np.isfinite(self.lcd)
        clear = np.concatenate([[0], np.cumsum(tagged & (self.lcd >= CLEAR_CELL))])
        every = np.concatenate([[0], np.cumsum(tagged)])
        _, lo, hi = self.grid.candidates(p, np.zeros(m, np.int64))
        n_clear = (clear[hi] - clear[lo]).sum(axis=1)
        n_all = (every[hi] - every[lo]).sum(axis=1)
        np.divide(n_clear, n_all, out=out, where=n_all >= CLEAR_SHARE_PHOTONS)
        return out

    @property
    def scale(self) -> float:
        """1 / (pi r^2 N), 1/mm^2: a gathered sum of f Phi times it is a luminance, cd/m^2."""
        return 1.0 / (math.pi * self.radius_mm ** 2 * self.emitted)

    def new_tally(self) -> np.ndarray:
        """A tally for :meth:`luminance`: what each photon adds to the luminances looked up with it."""
        return np.zeros(self.stored)

    def sum_standard_error(self, tally: np.ndarray) -> float:
        """The standard error (cd/m^2) of the sum of the weighted luminances looked up with ``tally``:
        sqrt(sum_p (T_p scale)^2), T_p a photon's tally. The photons are a Poisson sample, so the photons
        that several points share count (the sum of the points' own standard errors would take them as
        fully correlated); for a fixed number of particles it is conservative."""
        if not self.stored:
            return 0.0
        return float(np.sqrt(np.sum(tally * tally)) * self.scale)

    def summary(self) -> dict:
        """What the map is, for a result's JSON."""
        return {"photons_emitted": self.emitted, "photons_stored": self.stored, "radius_mm": self.radius_mm,
                "target_photons_per_gather": self.gather, "photon_paths_cut_at_max_depth": self.paths_cut,
                "seed": self.seed}


@register
class PhotonTracer(BackwardTracer):
    name = "photon"
    summary = ("retina -> specular chain -> visibility points, gathered from photons of the lights "
               "(paper sec. 4.1, progressive radius)")
    noise_advice = (", or raise methods.photon.radius_mm (less noise, more blur); where no scattering surface is "
                    "in view, use the forward or backward method")
    components = {"hit": "samples per pixel", "connection": "samples per pixel", "photon": "samples per pixel"}
    #: A visibility point's direct light is the connection and one sample of the surface's own law
    #: (:meth:`_direct_by_sampling`), weighted by the power heuristic.
    mis_with_hits = True
    efficiency_definition = ("retina samples that reached a source, connected to one or gathered a photon / "
                             "samples")
    found_what = "found light (a source, a connection or a photon)"
    probed_paths = "photon paths"

    #: What the pilot measures besides the reference: the initial radius, whence it came, the roulette scale.
    PILOT_STATE = ("r0", "radius_from", "photon_scale")

    def __init__(self, world, seed, batch_size=None, options=None):
        super().__init__(world, seed, batch_size, options)
        self.alpha = float(self.opts["alpha"])
        self.r0 = float(self.opts["radius_mm"]) or None  # None: measured by the pilot
        self.radius_from = "methods.photon.radius_mm" if self.r0 is not None else None
        w = self.world
        can_emit = w.accel is not None and w.lights.total_flux_lm > 0
        self.particles = Particles(w) if can_emit else None
        self._vis: list[tuple] = []
        self._footprint_pass = False
        #: Eye samples per batch where a batch covers part of a pass (:meth:`fit_batch`), else None.
        self.eye_batch: int | None = self.opts.get("_eye_batch")
        #: The photon pass's roulette scale (PhotonPass.potential), set by the pilot (:meth:`pilot_mean`).
        self.photon_scale = math.inf
        if not w.environment.is_black:
            self.warnings.append("the photon method's photons leave the lights only: environment light that reaches "
                                 "a scattering surface after a bounce is not counted (what the eye sees of the "
                                 "environment through specular optics, and its direct light on scattering "
                                 "surfaces, is)")

    # -- the initial radius ------------------------------------------------------------------------
    def footprint(self, rng: np.random.Generator) -> float:
        """The pixel's footprint (mm) on the surfaces in view: the median distance between the
        visibility points of neighbouring pixels, from rays through the pupil centre on a grid of
        pixels; 0 where no two neighbours reach the same scattering surface."""
        eye = self.eye
        w, h = eye.width, eye.height
        stride = max(1, int(math.ceil(math.sqrt(w * h / FOOTPRINT_PIXELS))))
        xs, ys = np.arange(0, w, stride), np.arange(0, h, stride)
        gx, gy = np.meshgrid(xs, ys)
        pix = (gy * w + gx).reshape(-1)
        n = len(pix)
        sx = (2 * ((pix % w) + 0.5) / w - 1) * eye.half_x
        sy = (1 - 2 * ((pix // w) + 0.5) / h) * eye.half_y
        o, d, _ = eye.generate_rays(sx, sy, np.zeros((2, n)))
        state = PathState(o, d, np.ones((3, n), F32), np.arange(n), np.zeros(n, np.int64), np.zeros(n),
                          np.ones(n, bool), {"sample": np.arange(n), "splits": np.zeros(n, np.int8)})
        ctx = Context(self.world, rng, Timers(), Splats())
        ctx.sample_found = np.zeros(n, bool)
        self._vis, self._footprint_pass = [], True
        try:
            if self.world.accel is not None:
                trace(self, state, ctx, self.max_depth, probe=False)
        finally:
            vis, self._vis, self._footprint_pass = self._vis, [], False
        point = np.full((3, n), np.nan)
        slot = np.full(n, -1)
        best = np.full(n, -1.0)
        for it, beta, owner, _rep, _sample, _bsdf in vis:
            y = luminance3(beta)
            order = np.argsort(y, kind="stable")  # the brightest branch of each grid pixel is written last
            own, yy = owner[order], y[order]
            better = yy > best[own]
            own_b = own[better]
            point[:, own_b] = take(it.p, order[better])
            slot[own_b] = it.slot[order[better]]
            best[own_b] = yy[better]
        grid_point = point.reshape(3, len(ys), len(xs))
        grid_slot = slot.reshape(len(ys), len(xs))
        gaps = []
        for a, b, sa, sb in ((grid_point[:, :, 1:], grid_point[:, :, :-1], grid_slot[:, 1:], grid_slot[:, :-1]),
                             (grid_point[:, 1:, :], grid_point[:, :-1, :], grid_slot[1:, :], grid_slot[:-1, :])):
            same = (sa == sb) & (sa >= 0)
            gaps.append(np.sqrt(((a - b) ** 2).sum(axis=0))[same])
        gaps = np.concatenate(gaps) / stride
        gaps = gaps[np.isfinite(gaps) & (gaps > 0)]
        return float(np.median(gaps)) if len(gaps) else 0.0

    def initial_radius(self, rng: np.random.Generator) -> float:
        """r_0 (mm) where ``radius_mm`` is 0: FOOTPRINT_RADII pixel footprints, widened so that a lit
        visibility point of a default batch's replicate gathers about TARGET_PHOTONS photons (from a
        pilot photon pass gathered at the footprint radius), at most MAX_FOOTPRINT_RADII footprints. A
        scene whose scattering surfaces no two neighbouring pixels see gets 1e-3 of its extent."""
        r_fp = FOOTPRINT_RADII * self.footprint(rng)
        if r_fp <= 0:
            extent = self.world.accel.extent if self.world.accel is not None else 1.0
            self.radius_from = "1e-3 of the scene's extent (no scattering surface on the footprint grid)"
            return float(1e-3 * max(extent, 1e-3))
        n = PILOT_PHOTONS
        k = min(n, PILOT_SAMPLES_PER_PIXEL * self.npix)
        ctx = Context(self.world, rng, Timers(), Splats())
        counts = []
        self._batch(ctx, rng.integers(0, self.npix, k), np.zeros(k, np.int64), 1, n, r_fp, counts)
        counts = np.concatenate(counts) if counts else np.zeros(0)
        lit = counts[counts > 0]
        self.radius_from = f"{FOOTPRINT_RADII} x the median pixel footprint on the surfaces in view"
        if len(lit) == 0:
            return r_fp
        per_batch = lit.mean() * (DEFAULT_BATCH / REPLICATES) / n  # photons within r_fp per replicate
        r = r_fp * math.sqrt(TARGET_PHOTONS / per_batch)
        if r <= r_fp:
            return r_fp
        if r >= MAX_FOOTPRINT_RADII / FOOTPRINT_RADII * r_fp:
            self.radius_from = f"{MAX_FOOTPRINT_RADII} pixel footprints (the most; few photons reach the surface)"
            return MAX_FOOTPRINT_RADII / FOOTPRINT_RADII * r_fp
        self.radius_from = f"{TARGET_PHOTONS:g} photons per lit visibility point and replicate of a default batch"
        return float(r)

    def _check_given_radius(self, rng: np.random.Generator):
        """Warn, before the pilot, of a ``radius_mm`` far larger than the automatic one can be: each
        visibility point gathers every photon of a disk that size, so that the number of pairs, the time
        of a batch (and of a stop, which waits for it) and the blur grow with its square (10 mm on
        hud-screen, 107 pixel footprints: 4,487 photons per point and 500 s for 200,000 rays)."""
        footprint = self.footprint(rng)
        if footprint > 0 and self.r0 > GIVEN_RADIUS_WARN * MAX_FOOTPRINT_RADII * footprint:
            self.warn_early(
                f"methods.photon.radius_mm = {self.r0:g} is {self.r0 / footprint:.3g} pixel footprints on the surface "
                f"in view (the automatic radius is {FOOTPRINT_RADII:g} to {MAX_FOOTPRINT_RADII:g}): every visibility "
                "point gathers the photons of a disk that size, so each batch is slow (a stop waits for the one "
                "running) and the image is blurred over it; 0 chooses the radius")

    def fit_batch(self, budget):
        """Batches keep their photons and their REPLICATES passes over the pixels where such a batch
        takes at most :data:`BATCH_SHARE_OF_TIME` of a budget in seconds (by the pilot's pace, photons
        and eye samples alike). Where it would take longer (a large retina, a short budget), a batch
        covers part of one pass, as the backward method's do (:meth:`batch_pixels`: one sample through
        each pixel of its part, one replicate, counts per pixel), and its photons shrink in the same
        proportion (at least :data:`MIN_BATCH`): a render can stop after any batch. The gather radius
        follows the batch index whatever a batch's photons (:func:`radius_schedule`)."""
        self.reference_luminance  # noqa: B018
        if not self.auto_batch or budget.seconds is None or self.eye_batch is not None:
            return
        pilot_eye_samples = min(PILOT_PATHS, PILOT_SAMPLES_PER_PIXEL * self.npix)  # as pilot_mean traces them
        pace = (PILOT_PATHS + pilot_eye_samples) / max(self.pilot_seconds, 1e-6)
        whole = self.batch_size + REPLICATES * self.npix
        share = pace * budget.seconds * BATCH_SHARE_OF_TIME / whole
        eye = max(MIN_BATCH, int(share * REPLICATES * self.npix))
        if eye >= self.npix:
            return  # a batch of at least one pass: whole batches overrun by at most that pass
        self.eye_batch = eye
        self.batch_size = max(MIN_BATCH, int(share * self.batch_size))

    def worker_options(self) -> dict:
        return dict(self.opts) | {"_eye_batch": self.eye_batch}

    def radius(self, batch: int) -> float:
        """The gather radius (mm) of batch ``batch`` (:func:`radius_schedule`)."""
        return radius_schedule(self.r0, self.alpha, batch)

    # -- the batch ---------------------------------------------------------------------------------
    def _photons(self, ctx, n: int, replicates: int, radius: float) -> tuple[PhotonGrid | None, PhotonGrid | None]:
        """The photon pass: n particles dealt into ``replicates``, with the batch's roulette; their
        photons in a grid, and those of the paths cut at max_depth and followed further (where the
        batch has a probe stream) in a second: (grid, probe grid), either None where empty."""
        if self.particles is None or n == 0:
            return None, None
        pp = PhotonPass(self.particles, store_direct=not self.next_event, scale=self.photon_scale)
        pctx = Context(self.world, ctx.rng, ctx.timers, roulette=ctx.roulette, store=ctx.store,
                       probe_rng=ctx.probe_rng)
        cut = pp.run(pctx, n, replicates, self.max_depth)
        _tally(ctx, "photons_emitted", n)
        _tally(ctx, "photon_paths_cut", cut)

        def grid(stored):
            arrays = stacked(stored)
            return None if arrays is None else PhotonGrid(*arrays, radius)

        main = grid(pp.stored)
        if main is not None:
            _tally(ctx, "photons_stored", len(main))
        return main, grid(pp.probe_stored)

    def _gather(self, ctx, grid: PhotonGrid | None, vis: list[tuple], per_replicate: np.ndarray,
                counts: list | None = None):
        """Density estimates at the visibility points ``vis`` into the "photon" component; with
        ``counts``, the number of photons each point gathered is appended to it."""
        if grid is None or not len(grid):
            return
        r2pi = math.pi * grid.radius * grid.radius
        by_material: dict[int, list] = {}
        for entry in vis:
            by_material.setdefault(id(entry[5]), []).append(entry)
        for entries in by_material.values():
            it = Interaction.concat([e[0] for e in entries])
            beta = np.concatenate([e[1] for e in entries], axis=1)
            owner, rep, sample = (np.concatenate([e[k] for e in entries]) for k in (2, 3, 4))
            g = gather(grid, it, entries[0][5], rep)
            for flux in g.flux:
                _tally(ctx, "photon_flux_gathered", flux)
            _tally(ctx, "photons_gathered", g.pairs)
            if counts is not None:
                counts.append(g.found)
            value = beta * g.sums / (r2pi * per_replicate[rep])
            self._add(ctx, "photon", owner, rep, sample, value)

    def _batch(self, ctx, pix: np.ndarray, rep: np.ndarray, replicates: int, photons: int, radius: float,
               counts: list | None = None) -> int:
        """Photons gathered at ``radius`` (mm), then eye samples through ``pix`` (replicates ``rep``)
        gathered wave by wave; the samples that found light. The photons of paths cut at max_depth
        and followed further (the probe) are gathered at the same points into a tally of their
        luminance per component (``ctx.store``, as tracer.transport.path.probe_cut keeps it), which
        the image never sees."""
        grid, probe_grid = self._photons(ctx, photons, replicates, radius)
        per_replicate = np.array([len(range(r, photons, replicates)) for r in range(replicates)], np.float64)
        ctx.sample_found = np.zeros(len(pix), bool)
        probe_ctx = None
        if probe_grid is not None:
            probe_ctx = Context(self.world, ctx.rng, ctx.timers, Splats())
            probe_ctx.sample_found = np.zeros(len(pix), bool)
        for a in range(0, len(pix), WAVE):
            b = min(a + WAVE, len(pix))
            self._vis = []
            state = self.camera_paths(ctx.rng, pix[a:b], rep[a:b], a)
            # No probe of paths cut at max_depth: their visibility points would need a gather of their
            # own (eye paths here run along specular chains only; the cut count is still reported).
            self.truncated += trace(self, state, ctx, self.max_depth, probe=False)
            _tally(ctx, "visibility_points", sum(len(v[2]) for v in self._vis))
            with ctx.timers("film"):
                self._gather(ctx, grid, self._vis, np.maximum(per_replicate, 1), counts)
                if probe_ctx is not None:
                    self._gather(probe_ctx, probe_grid, self._vis, np.maximum(per_replicate, 1))
            self._vis = []
        if probe_ctx is not None:
            tally_probe(ctx.store, probe_ctx.splats)
        return int(ctx.sample_found.sum())

    def run_batch(self, ctx):
        """One batch (trace_batch has run the pilot first, which sets r_0): REPLICATES passes over the
        pixels, or one sample through each pixel of the batch's part of a pass (:meth:`fit_batch`)."""
        if self.eye_batch is not None:
            pix = self.batch_pixels(ctx.batch, self.eye_batch)
            found = self._batch(ctx, pix, np.zeros(len(pix), np.int64), 1, self.batch_size, self.radius(ctx.batch))
            return len(pix), found, dict.fromkeys(self.components, pix), 1
        pix = np.tile(np.arange(self.npix), REPLICATES)
        rep = np.repeat(np.arange(REPLICATES), self.npix)
        found = self._batch(ctx, pix, rep, REPLICATES, self.batch_size, self.radius(ctx.batch))
        norms = dict.fromkeys(self.components, REPLICATES)
        return len(pix), found, norms, REPLICATES

    def pilot_mean(self, ctx) -> float:
        """r_0 (from the footprint, on the pilot's stream), then the image's mean luminance (cd/m^2) from
        ``batch_size`` photons gathered at as many random pixels, at radius r_0; also the photon pass's
        roulette scale (:class:`PhotonPass`): that mean over the mean luminance of the flux of the
        photons gathered (infinite, so that no photon is thinned, where none was gathered)."""
        if self.r0 is None:
            self.r0 = self.initial_radius(ctx.rng)
        else:
            self._check_given_radius(ctx.rng)
        n = self.batch_size
        k = min(n, PILOT_SAMPLES_PER_PIXEL * self.npix)
        pix = ctx.rng.integers(0, self.npix, k)
        self._batch(ctx, pix, np.zeros(k, np.int64), 1, n, self.r0)
        total = sum(float(luminance3(ctx.splats.gather(c)[2]).sum()) for c in self.components)
        mean = total / k
        pairs, flux = ctx.store.get("photons_gathered", 0), ctx.store.get("photon_flux_gathered", 0.0)
        self.photon_scale = mean / (flux / pairs) if pairs and flux > 0 and mean > 0 else math.inf
        return mean

    # -- hooks of the path loop (eye pass) ---------------------------------------------------------
    def connect(self, state, it, bsdf, ctx):
        """A visibility point: kept for the gather; its direct light from the lights and the environment
        by next-event estimation and by a sample of the surface's law, the two weighted by the power
        heuristic (Veach 1997, sec. 9.2)."""
        self._vis.append((it, state.beta, state.owner, state.rep, state.extra["sample"], bsdf))
        if self._footprint_pass:
            return None
        shadow = super().connect(state, it, bsdf, ctx)
        if self.next_event:
            self._direct_by_sampling(state, it, bsdf, ctx)
        return shadow

    def _direct_by_sampling(self, state, it, bsdf, ctx):
        """The second strategy of a visibility point's direct light: one direction from the surface's
        law (its eye sampler, as backward tracing's paths draw it), one closest-hit ray, and what it
        meets, an emitter or the environment, weighted against the connection's density (the power
        heuristic of :meth:`emitted` and :meth:`escaped`), into the "connection" component. A connection
        alone misses most of a large emitter close to the surface (a backlight 1 mm behind a diffuser),
        whose light comes from a small patch right under the point; this ray finds it. The eye path
        itself still ends here; the photons carry what this ray finds after other events."""
        m = len(state)
        nxt = Next.for_hits(state, 0)
        continue_by_sampling(state, it, self._eye_sampler[id(bsdf)], ctx, RADIANCE, nxt, slice(0, m))
        go = np.flatnonzero(nxt.alive[:m])
        if len(go) == 0:
            return
        ray = CompactedState(take(nxt.o, go), take(nxt.d, go), nxt, go)
        hits = self.world.accel.intersect(ray.o, ray.d)
        if len(self.lights):
            tri = take(self.lights.face_light_ext, hits.face)
            e = np.flatnonzero(tri >= 0)
            if len(e):
                lit = ray.take(e)
                self.emitted(lit, tri[e], lit.o + hits.t[e] * lit.d, hits.t[e], ctx, component="connection")
        miss = np.flatnonzero(hits.face < 0)
        if len(miss):
            self.escaped(ray.take(miss), ctx, component="connection")

    def continue_paths(self, state, it, bsdf, ctx, nxt, sl):
        """Specular surfaces continue the eye path (with the backward method's splits); the first
        scattering surface ends it."""
        if not bsdf.delta:
            return []
        return super().continue_paths(state, it, bsdf, ctx, nxt, sl)

    # -- the report --------------------------------------------------------------------------------
    def finish(self, result):
        figures = {k: int(result.extra.pop(k, 0)) for k in STORE_KEYS}
        super().finish(result)
        batches = max(result.batches, 1)
        r0 = self.r0 if self.r0 is not None else 0.0
        vis = figures["visibility_points"]
        result.extra["photon"] = {
            "replicates_per_batch": REPLICATES,
            "initial_radius_mm": r0,
            "initial_radius_from": self.radius_from,
            "alpha": self.alpha,
            "final_radius_mm": radius_schedule(r0, self.alpha, batches - 1) if r0 else 0.0,
            "photons_emitted": figures["photons_emitted"],
            "photons_stored": figures["photons_stored"],
            "photon_paths_cut_at_max_depth": figures["photon_paths_cut"],
            "eye_paths_cut_at_max_depth": int(self.truncated),
            "visibility_points": vis,
            "photons_per_visibility_point": figures["photons_gathered"] / vis if vis else 0.0,
        }
        film = result.film
        total = sum(float(luminance3(film.sums[c]).sum()) for c in self.components)
        result.extra["component_shares"] = {
            c: (float(luminance3(film.sums[c]).sum()) / total if total > 0 else 0.0) for c in self.components}
        cut_eye, emitted = int(self.truncated), figures["photons_emitted"]
        if cut_eye > CUT_WARN_SHARE * max(result.paths, 1):
            result.warnings.append(
                f"{cut_eye:,} eye paths (from {result.paths:,} samples, split at glass) were cut at "
                f"methods.photon.max_depth = {self.max_depth} before they reached a scattering surface: the light "
                "they would find is missing from the image (an eye path cut there has no visibility point, so its "
                "light is not measured): raise max_depth")
        if vis == 0 and result.paths:
            scattering = not all(m.delta for m in self.world.materials)
            why = (f"the eye paths were cut at methods.photon.max_depth = {self.max_depth} before any reached one: "
                   "raise it" if cut_eye and scattering else
                   "the image holds only the sources and environment seen through specular optics: use the backward "
                   "method, which renders them alone")
            result.warnings.append(
                f"no eye path reached a scattering (non-specular) surface in {result.paths:,} samples: the photon maps "
                f"were never used (efficiency {result.efficiency:.3g}); {why}")
        elif figures["photons_stored"] == 0 and result.paths:
            result.warnings.append(
                f"no photon reached a scattering surface after another event ({emitted:,} emitted; photons are "
                "stored only after their first event, since connections carry direct light): only direct light "
                "lights the surfaces in view, and the backward method renders such a scene alone"
                if self.next_event else
                f"no photon reached a scattering surface ({emitted:,} emitted): the surfaces in view stay dark")
