"""Lights: the emission block of scene objects and the one light table every method uses.

Emission is a light attached to an object, so any material can also emit (an LED die is an absorber
that emits; a backlight can be a diffuser that emits). Every emitter is a Lambertian area light: its
luminance L (cd/m^2) leaves its front side (both sides if two-sided) in every direction.

:class:`LightTable` holds every emitting triangle once, with a power-proportional distribution, and
answers what each method asks of lights:

- ``sample_emission``: a point and side for a particle (forward tracing; the direction is drawn by
  the caller, with the emitter's aim);
- ``sample_direct``: a point on a light seen from shading points, with its area density, for
  next-event estimation. Lights are grouped in clusters (the emitting objects); a cluster is chosen
  with a defensive mixture of its power and an importance the caller computes at each shading point
  (the BSDF toward the cluster times its power over the squared distance, in the manner of pbrt-v4's
  light samplers, Pharr, Jakob and Humphreys, "Physically Based Rendering", 4th ed., sec. 12.6), then
  a triangle by power and a uniform point on it;
- ``pdf_power_area``: the area density of the power-proportional choice alone, which both
  next-event estimation and emitter hits use in their multiple-importance weights (any weights
  that sum to one over the strategies keep the estimate unbiased, Veach 1997, sec. 9.2);
- ``quadrature``: deterministic points for the brightness-theorem analysis.

Units: mm, cd/m^2; powers in cd/m^2 mm^2 sr = 1e-6 lm.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..core.sampling import Distribution1D, TriangleSet
from ..core.schema import Field, Schema
from ..core.units import MM2_TO_M2, lambertian_luminance_cd_m2, luminance, normalize_color
from ..core.validate import MAX_FLUX, MAX_LUMINANCE, MIN_LUMINANCE
from ..core.vec import F32, dot, norm, take

#: Importance-driven cluster choice is used up to this many emitting objects (beyond it, power alone).
MAX_CLUSTERS = 32
#: Share of the cluster choice that follows power whatever the importance says (defensive mixture).
DEFENSIVE = 0.1


def _emission_check(params: dict, fail):
    if 0 < params.get("luminance", 0) < MIN_LUMINANCE:
        fail("luminance", f"a luminance of {params['luminance']:.3g} cd/m^2 is below {MIN_LUMINANCE:g} (give 0 for a "
                          "light that is off)")
    try:
        normalize_color(params["color"])
    except ValueError as e:
        fail("color", str(e))


#: The "emission" block of a scene object (also the fields of the legacy material type "emitter").
EMISSION = Schema(
    "emission", "Emission", "Lambertian emission from the object's front side (both sides if two-sided)",
    (Field("luminance", "number", None, unit="cd/m^2", minimum=0.0, maximum=MAX_LUMINANCE, label="Luminance",
           description="Luminance of the emitting surface, cd/m^2 (give this or the flux)", ui_default=1000.0),
     Field("flux", "number", None, unit="lm", minimum=0.0, maximum=MAX_FLUX, label="Flux",
           description="Luminous flux of the whole object, lm (give this or the luminance)", ui_default=1.0),
     Field("color", "rgb", [1.0, 1.0, 1.0], unit="1", minimum=0.0, maximum=1e6, label="Color",
           description="Linear Rec.709 colour; scaled so that its luminance is the given one"),
     Field("two_sided", "bool", False, label="Two-sided", description="Emit from both sides"),
     Field("polarisation", "group", None, label="Polarisation",
           description="Linearly polarised emission (an LCD panel, a polarised LED source)",
           fields=(Field("axis_deg", "number", unit="deg", minimum=-360.0, maximum=360.0, label="Axis",
                         description="Polarisation axis, degrees from the object's local x axis toward its local y "
                                     "axis", ui_default=0.0),
                   Field("degree", "number", 1.0, unit="1", minimum=0.0, maximum=1.0, label="Degree",
                         description="Degree of linear polarisation, 0 (unpolarised) to 1")))),
    can_aim=True, alternatives=(("luminance",), ("flux",)), check=_emission_check)


@dataclass
class Emission:
    """A validated emission block: luminance (cd/m^2; from the flux and the area when given as flux),
    colour normalised to Y = 1, two-sidedness and the paper's directed split for particles (an Aim)."""

    luminance: float
    color: np.ndarray
    two_sided: bool
    aim: object = None
    params: dict | None = None

    @property
    def polarisation(self) -> dict | None:
        """{"axis_deg", "degree"} of linearly polarised emission, or None (unpolarised)."""
        pol = (self.params or {}).get("polarisation")
        return pol if pol is not None and pol["degree"] > 0 else None

    @property
    def radiance(self) -> np.ndarray:
        """(3,) RGB whose Y is the luminance, cd/m^2."""
        return self.luminance * self.color


def make_emission(params: dict, area_mm2: float, aim) -> Emission:
    """An :class:`Emission` from parsed :data:`EMISSION` fields of an object of area ``area_mm2``."""
    sides = 2.0 if params["two_sided"] else 1.0
    lum = params["luminance"] if "luminance" in params else lambertian_luminance_cd_m2(params["flux"],
                                                                                       sides * area_mm2)
    return Emission(float(lum), normalize_color(params["color"]), bool(params["two_sided"]), aim, params)


class LightTable:
    """Every emitting triangle of a world (see the module docstring).

    Parameters
    ----------
    objects : scene objects (with ``slot``, ``triangles`` and ``emission``); those with an emission
        of positive luminance become lights.

    Attributes
    ----------
    tris : TriangleSet of the light triangles (planes (3, T)). radiance : (3, T) RGB cd/m^2.
    two_sided : (T,) bool. slot : (T,) the objects' world slots. cluster : (T,) cluster index.
    power : (T,) pi L A sides. total_flux_lm : float.
    """

    def __init__(self, objects: list):
        lights = [o for o in objects if o.emission is not None and o.emission.luminance > 0]
        self.objects = lights
        tris = [o.triangles for o in lights]
        self.tris = TriangleSet(np.concatenate(tris) if tris else np.zeros((0, 3, 3)))
        count = [len(t) for t in tris]
        rep = lambda vals: np.repeat(np.asarray(vals), count, axis=0)  # noqa: E731
        self.radiance = np.ascontiguousarray(rep([o.emission.radiance for o in lights]).T) if lights else \
            np.zeros((3, 0))
        self.two_sided = rep([o.emission.two_sided for o in lights]).astype(bool) if lights else np.zeros(0, bool)
        self.slot = rep([o.slot for o in lights]).astype(np.int64) if lights else np.zeros(0, np.int64)
        self.cluster = rep(np.arange(len(lights))).astype(np.int64) if lights else np.zeros(0, np.int64)
        sides = np.where(self.two_sided, 2.0, 1.0)
        self.power = np.pi * luminance(self.radiance.T) * self.tris.area * sides
        self.total_flux_lm = float(self.power.sum() * MM2_TO_M2)
        self.dist = Distribution1D(self.power) if self.total_flux_lm > 0 else None
        #: Global face index of the first triangle of each light object in the world's geometry is set
        #: by the world (:meth:`link_faces`); ``face_light[f]`` is the light triangle of face f or -1.
        self.face_light = None
        # Clusters: one per emitting object.
        k = len(lights)
        self.cluster_power = np.array([self.power[self.cluster == i].sum() for i in range(k)])
        starts = np.cumsum([0] + count)
        self.cluster_range = np.stack([starts[:-1], starts[1:]], axis=1) if k else np.zeros((0, 2), np.int64)
        self.centre = np.zeros((3, k))
        self.radius = np.zeros(k)
        self.cluster_normal = np.zeros((3, k))  # the common normal of a planar one-sided cluster, else 0
        for i, o in enumerate(lights):
            v = o.vertices
            c = 0.5 * (v.min(axis=0) + v.max(axis=0))
            self.centre[:, i] = c
            self.radius[i] = float(np.sqrt(((v - c) ** 2).sum(axis=1)).max())
            a, b = self.cluster_range[i]
            nrm = self.tris.normal[:, a:b]
            if not o.emission.two_sided and np.all(dot(nrm, nrm[:, :1]) > 1 - 1e-9):
                self.cluster_normal[:, i] = nrm[:, 0]
        self.cdf = np.cumsum(self.power)
        self._planar = np.any(self.cluster_normal != 0, axis=0)
        #: Float32 copies for the shading side (tracer.core.vec): normals (3, T), radiance (3, T), clusters.
        self.normal32 = self.tris.normal.astype(F32)
        self.radiance32 = self.radiance.astype(F32)
        self._centre32 = self.centre.astype(F32)
        self._cnormal32 = self.cluster_normal.astype(F32)
        self._cpower32 = self.cluster_power.astype(F32)
        self._r2_32 = (self.radius * self.radius).astype(F32)

    def __len__(self) -> int:
        return len(self.power)

    @property
    def clusters(self) -> int:
        return len(self.objects)

    def link_faces(self, n_faces: int, first_face: dict[int, int]):
        """Map the world's global face indices to light triangles (``first_face``: slot -> first
        global face of that object)."""
        self.face_light = np.full(n_faces, -1, np.int64)
        for i, o in enumerate(self.objects):
            a, b = self.cluster_range[i]
            f0 = first_face[o.slot]
            self.face_light[f0:f0 + (b - a)] = np.arange(a, b)
        #: face_light with -1 appended (np.take with face -1, a miss, gives -1).
        self.face_light_ext = np.append(self.face_light, -1)

    # -- emission (forward) ---------------------------------------------------------------------
    def sample_emission(self, u: np.ndarray):
        """Particles' starting points: u (4, n) -> (light triangles (n,), points (3, n) mm, float32 normals
        (3, n) on the emitting side, area density (n,) mm^-2 of point and side together)."""
        tri, pmf = self.dist.sample(u[0])
        points = self.tris.point(tri, u[1:3])
        normal = take(self.normal32, tri)
        pdf = pmf / self.tris.area[tri]
        two = self.two_sided[tri]
        if np.any(two):
            flip = two & (u[3] < 0.5)
            normal = np.where(flip, -normal, normal)
            pdf = np.where(two, 0.5 * pdf, pdf)
        return tri, points, normal, pdf

    def emitted(self, tri: np.ndarray, d: np.ndarray) -> np.ndarray:
        """(3, n) luminance leaving light triangles ``tri`` toward rays that arrive along ``d`` (3, n):
        the radiance on the emitting side, 0 behind a one-sided emitter."""
        front = dot(d, take(self.normal32, tri)) < 0
        visible = front | self.two_sided[tri]
        return take(self.radiance32, tri) * visible

    def pdf_power_area(self, tri: np.ndarray) -> np.ndarray:
        """Area density (mm^-2) of the power-proportional choice of a point on light triangles ``tri``."""
        return self.power[tri] / (self.dist.total * self.tris.area[tri])

    # -- next-event estimation ------------------------------------------------------------------
    def importance(self, p: np.ndarray, density) -> np.ndarray | None:
        """Per-cluster importance (K, n) at shading points ``p`` (3, n): ``density(w)`` (n,) toward unit
        directions w (3, n) (the BSDF's sampling density, proportional to the luminance of f |cos| for
        the materials here) times the cluster's power, its emitting-side cosine (planar one-sided
        clusters) and 1 / max(d^2, r^2). None when power alone decides (one cluster, or more than
        :data:`MAX_CLUSTERS`)."""
        k = self.clusters
        if k <= 1 or k > MAX_CLUSTERS:
            return None
        out = np.empty((k, p.shape[1]), F32)
        p32 = p.astype(F32)  # a heuristic: float32 relative to the shading points is plenty
        for i in range(k):
            v = self._centre32[:, i:i + 1] - p32
            d2 = dot(v, v)
            w = v * (1 / np.sqrt(np.maximum(d2, F32(1e-30))))
            g = self._cpower32[i] / np.maximum(d2, self._r2_32[i])
            if self._planar[i]:
                g = g * np.maximum(-dot(w, self._cnormal32[:, i:i + 1]), 0)
            out[i] = density(w) * g
        return out

    def sample_direct(self, p: np.ndarray, u: np.ndarray, importance: np.ndarray | None = None):
        """Points on lights for shading points ``p`` (3, n), from u (3, n).

        Returns (light triangles (n,), points (3, n) mm, area density (n,) mm^-2 of the whole choice).
        With ``importance`` (K, n) the cluster is drawn from the defensive mixture
        DEFENSIVE power + (1 - DEFENSIVE) importance (power alone where the importance is all zero),
        then a triangle of the cluster by power (u[0] reused, rescaled) and a uniform point (u[1:3]).
        """
        if importance is None:
            tri, pmf = self.dist.sample(u[0])
            return tri, self.tris.point(tri, u[1:3]), pmf / self.tris.area[tri]
        share = (self.cluster_power / self.cluster_power.sum()).astype(F32)[:, None]
        total = importance.sum(axis=0)
        q = DEFENSIVE * share + (1 - DEFENSIVE) * importance * (1 / np.where(total > 0, total, 1))
        q = np.where(total > 0, q, share)
        cdf = np.cumsum(q, axis=0)
        x = u[0] * cdf[-1]
        k = np.minimum((cdf <= x).sum(axis=0), self.clusters - 1)
        q_k = np.take_along_axis(q, k[None], axis=0)[0].astype(np.float64) / cdf[-1]
        lo = np.where(k > 0, np.take_along_axis(cdf, np.maximum(k - 1, 0)[None], axis=0)[0], 0.0)
        hi = np.take_along_axis(cdf, k[None], axis=0)[0]
        v = np.clip((x - lo) / np.maximum(hi - lo, 1e-30), 0.0, 1.0 - 1e-7)  # u[0] rescaled in the cluster
        a, b = self.cluster_range[k, 0], self.cluster_range[k, 1]
        c0 = np.where(a > 0, self.cdf[np.maximum(a - 1, 0)], 0.0)
        tri = np.searchsorted(self.cdf, c0 + v * (self.cdf[b - 1] - c0), side="right")
        tri = np.clip(tri, a, b - 1)
        pdf = q_k * self.power[tri] / (self.cluster_power[k] * self.tris.area[tri])
        return tri, self.tris.point(tri, u[1:3]), pdf

    def connection(self, p: np.ndarray, tri: np.ndarray, y: np.ndarray):
        """Geometry of connections from shading points ``p`` to light points ``y`` (both (3, n)):
        (unit directions p -> y (3, n) float32, distances (n,) mm, luminance arriving at p (3, n) float32,
        |cos| at the light (n,) float32)."""
        v = y - p
        dist = norm(v)
        w = (v * (1.0 / np.maximum(dist, 1e-300))).astype(F32)
        n_y = take(self.normal32, tri)
        cos_y = -dot(w, n_y)
        lit = (cos_y > 0) | self.two_sided[tri]
        return w, dist, take(self.radiance32, tri) * lit, np.abs(cos_y)

    # -- the brightness-theorem analysis --------------------------------------------------------
    def quadrature(self, level: int | np.ndarray = 4):
        """Deterministic quadrature of every light triangle: points (3, q), normals (3, q), weights
        (q,) mm^2, radiance (3, q), two-sided flags (q,), cell sizes (q,) mm (the longest edge of the
        cell): the midpoints of a level x level subdivision of each triangle into equal-area cells
        similar to it (centroid rule, exact for linear integrands). ``level`` is one for all triangles
        or one per triangle (T,)."""
        t = self.tris
        levels = np.broadcast_to(np.asarray(level, dtype=np.int64), (len(t),))
        longest = np.maximum.reduce([norm(e) for e in (t.e1, t.e2, t.e2 - t.e1)])
        parts = []
        for lv in np.unique(levels).tolist():
            idx = np.flatnonzero(levels == lv)
            cells = []
            for i in range(lv):
                for j in range(lv - i):
                    cells.append(((i + 1 / 3) / lv, (j + 1 / 3) / lv))
                    if i + j < lv - 1:
                        cells.append(((i + 2 / 3) / lv, (j + 2 / 3) / lv))
            b = np.array(cells).T  # (2, c)
            c = b.shape[1]
            v0, e1, e2 = (take(a, idx)[:, :, None] for a in (t.v0, t.e1, t.e2))
            pts = (v0 + b[0] * e1 + b[1] * e2).reshape(3, -1)
            parts.append((pts, *(np.repeat(take(a, idx), c, axis=-1)
                                 for a in (t.normal, t.area / c, self.radiance, self.two_sided, longest / lv))))
        if not parts:
            return (np.zeros((3, 0)), np.zeros((3, 0)), np.zeros(0), np.zeros((3, 0)), np.zeros(0, bool),
                    np.zeros(0))
        return tuple(np.concatenate(arrays, axis=-1) for arrays in zip(*parts, strict=True))
