"""The surface interface: what every material does with a batch of rays that hits it.

In the manner of pbrt-v4's BxDFs and Mitsuba 3's BSDFs (Pharr, Jakob and Humphreys, "Physically Based
Rendering", 4th ed., ch. 9; Jakob et al., Mitsuba 3, ``mitsuba/core/bsdf.h``), every material offers

- ``sample(it, u, mode) -> BSDFSample``: new directions ``wo``, the weight f |cos| / pdf, the pdf (per
  steradian; 0 for delta lobes) and per-ray lobe flags; the random numbers ``u`` (``dims``, n) are
  arguments, so that the caller owns the streams;
- ``eval(it, wo, mode)``: f |cos(wo)|, (3, n) RGB, 1/sr; zero for delta lobes;
- ``pdf(it, wo)``: the solid-angle density of ``sample``; zero for delta lobes;
- ``lobes(it, mode)``: for purely specular materials, every delta branch with its weight, for the
  deterministic analysis and for splitting (a path may follow all branches at once).

Directions follow the path: ``it.d`` is the propagation direction of the arriving ray, ``wo`` the one
of the ray that leaves. Transport modes (Veach 1997, ch. 5, "non-symmetric scattering"): camera
paths carry radiance (``RADIANCE``), light paths carry flux (``IMPORTANCE``); only refraction differs
(radiance crossing into a denser medium is scaled by (n_i / n_t)^2 on camera paths only), and, on
smoothed surfaces, the path loop multiplies light paths by :func:`adjoint_shading_factor`.

One material instance serves every object of its type in a world (shading is grouped by material,
not by object); per-object parameters live in small tables indexed by ``it.slot``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..core.vec import F32, dot, take
from .polar import DEPOLARISE, Mueller

#: Transport modes.
RADIANCE, IMPORTANCE = "radiance", "importance"

#: Lobe flags (bits of ``BSDFSample.flags`` and ``BSDF.flags``).
DELTA, REFLECTION, TRANSMISSION = 1, 2, 4


def adjoint_shading_factor(it, wo: np.ndarray) -> np.ndarray:
    """(n,) the factor that makes a light path's scattering at shading normals the adjoint of a camera
    path's (Veach 1997, sec. 5.3, eq. 5.19, doi:10.5555/927297; pbrt-v3's CorrectShadingNormal):
    |d . ns| |wo . ng| / (|d . ng| |wo . ns|), ``d`` the arriving direction and ``wo`` the one sampled.
    Materials weigh samples by cosines to the shading normal in both modes, which is right for
    radiance; flux crosses the real (geometric) surface, and without the factor forward tracing through
    a smoothed mirror or lens disagrees with backward tracing. 1 where ns is ng (bit for bit: the same
    two products), 0 where a direction grazes the geometric surface."""
    num = np.abs(dot(it.d, it.ns)) * np.abs(dot(wo, it.ng))
    den = np.abs(dot(it.d, it.ng)) * np.abs(dot(wo, it.ns))
    return np.where(den > 0, num / np.where(den > 0, den, 1), 0).astype(F32)


@dataclass
class Interaction:
    """Rays (n of them) that hit surfaces of one material; all vectors (3, n) planes, world mm.

    d : unit propagation directions of the arriving rays (float32). p : hit points (float64).
    ng : unit geometric normals (mesh winding; float32). ns : unit shading normals (interpolated, on
    the side of ng; float32). uv : (2, n) float32 texture coordinates or None. slot : (n,) the
    objects' slots in the world.
    offset : (n,) the faces' spawn offsets (mm; tracer.transport.accel), or None.
    cache : per-interaction values a material computes once (its local frames).
    polar : in a polarised world, the arriving paths' state (stokes (3, C, n), frame (3, n); see
        tracer.optics.polar), so that a material with two delta branches can choose between them by
        what the path carries; None elsewhere.
    """

    d: np.ndarray
    p: np.ndarray
    ng: np.ndarray
    ns: np.ndarray
    uv: np.ndarray | None
    slot: np.ndarray
    offset: np.ndarray | None = None
    cache: dict = field(default_factory=dict)
    polar: tuple | None = None

    def __len__(self) -> int:
        return self.d.shape[1]

    def side(self) -> np.ndarray:
        """+1 where the ray arrives on the front (normal) side, -1 on the back side; (n,)."""
        if "side" not in self.cache:
            self.cache["side"] = np.where(dot(self.d, self.ng) < 0, F32(1), F32(-1))
        return self.cache["side"]

    def take(self, idx: np.ndarray) -> Interaction:
        """The interaction of rays ``idx`` only, with what the materials cached for them."""
        n = len(self)
        t = lambda a: None if a is None else take(a, idx)  # noqa: E731

        def part(v):
            if isinstance(v, tuple):
                return tuple(part(x) for x in v)
            return t(v) if isinstance(v, np.ndarray) and v.shape[-1] == n and v.ndim >= 1 else v

        ns = t(self.ns) if self.ns is not self.ng else None
        ng = t(self.ng)
        out = Interaction(t(self.d), t(self.p), ng, ns if ns is not None else ng, t(self.uv), self.slot[idx],
                          t(self.offset))
        out.cache = {k: part(v) for k, v in self.cache.items()}
        out.polar = None if self.polar is None else part(self.polar)
        return out

    @staticmethod
    def concat(parts: list[Interaction]) -> Interaction:
        """One interaction of several (their caches dropped)."""
        if len(parts) == 1:
            return parts[0]
        c = lambda name: np.concatenate([getattr(i, name) for i in parts], axis=-1)  # noqa: E731
        ng = c("ng")
        ns = c("ns") if any(i.ns is not i.ng for i in parts) else ng
        uv = c("uv") if all(i.uv is not None for i in parts) else None
        offset = c("offset") if all(i.offset is not None for i in parts) else None
        return Interaction(c("d"), c("p"), ng, ns, uv, c("slot"), offset)


@dataclass
class BSDFSample:
    """Outgoing directions wo (3, n), weights f |cos| / pdf (3, n), or an array that broadcasts to it
    ((3, 1) for one RGB factor, (1, n) for a grey one; 0 where absorbed), pdf (n,) per sr (0 for delta
    lobes and absorbed samples), lobe flags (n,) int8 of the sampled lobe (0: absorbed)."""

    wo: np.ndarray
    weight: np.ndarray
    pdf: np.ndarray
    flags: np.ndarray


class BSDF:
    """Base of every material. Subclasses set ``schema`` (tracer.core.schema.Schema), ``flags`` (the union of
    their lobes' flags; 0 for a black absorber), ``dims`` (random numbers per sample) and implement
    the methods of the module docstring."""

    schema = None
    flags = 0
    dims = 0
    #: False for virtual objects that are not traced (apertures).
    traced = True
    #: Whether the material changes light's state of polarisation by intensity (a diattenuator: Fresnel
    #: surfaces, s/p coatings, metals, polarisers). A world needs Stokes vectors only where some object
    #: does, or a source or the eye is polarised (tracer.optics.polar).
    polarising = False
    #: Whether its Mueller matrices differ between the RGB channels (tracer.optics.polar.Transport).
    chromatic_polarisation = False

    def __init__(self, objects: list):
        """``objects``: the scene objects (tracer.scene.SceneObject) of this material, with their
        world slots in ``obj.slot``."""
        self.objects = objects
        n_slots = 1 + max(o.slot for o in objects)
        self.local = np.full(n_slots, -1, np.int64)
        for i, o in enumerate(objects):
            self.local[o.slot] = i

    @property
    def delta(self) -> bool:
        """Every lobe is a delta distribution (nothing for next-event estimation to connect to)."""
        return bool(self.flags & DELTA) or self.flags == 0

    def table(self, name: str) -> np.ndarray:
        """A parameter of every object, stacked along the last axis: (k, objects) or (objects,), float32."""
        return np.stack([np.asarray(o.material.params[name], dtype=F32) for o in self.objects], axis=-1)

    def gather(self, values: np.ndarray, it: Interaction) -> np.ndarray:
        """Per-object values (..., objects) at the rays of ``it``: (..., 1), which broadcasts, when
        there is one object, else (..., n)."""
        if values.shape[-1] == 1:
            return values
        return take(values, self.local[it.slot])

    # -- the interface ---------------------------------------------------------------------------
    def sample(self, it: Interaction, u: np.ndarray, mode: str) -> BSDFSample:
        raise NotImplementedError

    def eval(self, it: Interaction, wo: np.ndarray, mode: str) -> np.ndarray:
        return np.zeros((3, len(it)))

    def pdf(self, it: Interaction, wo: np.ndarray) -> np.ndarray:
        return np.zeros(len(it))

    def eval_pdf(self, it: Interaction, wo: np.ndarray, mode: str) -> tuple[np.ndarray, np.ndarray]:
        """(eval, pdf) together; materials whose two share work override it."""
        return self.eval(it, wo, mode), self.pdf(it, wo)

    def mueller(self, it: Interaction, k_in: np.ndarray, k_out: np.ndarray, flags: np.ndarray):
        """The normalised Mueller matrix (tracer.optics.polar.Mueller) of the lobes ``flags`` (n,) that
        take light arriving along ``k_in`` to ``k_out`` (both (3, n), the light's directions, whatever
        the path's), or None for the identity on an undeviated ray. The default: scattering lobes
        depolarise, delta lobes are the identity (materials that deviate light by a delta lobe or
        polarise override it)."""
        return None if self.flags & DELTA else Mueller(DEPOLARISE)

    def prepare(self, it: Interaction):
        """Compute what later calls on ``it`` or on its subsets (Interaction.take) share (local frames)."""

    def lobes(self, it: Interaction, mode: str) -> list[tuple[np.ndarray, np.ndarray, int, str]]:
        """Every delta branch: [(wo (3, n), weight (3, n), flags, label)] (purely specular materials)."""
        raise NotImplementedError(f"{type(self).__name__} has non-delta lobes")
