"""Sequential tracing: rays from the eye followed through one named specular chain to the object the
image forms on (the PGU), as a lens-design program traces a system surface by surface.

The brightness-theorem analysis (:mod:`.chains`) follows every branch of every specular surface and
names each chain it finds by its events, ``windshield:reflect > mirror:reflect > lcd:transmit >
scatterer:scatter``. The optical analysis (:mod:`tracer.analysis.optics`) asks a narrower question of
one such chain: where does a ray from this eye point, in this direction, land on the PGU when it takes
exactly these branches? :func:`follow` answers it for a batch of rays with the same path-loop pieces
the renders use (the accelerator's float64 hits, refined onto exact surfaces; the world's interactions;
each material's delta lobes), so that the analysis and the renders trace the same optics. A ray that
meets another object than its chain's next one, or whose branch carries nothing (total internal
reflection for a refraction), fails. The last leg is intersected with the PGU's plane itself, so that
the landing point is defined up to and beyond the edges of its active area; a ray that meets something
else before that plane is marked vignetted.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..core.units import luminance3
from ..core.vec import F32, dot, take
from ..optics.bsdf import RADIANCE, TRANSMISSION


class ChainError(ValueError):
    """A chain that names an object or a branch the world does not have."""


@dataclass(frozen=True)
class Chain:
    """A specular chain from the eye to the PGU: ``steps`` ((object slot, lobe label), ...) in the order
    the eye's rays meet them, then the ``pgu`` slot. ``text`` is the chain as the analyses name it
    (``windshield:reflect > mirror:reflect > lcd``)."""

    steps: tuple[tuple[int, str], ...]
    pgu: int
    text: str


def chain_from_events(world, events: list[str], pgu: str) -> Chain:
    """The :class:`Chain` of ``events`` (``["windshield:reflect", "mirror:reflect"]``) ending on the
    object ``pgu``. Raises :class:`ChainError` for an unknown object or a branch its material lacks."""
    slots = {o.name: o.slot for o in world.scene.objects}
    steps = []
    for ev in events:
        name, _, label = ev.rpartition(":")
        if name not in slots:
            raise ChainError(f"{ev!r}: no object named {name!r}")
        mat = world.materials[world.slot_material[slots[name]]]
        if not mat.delta:
            raise ChainError(f"{ev!r}: {name} scatters; a chain follows specular branches only")
        steps.append((slots[name], label))
    if pgu not in slots:
        raise ChainError(f"no object named {pgu!r}")
    return Chain(tuple(steps), slots[pgu], " > ".join([*events, pgu]))


@dataclass
class Plane:
    """The PGU's plane: ``centre`` (3,) mm, unit ``normal`` (3,) and in-plane unit axes ``x``, ``y`` (3,)."""

    centre: np.ndarray
    normal: np.ndarray
    x: np.ndarray
    y: np.ndarray

    def local(self, p: np.ndarray) -> np.ndarray:
        """(2, n) in-plane coordinates (mm) of points ``p`` (3, n)."""
        q = p - self.centre[:, None]
        return np.stack([self.x @ q, self.y @ q])


@dataclass
class Landing:
    """Where rays land on the PGU: ``xy`` (2, n) mm in its plane (NaN where the chain failed), ``ok``
    (n,) the chain held, ``vignetted`` (n,) something else lies before the plane on the last leg,
    ``factor`` (n,) the luminance factor of the branches taken (the product of their R and T, Y of
    RGB), ``direction`` (3, n) the rays' directions on arrival."""

    xy: np.ndarray
    ok: np.ndarray
    vignetted: np.ndarray
    factor: np.ndarray
    direction: np.ndarray


def follow(world, chain: Chain, plane: Plane, o: np.ndarray, d: np.ndarray) -> Landing:
    """Follow rays from ``o`` (3, n) mm along unit ``d`` (3, n) through ``chain`` to ``plane``.

    The factor is the chain's luminance factor for light leaving the PGU: the branches' weights, and in
    a world that polarises (``world.polar``) the s and p channels followed as the renders follow them
    (the eye's row vector through each interaction's Mueller matrix, tracer.optics.polar), ending
    with the PGU's own polarisation (an emitter's, or an LCD's output polariser) where the ray meets it."""
    accel = world.accel
    polar = world.polar
    n = o.shape[1]
    o = np.asarray(o, dtype=np.float64)
    d = np.asarray(d, dtype=np.float64)
    idx = np.arange(n)  # the rays still on the chain
    beta = np.ones((3, n), F32)
    extra = None
    if polar is not None:
        beta, extra = polar.start_camera(beta, d.astype(F32))
    for slot, label in chain.steps:
        hits = accel.intersect(o, d)  # float64 directions: the hit and the branch to float64 precision
        on = np.flatnonzero((hits.face >= 0) & (take(accel.face_slot, np.maximum(hits.face, 0)) == slot))
        don = take(d, on)
        p = take(o, on) + hits.t[on] * don
        mat = world.materials[world.slot_material[slot]]
        it = world.interaction(hits.face[on], p, don, material=mat)
        lobe = [lb for lb in mat.lobes(it, RADIANCE) if lb[3] == label]
        if not lobe:
            raise ChainError(f"{world.scene.objects[slot].name}:{label}: its material has no branch {label!r}")
        wo, weight, flags = lobe[0][0], np.asarray(lobe[0][1], dtype=np.float64), lobe[0][2]
        weight3 = np.broadcast_to(weight, (3, len(on))) if weight.shape[0] == 3 else \
            np.broadcast_to(weight.reshape(-1), (3, len(on)))
        b = take(beta, on)
        if polar is not None:
            sub = {k: take(v, on) for k, v in extra.items()}
            b, stokes, frame = polar.scatter(b, sub, it, mat, wo, weight3.astype(F32),
                                             np.full(len(on), flags, np.int8), False)
            extra = {"stokes": stokes, "frame": frame}
        else:
            b = b * weight3
        go = np.flatnonzero(luminance3(weight3) > 0)  # a refraction under total internal reflection carries nothing
        wo = take(wo, go).astype(np.float64)
        o = accel.spawn(take(p, go), take(it.ng, go), wo, take(it.offset, go))
        d = wo / np.sqrt(dot(wo, wo))
        idx, beta = idx[on[go]], take(b, go)
        if polar is not None:
            extra = {k: take(v, go) for k, v in extra.items()}
    # The last leg: the PGU's plane, and whether anything lies before it.
    xy = np.full((2, n), np.nan)
    ok = np.zeros(n, bool)
    vignetted = np.zeros(n, bool)
    factor = np.zeros(n)
    direction = np.full((3, n), np.nan)
    denom = plane.normal @ d
    t = ((plane.centre[:, None] - o) * plane.normal[:, None]).sum(axis=0) / np.where(denom != 0, denom, np.nan)
    front = np.flatnonzero(np.isfinite(t) & (t > 0))
    if len(front):
        o, d, t, idx, beta = take(o, front), take(d, front), t[front], idx[front], take(beta, front)
        hits = accel.intersect(o, d)
        hit_slot = take(accel.face_slot, np.maximum(hits.face, 0))
        margin = 1e-3 + 1e-6 * t
        vignetted[idx] = (hits.face >= 0) & (hits.t < t - margin) & (hit_slot != chain.pgu)
        if polar is not None:
            extra = {k: take(v, front) for k, v in extra.items()}
            beta = _at_pgu(world, chain.pgu, beta, extra, o, d, hits, hit_slot)
        xy[:, idx] = plane.local(o + t * d)
        ok[idx] = True
        factor[idx] = luminance3(beta)
        direction[:, idx] = d
    return Landing(xy, ok, vignetted, factor, direction)


def _at_pgu(world, pgu: int, beta: np.ndarray, extra: dict, o: np.ndarray, d: np.ndarray, hits, hit_slot):
    """The eye's row (``beta``, ``extra``) applied to the light the PGU sends along the rays that meet
    it: an emitter's polarisation, or an LCD's output polariser (its transmitted branch's Mueller matrix,
    without the slide's modulation)."""
    polar = world.polar
    mat = world.materials[world.slot_material[pgu]]
    obj = world.scene.objects[pgu]
    on = np.flatnonzero((hits.face >= 0) & (hit_slot == pgu))
    if len(on) == 0:
        return beta
    beta = beta.copy()
    b, sub = take(beta, on), {k: take(v, on) for k, v in extra.items()}
    d_on = take(d, on)
    if obj.emission is not None:
        beta[:, on] = polar.emitted(b, sub, d_on.astype(F32), np.full(len(on), pgu))
        return beta
    if not mat.delta:  # a scattering PGU (a projection screen) sends its light depolarised
        return beta
    p = take(o, on) + hits.t[on] * d_on
    it = world.interaction(hits.face[on], p, d_on, material=mat)
    lobe = [lb for lb in mat.lobes(it, RADIANCE) if lb[2] & TRANSMISSION]
    if not lobe:
        return beta
    wo, flags = lobe[0][0], lobe[0][2]
    beta[:, on], _, _ = polar.scatter(b, sub, it, mat, wo, np.ones((3, len(on)), F32),
                                      np.full(len(on), flags, np.int8), False)
    return beta
