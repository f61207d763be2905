"""Brightness-theorem analysis: a deterministic second method for what the eye should see.

For a grid of retina pixels the chief ray (through the pupil centre) runs on the same path loop as
the stochastic methods (:mod:`tracer.transport.path`), but deterministically: at every specular
surface it follows every branch (mirror, LCD, coating, both Fresnel branches of a dielectric) with
the product of the reflectances and transmittances along it, and drops a branch by the loop's one
roulette rule, without randomness (below 1e-7 of the brightest source). A branch ends on an emitter
(its luminance), in the environment, or on a scattering surface, whose outgoing luminance toward the
eye is integrated deterministically from the lights it sees directly (the light table's quadrature,
with shadow rays), plus what the environment gives it directly (a sky, a panorama, the sun: directions
drawn from the environment's own distribution on a fixed random stream, with shadow rays). The
predicted apparent luminance of the branch is the product times that
luminance: the brightness theorem (luminance is conserved along a lossless specular chain; see
../shared/reference/hud-physics.md, "Photometry").

Each distinct chain (the sequence of objects and events) is one *path*; in a HUD the dominant path
is the symbol image (windshield reflection, mirror, LCD, the scatterer behind it) and the chain
that refracts into the windshield and reflects at its outer surface is the ghost image.

The chief ray alone predicts a pixel only where what it ends on fills the pupil as seen back through
the chain. Where optics image a small source into the pupil (a Maxwellian view: a condenser, a
concave mirror) only part of the pupil sees it, so :func:`specular_paths` can also follow rays from
stratified points over the whole pupil and average them (the pixel's luminance is the pupil average
of the luminance its rays see, paper eq. 2). What the analysis cannot follow it reports: a
scattering surface whose direct view of a light is blocked by a specular surface (a condenser lens,
a mirror) is lit through optics the quadrature does not trace, so its prediction is a lower bound
(``through_specular`` of the leaves, and ``ChiefRays.specular_blockers``).
"""

from __future__ import annotations

import math
from collections import defaultdict

import numpy as np

from ..core.film import Splats
from ..core.sampling import make_rng, uniform_disk_concentric
from ..core.units import luminance3
from ..core.vec import F32, dot, norm, take
from ..optics.bsdf import DELTA, RADIANCE
from ..optics.materials import LCD
from .path import Context, PathMethod, PathState, Roulette, Timers, segment_to, trace

#: The analysis drops branches whose transfer factor falls below this fraction (of the brightest
#: source's luminance: the roulette's reference is MIN_FACTOR / Roulette.EPSILON of it): far below the
#: weakest chain an image needs, a chain through an LCD's black cells (about 2e-5 on hud-direct) and
#: its higher-order ghosts, or what polarised sunglasses pass of an s-polarised HUD (2e-5).
MIN_FACTOR = 1e-12
#: Quadrature cells of a light triangle are at most this fraction of its distance to the nearest
#: scattering surface (relative error of the centroid rule ~ its square, 1e-4).
QUAD_RATIO = 0.01
#: A (surface point, quadrature cell) pair whose cell is larger than this fraction of its distance is
#: not resolved: the finest level (``level`` of :func:`quadrature_levels`) cannot follow a large light
#: close to a surface, such as a backlight 1 mm behind a screen. Such pairs' light is tallied apart
#: (``coarse`` of the leaves), so that the sections it carries are marked not comparable. The centroid
#: rule's error against Lambert's contour formula, over a square light 100 mm away (points under its
#: centre, a sixth and a third of the way out), with cells of 0.71, 1.0, 1.41, 2.0 and 2.8 times the
#: distance: at most 1.2, 1.7, 3.1, 8.5 and 26 %; analytic-disk's fan cells (0.12 of it) 0.1 %.
QUAD_TRUST = 1.0
#: Point pairs (surface point, quadrature point) per shadow-ray call.
CHUNK = 1 << 16
#: Directions drawn from the environment's own distribution (its sky and its sun by power) at every
#: scattering surface point, for the light the environment gives it directly.
ENV_SAMPLES = 32


def quadrature_levels(world, level: int = 4) -> np.ndarray:
    """The subdivision level of every light triangle's quadrature (T,): the centroid rule's relative
    error is about (h / d)^2 for cells of size h seen from distance d, so a triangle gets the
    smallest level (at most ``level``) whose cells are below QUAD_RATIO of its distance to the
    nearest scattering surface (the bounding box of any object whose material is neither purely
    specular nor black). hud-direct's LED dies, 0.2 mm at some 20 mm, need one point, not 16."""
    tris = world.lights.tris
    if len(tris) == 0:
        return np.zeros(0, np.int64)
    boxes = [(o.vertices.min(axis=0), o.vertices.max(axis=0)) for m in world.materials
             if m.flags != 0 and not m.flags & DELTA for o in m.objects]
    if not boxes:
        return np.ones(len(tris), np.int64)  # no scattering leaf will use the quadrature
    centroid = (tris.v0 + (tris.e1 + tris.e2) / 3).T  # (T, 3)
    lo = np.array([b[0] for b in boxes])[None]  # (1, B, 3)
    hi = np.array([b[1] for b in boxes])[None]
    gap = np.maximum(np.maximum(lo - centroid[:, None], centroid[:, None] - hi), 0.0)
    dist = np.sqrt((gap * gap).sum(axis=2)).min(axis=1)
    size = np.maximum.reduce([norm(e) for e in (tris.e1, tris.e2, tris.e2 - tris.e1)])  # longest edge
    need = np.ceil(size / np.maximum(QUAD_RATIO * dist, 1e-300))
    return np.clip(need, 1, level).astype(np.int64)


class ChiefRays(PathMethod):
    """The analysis' hooks on the path loop; leaves are collected per chain code."""

    mode = RADIANCE

    def __init__(self, world, level: int = 4, environment: bool = True, photons=None, photon_tally=None):
        self.world = world
        self.environment = environment
        #: Light through other surfaces at scattering surfaces (a tracer.methods.photon.PhotonMap), or None.
        self.photons = photons
        #: What each photon adds to the chains' luminances (PhotonMap.luminance's tally), or None.
        self.photon_tally = photon_tally
        self.quad = world.lights.quadrature(quadrature_levels(world, level)) if len(world.lights) else None
        #: Scattering object name -> names of the specular objects that block its direct view of a light.
        self.specular_blockers: dict[str, set[str]] = defaultdict(set)
        delta = np.array([bool(m.flags & DELTA) for m in world.materials] + [False])  # absorbers cast shadows
        self._delta_face = delta[world.face_material] if world.accel is not None else np.zeros(0, bool)
        self.max_lum = world.max_luminance
        self.names = {0: ()}
        self.codes: dict[tuple, int] = {(): 0}
        self.leaves: dict[int, list] = defaultdict(list)
        #: Where chains end on a light or a scattering surface, for :func:`aim_coverage`: (kind
        #: "emission" or "material", object slots (m,), points (3, m), directions toward the eye (3, m),
        #: weight (m,): the luminance an emitter sends along the chain, the chain's transfer factor
        #: at a scattering surface, which may be lit through optics the analysis does not follow; the
        #: rays' indices (m,), pixel times the pupil's samples).
        self.ends: list[tuple] = []

    def _code(self, parent: np.ndarray, labels: list[str], which: np.ndarray | None = None) -> np.ndarray:
        """Chain codes (m,) of chains ``parent`` (m,) extended by ``labels[which]`` (one label for all
        when ``which`` is None); a loop over the distinct (chain, label) pairs only."""
        which = np.zeros(len(parent), np.int64) if which is None else which
        pairs, inverse = np.unique(parent * len(labels) + which, return_inverse=True)
        codes = np.empty(len(pairs), np.int64)
        for i, pair in enumerate(pairs.tolist()):
            key = self.names[pair // len(labels)] + (labels[pair % len(labels)],)
            if key not in self.codes:
                self.codes[key] = len(self.codes)
                self.names[self.codes[key]] = key
            codes[i] = self.codes[key]
        return codes[inverse.reshape(-1)]

    def _by_object(self, slots: np.ndarray, suffix: str = "") -> tuple[list[str], np.ndarray]:
        """(labels "<object name><suffix>" of the distinct slots, index of each ray's label)."""
        objs = self.world.scene.objects
        uniq, inverse = np.unique(slots, return_inverse=True)
        return [objs[s].name + suffix for s in uniq.tolist()], inverse.reshape(-1)

    def _leaf(self, state: PathState, labels: list[str], which: np.ndarray | None, value: np.ndarray,
              through_specular: np.ndarray | None = None, coarse: np.ndarray | None = None,
              photon_se: np.ndarray | None = None):
        codes = self._code(state.extra["sig"], labels, which)
        factor = luminance3(state.beta)
        zero = np.zeros(len(state))
        through_specular = zero if through_specular is None else through_specular
        coarse = zero if coarse is None else coarse
        photon_se = zero if photon_se is None else photon_se
        for c in np.unique(codes):
            k = codes == c
            self.leaves[int(c)].append((state.owner[k], value[:, k].T, factor[k], state.extra["lcd"][k],
                                        through_specular[k], coarse[k], photon_se[k]))

    def escaped(self, state, ctx):
        env = self.world.environment
        if self.environment and not env.is_black:
            self._leaf(state, ["environment"], None, state.beta * env.radiance(state.d))

    def emitted(self, state, tri, p, t, ctx):
        lights = self.world.lights
        beta = state.beta
        if self.world.polar is not None:
            beta = self.world.polar.emitted(beta, state.extra, state.d, lights.slot[tri])
        value = beta * lights.emitted(tri, state.d)
        self.ends.append(("emission", lights.slot[tri], p, -state.d, luminance3(value), state.owner))
        self._leaf(state, *self._by_object(lights.slot[tri]), value)

    def connect(self, state, it, bsdf, ctx):
        """A scattering surface ends the chain: its luminance toward the eye from the lights in direct
        view, the sum over quadrature points of f L_e cos_i cos_e / d^2 dA, with one shadow-ray call
        per chunk of point pairs. Where the first thing between the surface and a light point is a
        specular surface, the light that point would give unblocked is tallied (Y, cd/m^2, times the
        chain's factor) as ``through_specular``, and the blocker is named in ``specular_blockers``.
        The light of pairs whose quadrature cell is too large for their distance (:data:`QUAD_TRUST`)
        is in the prediction and also tallied (Y, cd/m^2) as ``coarse``. With a photon map
        (``photons``) the light that reaches the surface through other surfaces is its density
        estimate (its standard error tallied as ``photon_se``, Y cd/m^2), and the lights' light is
        all followed: ``through_specular`` keeps only the environment's (the blockers are still named)."""
        m = len(state)
        out = np.zeros((3, m))
        through = np.zeros(m)
        coarse = np.zeros(m)
        if self.quad is not None:
            qp, qn, qw, ql, q2, qh = self.quad
            accel = self.world.accel
            step = max(1, CHUNK // max(m, 1))
            for k0 in range(0, qp.shape[1], step):
                k = np.arange(k0, min(k0 + step, qp.shape[1]))
                ii = np.repeat(np.arange(m), len(k))
                kk = np.tile(k, m)
                p = take(it.p, ii)
                v = take(qp, kk) - p
                dist = norm(v)
                w = (v / dist).astype(F32)  # toward the light point
                cos_e = -dot(w, take(qn, kk))
                o, d, tmax = segment_to(accel, p, take(it.ng, ii), take(qp, kk), it.offset[ii])
                blocked = accel.occluded(o, d, tmax)
                sub = it.take(ii)
                f = bsdf.eval(sub, w, RADIANCE)
                g = np.where((cos_e > 0) | q2[kk], np.abs(cos_e) * qw[kk] / (dist * dist), 0.0)
                contrib = f * take(ql, kk) * g
                lost = np.flatnonzero(blocked & (luminance3(contrib) > 0))
                if len(lost):
                    spec, face = self._specular_first(take(o, lost), take(d, lost))
                    if spec.any():
                        lost, face = lost[spec], face[spec]
                        np.add.at(through, ii[lost], luminance3(take(contrib, lost)))
                        self._name_blockers(it.slot[ii[lost]], face)
                contrib[:, blocked] = 0.0
                out += contrib.reshape(3, m, len(k)).sum(axis=2)
                rough = np.flatnonzero(qh[kk] > QUAD_TRUST * dist)
                if len(rough):
                    np.add.at(coarse, ii[rough], luminance3(take(contrib, rough)))
        photon_se = None
        if self.photons is not None:  # the lights' light through optics, followed (the environment's is not)
            value, photon_se = self.photons.luminance(it, bsdf, weight=state.beta, tally=self.photon_tally)
            out += value
            through[:] = 0.0
        env = self.world.environment
        if self.environment and not env.is_black:
            out += self._environment_light(it, bsdf, ctx.rng, through)
        self.ends.append(("material", it.slot, it.p, -state.d, luminance3(state.beta), state.owner))  # lit or not
        factor = luminance3(state.beta)
        self._leaf(state, *self._by_object(it.slot, ":scatter"), state.beta * out, factor * through, factor * coarse,
                   None if photon_se is None else factor * photon_se)
        return None

    def _specular_first(self, o: np.ndarray, d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """For blocked shadow rays (origins, directions (3, k)): whether the first surface they meet is
        specular (k,), and its face (k,)."""
        face = self.world.accel.intersect(o, d).face
        spec = face >= 0
        spec[spec] = self._delta_face[face[spec]]
        return spec, face

    def _name_blockers(self, slots: np.ndarray, faces: np.ndarray):
        """Record the specular objects of ``faces`` as blocking the light of the scattering objects
        ``slots`` (``specular_blockers``)."""
        objs = self.world.scene.objects
        blockers = {objs[b].name for b in np.unique(self.world.accel.face_slot[faces]).tolist()}
        for s in np.unique(slots).tolist():
            self.specular_blockers[objs[s].name] |= blockers

    def _environment_light(self, it, bsdf, rng: np.random.Generator, through: np.ndarray) -> np.ndarray:
        """The luminance (3, m) that surfaces ``it`` send toward the eye from the environment they see
        directly (a sky, a panorama, the sun): the mean over :data:`ENV_SAMPLES` directions drawn from
        the environment's own distribution (its sun among them by power) of f L / p, with a shadow ray
        each, on the analysis' fixed random stream (the pupil points' sampling error, which the
        sections' standard errors measure, includes it). Light blocked by a specular surface (a
        windshield between a dashboard and the sky) is tallied into ``through`` as the quadrature's is."""
        env, accel = self.world.environment, self.world.accel
        m = len(it)
        out = np.zeros((3, m))
        chunk = max(1, CHUNK // ENV_SAMPLES)  # surface points per shadow-ray call
        for a in range(0, m, chunk):
            b = min(m, a + chunk)
            ii = np.repeat(np.arange(a, b), ENV_SAMPLES)
            w, radiance, pdf = env.sample(rng.random((2, len(ii))))
            w = w.astype(F32)
            sub = it.take(ii)
            value = bsdf.eval(sub, w, RADIANCE) * radiance * (1.0 / (ENV_SAMPLES * np.maximum(pdf, 1e-300)))
            lit = np.flatnonzero(luminance3(value) > 0)
            if len(lit) == 0:
                continue
            w_lit = take(w, lit)
            o = accel.spawn(take(sub.p, lit), take(sub.ng, lit), w_lit, sub.offset[lit])
            blocked = np.flatnonzero(accel.occluded(o, w_lit, np.full(len(lit), np.inf)))
            if len(blocked):
                spec, face = self._specular_first(take(o, blocked), take(w_lit, blocked))
                lost = lit[blocked]
                if spec.any():
                    np.add.at(through, ii[lost[spec]], luminance3(take(value, lost[spec])))
                    self._name_blockers(sub.slot[lost[spec]], face[spec])
                value[:, lost] = 0.0
            for c in range(3):
                out[c, a:b] += np.bincount(ii - a, weights=value[c], minlength=b - a)
        return out

    def spare(self, bsdf, hits):
        return hits * 2 if bsdf.delta else 0

    def continue_paths(self, state, it, bsdf, ctx, nxt, sl):
        """Every delta branch, as further paths (``nxt[sl]`` is left dead: the analysis always splits)."""
        if not bsdf.delta:
            return []
        names, which = self._by_object(it.slot)
        out = []
        rel = None
        if isinstance(bsdf, LCD):
            rel = luminance3(bsdf.modulation(it))
        polar = self.world.polar
        for wo, weight, flags, label in bsdf.lobes(it, RADIANCE):
            if polar is not None:  # s and p (the Stokes row vector) followed through the chain
                beta, stokes, frame = polar.scatter(state.beta, state.extra, it, bsdf, wo, weight,
                                                    np.full(len(it), flags, np.int8), False)
            else:
                beta = state.beta * weight
            keep = np.flatnonzero(ctx.roulette.keep(luminance3(beta) * self.max_lum))
            if len(keep) == 0:
                continue
            lcd = state.extra["lcd"]
            if rel is not None:
                lcd = np.where(np.isnan(lcd), rel, lcd)
            sig = self._code(state.extra["sig"][keep], [f"{nm}:{label}" for nm in names], which[keep])
            w_k = take(wo, keep)
            o = ctx.world.accel.spawn(take(it.p, keep), take(it.ng, keep), w_k, it.offset[keep])
            extra = {"sig": sig, "lcd": lcd[keep]}
            if polar is not None:
                extra |= {"stokes": take(stokes, keep), "frame": take(frame, keep)}
            out.append(PathState(o, w_k, take(beta, keep), state.owner[keep], state.rep[keep],
                                 np.zeros(len(keep)), np.ones(len(keep), bool), extra))
        return out


def specular_paths(world, stride: int | None = None, max_depth: int = 12, directions: np.ndarray | None = None,
                   pixels: np.ndarray | None = None, pupil_grid: int = 0, environment: bool = True, seed: int = 0,
                   photons=None, photon_tally: np.ndarray | None = None):
    """Follow chief rays of a pixel grid (or along given world ``directions`` (p, 3) from the pupil
    centre, or of the given flat ``pixels``) through all specular branches.

    With ``pupil_grid`` n > 0 every pixel is followed by n x n rays instead of its chief ray, from
    points stratified over the pupil disk and uniform over the pixel's area (random by ``seed``), and
    each ray's luminance is divided by n^2, so that the sum over a pixel's rays is its average over
    the pupil and the pixel: the pixel's luminance where its rays see different things (paper eq. 2).
    ``environment`` False leaves the environment out (for methods that do not render it). ``photons``
    (a :class:`tracer.methods.photon.PhotonMap`, or None) adds the light that reaches scattering
    surfaces through other surfaces (a projection lens), which the quadrature does not follow; with a
    ``photon_tally`` (:meth:`~tracer.methods.photon.PhotonMap.new_tally`), what each photon adds to the
    rays' luminances (the luminances' Y, each ray's as its path carries it) is summed into it.

    Returns a dict with ``pixels`` (p,) flat indices analysed (or 0..p-1 for given directions),
    ``stride``, ``grid``, ``pupil_samples`` (n^2, or 1 for chief rays), ``specular_blockers``
    (scattering object -> specular objects blocking its view of a light) and ``paths``: a list of
    {"path": str, "pixel" (k,) positions into ``pixels``, "luminance" (k, 3) predicted cd/m^2,
    "factor" (k,) Y of the product of R and T, "lcd" (k,) the first LCD's transmittance relative to
    a clear cell, NaN if none, "through_specular" (k,) Y cd/m^2 a scattering leaf would add were its
    specular blockers clear, "coarse" (k,) Y cd/m^2 of the predicted luminance that comes from lights
    closer than the quadrature resolves (:data:`QUAD_TRUST`), "photon_se" (k,) Y cd/m^2 the standard
    error of the photon map's part of "luminance" (0 without one), "ray" (k,) the ray's index: pixel
    position * n^2 + sample}.
    """
    eye = world.eye
    w, h = eye.width, eye.height
    lens = None
    if directions is not None:
        stride, jj = 1, np.zeros((1, len(directions)))
        pixels = np.arange(len(directions))
        d = np.asarray(directions, dtype=np.float64).T
        d = d / norm(d)
        o = np.repeat(eye.position.reshape(3, 1), d.shape[1], axis=1)
    else:
        if pixels is None:
            if stride is None:
                stride = max(1, math.ceil(math.sqrt(w * h / 40000)))
            jj, ii = np.meshgrid(np.arange(stride // 2, h, stride), np.arange(stride // 2, w, stride), indexing="ij")
            pixels = (jj * w + ii).ravel()
        else:
            pixels = np.asarray(pixels, dtype=np.int64)
            jj = np.zeros((1, len(pixels)))
        sx, sy = eye.pixel_centers()
        px = pixels
        rx, ry = sx[px % w], sy[px // w]
        if pupil_grid > 0:
            n2 = pupil_grid * pupil_grid
            px = np.repeat(pixels, n2)
            cell = np.tile(np.arange(n2), len(pixels))
            rng = make_rng(seed)
            u = (np.stack([cell % pupil_grid, cell // pupil_grid]) + rng.random((2, len(px)))) / pupil_grid
            lens = uniform_disk_concentric(u) * eye.pupil_radius
            # A point uniform over the pixel too: the pixel's value is its average over its area and
            # the pupil (paper eq. 2), which the render estimates.
            jitter = rng.random((2, len(px))) - 0.5
            rx = sx[px % w] + jitter[0] * eye.pixel_w
            ry = sy[px // w] + jitter[1] * eye.pixel_h
        o, d, _ = eye.generate_rays(rx, ry, lens if lens is not None else np.zeros((2, len(px))))
    samples = pupil_grid * pupil_grid if lens is not None else 1
    n = d.shape[1]
    method = ChiefRays(world, environment=environment, photons=photons, photon_tally=photon_tally)
    beta = np.ones((3, n), F32)
    extra = {"sig": np.zeros(n, np.int64), "lcd": np.full(n, np.nan)}
    if world.polar is not None:  # the eye's detector row (and analyser): s and p followed separately
        beta, pol = world.polar.start_camera(beta, d.astype(F32))
        extra |= pol
    state = PathState(o, d.astype(F32), beta, np.arange(n), np.zeros(n, np.int64), np.zeros(n, F32),
                      np.ones(n, bool), extra)
    ctx = Context(world, make_rng(0), Timers(), Splats(), Roulette(MIN_FACTOR / Roulette.EPSILON * method.max_lum))
    trace(method, state, ctx, max_depth)
    paths = []
    for s, parts in method.leaves.items():
        own = np.concatenate([p[0] for p in parts]) // samples
        lum = np.concatenate([p[1] for p in parts]) / samples
        fac = np.concatenate([p[2] for p in parts])
        lc = np.concatenate([p[3] for p in parts])
        thr = np.concatenate([p[4] for p in parts]) / samples
        rough = np.concatenate([p[5] for p in parts]) / samples
        se = np.concatenate([p[6] for p in parts]) / samples
        paths.append({"path": " > ".join(method.names[s]), "pixel": own, "luminance": lum, "factor": fac, "lcd": lc,
                      "through_specular": thr, "coarse": rough, "photon_se": se,
                      "ray": np.concatenate([p[0] for p in parts])})
    paths.sort(key=lambda p: -float(luminance3(p["luminance"].T).sum()))
    return {"pixels": pixels, "stride": stride, "grid": jj.shape, "paths": paths, "pupil_samples": samples,
            "specular_blockers": {k: sorted(v) for k, v in method.specular_blockers.items()},
            "ends": method.ends}


def aim_coverage(world, ends: list[tuple]) -> dict[str, dict]:
    """For every object whose light paths are aimed (an emission's or a scattering material's
    ``aim``, tracer.optics.aimed): the share of what the analysed chains carry from it to the eye
    (``ends``: :attr:`ChiefRays.ends` of one or more calls, weighted as it says) that leaves it inside
    its aim target, {name: {"target", "coverage"}}.
    Below 1, forward tracing finds the rest only through the unaimed share of its samples, in rare
    heavy particles: glass or a lens between the object and its target bends the aimed light off it
    (a plane slab brings an image t (1 - 1/n) nearer), or the target is smaller than what the eye
    receives light through."""
    kinds: dict[tuple, list] = defaultdict(list)
    for kind, slot, p, wo, lum, _ in ends:
        kinds[kind].append((slot, p, wo, lum))
    objects = world.scene.objects
    out = {}
    for kind, parts in kinds.items():
        slot = np.concatenate([s for s, _, _, _ in parts])
        p = np.concatenate([q for _, q, _, _ in parts], axis=1)
        wo = np.concatenate([w for _, _, w, _ in parts], axis=1)
        lum = np.concatenate([v for _, _, _, v in parts])
        for s in np.unique(slot).tolist():
            o = objects[s]
            aim = o.emission.aim if kind == "emission" else o.material.aim
            k = np.flatnonzero((slot == s) & (lum > 0))
            if aim is None or aim.share <= 0 or len(k) == 0:
                continue
            sign = -1.0 if aim.mode == "away" else 1.0
            inside = world.target(aim.target).pdf(take(p, k), take(wo, k) * sign) > 0
            total = float(lum[k].sum())
            entry = out.setdefault(o.name, {"target": aim.target, "inside": 0.0, "luminance": 0.0})
            entry["inside"] += float(lum[k][inside].sum())
            entry["luminance"] += total
    return {name: {"target": e["target"], "coverage": e["inside"] / e["luminance"]} for name, e in out.items()}
