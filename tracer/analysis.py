"""Brightness-theorem analysis: a deterministic second method for what the eye should see.

For a grid of retina pixels the chief ray (through the pupil centre) runs on the same path loop as
the stochastic methods (:mod:`tracer.integrators.path`), but deterministically: at every specular
surface it follows every branch (mirror, LCD, coating, both Fresnel branches of a dielectric) with
the product of the reflectances and transmittances along it, and drops a branch by the loop's one
roulette rule, without randomness (below 1e-5 of the brightest source). A branch ends on an emitter
(its luminance), in the environment, or on a scattering surface, whose outgoing luminance toward the
eye is integrated deterministically from the lights it sees directly (the light table's quadrature,
with shadow rays). The predicted apparent luminance of the branch is the product times that
luminance: the brightness theorem (luminance is conserved along a lossless specular chain; see
../shared/reference/hud-physics.md, "Photometry").

Each distinct chain (the sequence of objects and events) is one *path*; in a HUD the dominant path
is the symbol image (windshield reflection, mirror, LCD, the scatterer behind it) and the chain
that refracts into the windshield and reflects at its outer surface is the ghost image.
"""

from __future__ import annotations

import math
from collections import defaultdict

import numpy as np

from .film import Splats
from .integrators.path import Context, PathMethod, PathState, Roulette, Timers, segment_to, trace
from .optics.bsdf import RADIANCE
from .optics.materials import LCD
from .sampling import make_rng
from .units import luminance3
from .vec import F32, dot, norm

#: The analysis drops branches whose transfer factor falls below this fraction (of the brightest
#: source's luminance: the roulette's reference is MIN_FACTOR / Roulette.EPSILON of it).
MIN_FACTOR = 1e-5
#: Point pairs (surface point, quadrature point) per shadow-ray call.
CHUNK = 1 << 16


class ChiefRays(PathMethod):
    """The analysis' hooks on the path loop; leaves are collected per chain code."""

    mode = RADIANCE

    def __init__(self, world, level: int = 4):
        self.world = world
        self.quad = world.lights.quadrature(level) if len(world.lights) else None
        self.max_lum = world.max_luminance
        self.names = {0: ()}
        self.codes: dict[tuple, int] = {(): 0}
        self.leaves: dict[int, list] = defaultdict(list)

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

    def _leaf(self, state: PathState, labels: list[str], which: np.ndarray | None, value: np.ndarray):
        codes = self._code(state.extra["sig"], labels, which)
        factor = luminance3(state.beta)
        for c in np.unique(codes):
            k = codes == c
            self.leaves[int(c)].append((state.owner[k], value[:, k].T, factor[k], state.extra["lcd"][k]))

    def escaped(self, state, ctx):
        env = self.world.environment
        if not env.is_black:
            self._leaf(state, ["environment"], None, state.beta * env.radiance(state.d))

    def emitted(self, state, tri, p, t, ctx):
        lights = self.world.lights
        self._leaf(state, *self._by_object(lights.slot[tri]), state.beta * lights.emitted(tri, state.d))

    def connect(self, state, it, bsdf, ctx):
        """A scattering surface ends the chain: its luminance toward the eye from the lights in direct
        view, the sum over quadrature points of f L_e cos_i cos_e / d^2 dA, with one shadow-ray call
        per chunk of point pairs."""
        m = len(state)
        out = np.zeros((3, m))
        if self.quad is not None:
            qp, qn, qw, ql, q2 = self.quad
            accel = self.world.accel
            step = max(1, CHUNK // max(m, 1))
            for k0 in range(0, qp.shape[1], step):
                k = np.arange(k0, min(k0 + step, qp.shape[1]))
                ii = np.repeat(np.arange(m), len(k))
                kk = np.tile(k, m)
                p = np.take(it.p, ii, axis=1)
                v = np.take(qp, kk, axis=1) - p
                dist = norm(v)
                w = (v / dist).astype(F32)  # toward the light point
                cos_e = -dot(w, np.take(qn, kk, axis=1))
                blocked = accel.occluded(*segment_to(accel, p, np.take(it.ng, ii, axis=1), np.take(qp, kk, axis=1),
                                                     it.offset[ii]))
                sub = it.take(ii)
                f = bsdf.eval(sub, w, RADIANCE)
                g = np.where(((cos_e > 0) | q2[kk]) & ~blocked, np.abs(cos_e) * qw[kk] / (dist * dist), 0.0)
                contrib = f * np.take(ql, kk, axis=1) * g
                out += contrib.reshape(3, m, len(k)).sum(axis=2)
        self._leaf(state, *self._by_object(it.slot, ":scatter"), state.beta * out)
        return None

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
        for wo, weight, _flags, label in bsdf.lobes(it, RADIANCE):
            beta = state.beta * weight
            keep = np.flatnonzero(ctx.roulette.keep(luminance3(beta) * self.max_lum))
            if len(keep) == 0:
                continue
            lcd = state.extra["lcd"]
            if rel is not None:
                lcd = np.where(np.isnan(lcd), rel, lcd)
            sig = self._code(state.extra["sig"][keep], [f"{nm}:{label}" for nm in names], which[keep])
            w_k = np.take(wo, keep, axis=1)
            o = ctx.world.accel.spawn(np.take(it.p, keep, axis=1), np.take(it.ng, keep, axis=1), w_k, it.offset[keep])
            out.append(PathState(o, w_k, np.take(beta, keep, axis=1), state.owner[keep], state.rep[keep],
                                 np.zeros(len(keep)), np.ones(len(keep), bool), {"sig": sig, "lcd": lcd[keep]}))
        return out


def specular_paths(world, stride: int | None = None, max_depth: int = 12, directions: np.ndarray | None = None):
    """Follow chief rays of a pixel grid (or along given world ``directions`` (p, 3) from the pupil
    centre) through all specular branches.

    Returns a dict with ``pixels`` (p,) flat indices analysed (or 0..p-1 for given directions),
    ``stride``, ``grid`` and ``paths``: a list of {"path": str, "pixel" (k,) positions into
    ``pixels``, "luminance" (k, 3) predicted cd/m^2, "factor" (k,) Y of the product of R and T,
    "lcd" (k,) the first LCD's transmittance relative to a clear cell, NaN if none}.
    """
    eye = world.eye
    w, h = eye.width, eye.height
    if directions is not None:
        stride, jj = 1, np.zeros((1, len(directions)))
        pixels = np.arange(len(directions))
        d = np.asarray(directions, dtype=np.float64).T
        d = d / norm(d)
        o = np.repeat(eye.position.reshape(3, 1), d.shape[1], axis=1)
    else:
        if stride is None:
            stride = max(1, math.ceil(math.sqrt(w * h / 40000)))
        jj, ii = np.meshgrid(np.arange(stride // 2, h, stride), np.arange(stride // 2, w, stride), indexing="ij")
        pixels = (jj * w + ii).ravel()
        sx, sy = eye.pixel_centers()
        o, d, _ = eye.generate_rays(sx[pixels % w], sy[pixels // w], np.zeros((2, len(pixels))))
    n = len(pixels)
    method = ChiefRays(world)
    state = PathState(o, d.astype(F32), np.ones((3, n), F32), np.arange(n), np.zeros(n, np.int64), np.zeros(n, F32),
                      np.ones(n, bool),
                      {"sig": np.zeros(n, np.int64), "lcd": np.full(n, np.nan)})
    ctx = Context(world, make_rng(0), Timers(), Splats(), Roulette(MIN_FACTOR / Roulette.EPSILON * method.max_lum))
    trace(method, state, ctx, max_depth)
    paths = []
    for s, parts in method.leaves.items():
        own = np.concatenate([p[0] for p in parts])
        lum = np.concatenate([p[1] for p in parts])
        fac = np.concatenate([p[2] for p in parts])
        lc = np.concatenate([p[3] for p in parts])
        paths.append({"path": " > ".join(method.names[s]), "pixel": own, "luminance": lum, "factor": fac, "lcd": lc})
    paths.sort(key=lambda p: -float(luminance3(p["luminance"].T).sum()))
    return {"pixels": pixels, "stride": stride, "grid": jj.shape, "paths": paths}
