"""The one module that talks to Embree (through embreex).

All traced objects form one Embree geometry, so a hit's primitive id is a global face index; tables
indexed by it give the object slot, the triangle's plane and its vertices' normals and texture
coordinates. Rays come in and hits go out as (3, n) planes (:mod:`tracer.core.vec`).

Embree works in float32. To keep millimetre optics exact enough for sub-pixel edge positions the
scene is re-centred on its bounding-box centre before it reaches Embree, every hit distance is
refined in float64 against the triangle's plane, barycentric coordinates are recomputed in float64
from the geometry (finer than Embree's and independent of its BVH, so a batch gives the same numbers
in every process), and new rays start a scale-aware distance off the surface (:meth:`Accelerator.spawn`).
Shadow rays use Embree's occlusion query (any hit, no closest-hit search). Hits on faces that lie on an
object's exact surface are refined onto it (:mod:`tracer.transport.surfaces`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from embreex.mesh_construction import TriangleMesh
from embreex.rtcore_scene import EmbreeScene

from ..core.vec import F32, cross, dot, max3, norm, take
from .surfaces import SurfaceTable

#: Relative size of the spawn offset: eps = OFFSET_SCALE * (1 + |p - centre|_max), mm.
OFFSET_SCALE = 2e-6


@dataclass
class Hits:
    """Closest hits of a ray batch: ``face`` (n,) global face index or -1 for a miss, ``t`` (n,)
    distance in mm (inf for a miss), float64."""

    face: np.ndarray
    t: np.ndarray

    @property
    def hit(self) -> np.ndarray:
        return self.face >= 0


class Accelerator:
    """Embree scene over the triangle meshes of ``objects`` (scene objects, in world mm).

    Attributes
    ----------
    face_slot : (F,) the object slot of every global face. first_face : {slot: first global face}.
    v0, e1, e2, normal : (3, F) planes of every triangle (corner, edges, unit geometric normal).
    rays_traced : int, every ray segment handed to Embree (closest-hit and shadow rays).
    surfaces : the objects' exact surfaces (:class:`tracer.transport.surfaces.SurfaceTable`), or None
    where no object has one or ``exact_surfaces`` is false (the meshes alone).
    """

    def __init__(self, objects: list, exact_surfaces: bool = True):
        if not objects:
            raise ValueError("an accelerator needs at least one mesh")
        allv = np.concatenate([o.vertices for o in objects])
        self.center = 0.5 * (allv.min(axis=0) + allv.max(axis=0))
        self.center_col = self.center.reshape(3, 1)
        self.extent = float(np.abs(allv - self.center).max())
        verts, faces, slots, firsts = [], [], [], {}
        vnormal, vuv, has_n, has_uv = [], [], [], []
        offset = nfaces = 0
        for o in objects:
            verts.append(o.vertices)
            faces.append(o.faces + offset)
            firsts[o.slot] = nfaces
            slots.append(np.full(len(o.faces), o.slot, np.int64))
            vnormal.append(o.normals if o.normals is not None else np.zeros_like(o.vertices))
            vuv.append(o.uv if o.uv is not None else np.zeros((len(o.vertices), 2)))
            has_n.append(np.full(len(o.faces), o.normals is not None))
            has_uv.append(np.full(len(o.faces), o.uv is not None))
            offset += len(o.vertices)
            nfaces += len(o.faces)
        vertices = np.concatenate(verts)
        f = np.concatenate(faces)
        self._scene = EmbreeScene()
        TriangleMesh(self._scene, (vertices - self.center).astype(np.float32), np.ascontiguousarray(f, np.int32))
        self.face_slot = np.concatenate(slots)
        self.first_face = firsts
        tri = vertices[f]
        self.v0 = np.ascontiguousarray(tri[:, 0].T)
        self.e1 = np.ascontiguousarray((tri[:, 1] - tri[:, 0]).T)
        self.e2 = np.ascontiguousarray((tri[:, 2] - tri[:, 0]).T)
        c = cross(self.e1, self.e2)
        length = norm(c)
        self.normal = c / np.where(length > 0, length, 1.0)
        #: The unit normals in float32 (directions are float32: tracer.core.vec), with one more zero column
        #: for misses (face -1), and the plane offsets n . v0 (mm, float64) of these float32 normals.
        self.normal32 = self.normal.astype(F32)
        self.normal_ext = np.concatenate([self.normal32, np.zeros((3, 1), F32)], axis=1)
        self.plane = np.append(dot(self.normal32.astype(np.float64), self.v0), 0.0)
        #: Spawn offset of every face (mm, and 0 for misses): OFFSET_SCALE (1 + the largest coordinate of
        #: its corners relative to the scene's centre), so that float32 Embree resolves it.
        corner_extent = np.abs(tri - self.center).max(axis=(1, 2))
        self.offset = np.append(OFFSET_SCALE * (1.0 + corner_extent), 0.0)
        self.surfaces = None
        if exact_surfaces and any(o.surfaces for o in objects):
            self.surfaces = SurfaceTable(objects, firsts, nfaces)
            self.offset[:-1] += 2.0 * self.surfaces.gap  # rays leave the exact surface beyond the facets
        self.face_has_normals = np.concatenate(has_n)
        self.face_has_uv = np.concatenate(has_uv)
        # Vertex attributes are linear over a triangle: a(p) = M p + c for points p in its plane, with
        # u = d1 . (p - v0), v = d2 . (p - v0) through the dual basis of (e1, e2) (d1, d2 are orthogonal
        # to the normal, so points just off the plane interpolate as their projections). Per face:
        # the 3 x 3 (normals) or 2 x 3 (texture coordinates) matrix M, row-major, then c.
        n = self.normal.T
        e1, e2 = self.e1.T, self.e2.T
        d1 = np.cross(e2, n)
        d1 /= np.where(np.abs((d1 * e1).sum(1)) > 0, (d1 * e1).sum(1), 1.0)[:, None]
        d2 = np.cross(n, e1)
        d2 /= np.where(np.abs((d2 * e2).sum(1)) > 0, (d2 * e2).sum(1), 1.0)[:, None]
        v0 = self.v0.T
        self.normal_map = self._affine(np.concatenate(vnormal)[f], d1, d2, v0) if self.face_has_normals.any() else None
        self.uv_map = self._affine(np.concatenate(vuv)[f], d1, d2, v0) if self.face_has_uv.any() else None
        self.faces = nfaces
        self.rays_traced = 0

    @staticmethod
    def _affine(attr: np.ndarray, d1: np.ndarray, d2: np.ndarray, v0: np.ndarray) -> np.ndarray:
        """(k * 3 + k, F) rows of M (row-major) and c of the map p -> M p + c that interpolates the
        per-corner attribute ``attr`` (F, 3, k) linearly over each triangle."""
        a0, da1, da2 = attr[:, 0], attr[:, 1] - attr[:, 0], attr[:, 2] - attr[:, 0]  # (F, k)
        m = da1[:, :, None] * d1[:, None, :] + da2[:, :, None] * d2[:, None, :]  # (F, k, 3)
        c = a0 - da1 * (d1 * v0).sum(1)[:, None] - da2 * (d2 * v0).sum(1)[:, None]
        k = attr.shape[2]
        return np.ascontiguousarray(np.concatenate([m.reshape(len(attr), 3 * k), c], axis=1).T)

    @staticmethod
    def _apply(table: np.ndarray, face: np.ndarray, p: np.ndarray) -> np.ndarray:
        """M p + c of the faces ``face`` at points ``p`` (3, n), (k, n)."""
        t = take(table, face)
        k = t.shape[0] // 4
        return np.stack([t[3 * i] * p[0] + t[3 * i + 1] * p[1] + t[3 * i + 2] * p[2] + t[3 * k + i]
                         for i in range(k)])

    def _rays32(self, o: np.ndarray, d: np.ndarray):
        n = o.shape[1]
        o32 = np.empty((n, 3), np.float32)
        d32 = np.empty((n, 3), np.float32)
        for i in range(3):
            o32[:, i] = o[i] - self.center[i]
            d32[:, i] = d[i]
        return o32, d32

    def intersect(self, o: np.ndarray, d: np.ndarray) -> Hits:
        """Closest hits of rays (origins (3, n) mm float64, unit directions (3, n) float32); one Embree call.

        The distance is refined against the hit triangle's plane, t = (n . v0 - n . o) / (n . d), the
        numerator in float64, so the hit point o + t d lies on the plane to float64 precision whatever
        Embree's float32 t (off by ~1e-7 |t| and dependent on its BVH); where the ray grazes the plane,
        Embree's own t stays. On a face of an exact surface, the distance is the surface's."""
        n = o.shape[1]
        self.rays_traced += n
        if n == 0:
            return Hits(np.zeros(0, np.int64), np.zeros(0))
        o32, d32 = self._rays32(o, d)
        face = self._scene.run(o32, d32, output=False).astype(np.int64)  # primID, -1 for a miss
        ng = take(self.normal_ext, face)  # face -1 (a miss) takes the zero column
        denom = dot(d, ng)
        ok = np.abs(denom) > 1e-9
        t = (take(self.plane, face) - (o[0] * ng[0] + o[1] * ng[1] + o[2] * ng[2])) / np.where(ok, denom, 1)
        if not ok.all():
            # Misses, and rays parallel to the plane they hit (t undefined there: the distance to the
            # triangle's first corner along the ray).
            graze = np.flatnonzero(~ok & (face >= 0))
            if len(graze):
                f = face[graze]
                v = take(self.v0, f) - take(o, graze)
                t[graze] = dot(v, take(d, graze).astype(np.float64))
            t[face < 0] = np.inf
        if self.surfaces is not None:
            t = self.surfaces.refine(o, d, face, t)
        return Hits(face, t)

    def occluded(self, o: np.ndarray, d: np.ndarray, tmax: np.ndarray) -> np.ndarray:
        """Whether anything lies on the segments o + s d, 0 < s < tmax ((3, n), (3, n), (n,) mm);
        one Embree occlusion call. (n,) bool."""
        n = o.shape[1]
        self.rays_traced += n
        if n == 0:
            return np.zeros(0, bool)
        o32, d32 = self._rays32(o, d)
        tm = np.minimum(tmax, 3.0e38).astype(np.float32)
        return self._scene.run(o32, d32, dists=tm, query="OCCLUDED") == 0

    def barycentrics(self, face: np.ndarray, p: np.ndarray) -> np.ndarray:
        """(u, v), (2, n), of points ``p`` (3, n) on their triangles ``face`` (n,), in float64."""
        e1, e2 = take(self.e1, face), take(self.e2, face)
        w = p - take(self.v0, face)
        d11, d12, d22 = dot(e1, e1), dot(e1, e2), dot(e2, e2)
        w1, w2 = dot(w, e1), dot(w, e2)
        det = d11 * d22 - d12 * d12
        det = np.where(det > 0, det, 1.0)
        return np.stack([(d22 * w1 - d12 * w2) / det, (d11 * w2 - d12 * w1) / det])

    def shading(self, face: np.ndarray, p: np.ndarray, ng: np.ndarray):
        """Shading normals (3, n) float32 (interpolated vertex normals on the side of ``ng``; ``ng``
        itself for flat objects) and texture coordinates (2, n) float32 or None, at points ``p`` on
        faces ``face``."""
        ns, uv = ng, None
        if self.normal_map is not None:
            with_n = self.face_has_normals[face]
            if with_n.any():
                s = self._apply(self.normal_map, face, p)
                s = (s * (1.0 / np.maximum(norm(s), 1e-300))).astype(F32)
                s = np.where(dot(s, ng) < 0, -s, s)
                ns = s if with_n.all() else np.where(with_n, s, ng)
        if self.uv_map is not None and self.face_has_uv[face].any():
            uv = self._apply(self.uv_map, face, p).astype(F32)
        return ns, uv

    def spawn(self, p: np.ndarray, ng: np.ndarray, d: np.ndarray, offset: np.ndarray | None = None) -> np.ndarray:
        """Origins (3, n) for rays leaving surface points ``p`` along ``d``: offset along the
        geometric normal ``ng`` to the side the ray goes, by a distance that scales with the
        coordinates' magnitude (float32 Embree resolves about 6e-8 of it): ``offset`` (n,) mm, the
        faces' own (:attr:`offset`), or computed from ``p``."""
        if offset is None:
            offset = OFFSET_SCALE * (1.0 + max3(np.abs(p - self.center_col)))
        return p + np.copysign(offset, dot(d, ng)) * ng
