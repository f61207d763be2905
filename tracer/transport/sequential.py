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
from ..core.vec import dot, take
from ..optics.bsdf import RADIANCE


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
    """Follow rays from ``o`` (3, n) mm along unit ``d`` (3, n) through ``chain`` to ``plane``."""
    accel = world.accel
    n = o.shape[1]
    o = np.asarray(o, dtype=np.float64)
    d = np.asarray(d, dtype=np.float64)
    idx = np.arange(n)  # the rays still on the chain, and their weights
    fac = np.ones(n)
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
        wo, weight = lobe[0][0], np.asarray(lobe[0][1], dtype=np.float64)
        w = luminance3(np.broadcast_to(weight, (3, len(on)))) if weight.shape[0] == 3 else \
            np.broadcast_to(weight.reshape(-1), (len(on),))
        go = np.flatnonzero(w > 0)  # a refraction under total internal reflection carries nothing
        wo = take(wo, go).astype(np.float64)
        o = accel.spawn(take(p, go), take(it.ng, go), wo, take(it.offset, go))
        d = wo / np.sqrt(dot(wo, wo))
        idx, fac = idx[on[go]], fac[on[go]] * w[go]
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
        o, d, t, idx, fac = take(o, front), take(d, front), t[front], idx[front], fac[front]
        hits = accel.intersect(o, d)
        hit_slot = take(accel.face_slot, np.maximum(hits.face, 0))
        margin = 1e-3 + 1e-6 * t
        vignetted[idx] = (hits.face >= 0) & (hits.t < t - margin) & (hit_slot != chain.pgu)
        xy[:, idx] = plane.local(o + t * d)
        ok[idx] = True
        factor[idx] = fac
        direction[:, idx] = d
    return Landing(xy, ok, vignetted, factor, direction)
