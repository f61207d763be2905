"""The one module that talks to Embree (through embreex).

Embree works in float32. To keep millimetre optics exact enough for sub-pixel edge positions the
scene is re-centred on its bounding-box centre before it reaches Embree, every hit distance is
refined in float64 against the triangle's plane, and new rays start a scale-aware distance off the
surface (:meth:`Accelerator.spawn`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from embreex.mesh_construction import TriangleMesh
from embreex.rtcore_scene import EmbreeScene

from .vec import axpy, dot, max3, norm, rows

#: Relative size of the spawn offset: eps = OFFSET_SCALE * (1 + |p - centre|_max), mm.
OFFSET_SCALE = 2e-6


@dataclass
class Hits:
    """Closest hits of a ray batch; arrays of length n, world mm, float64.

    ``obj`` is the slot of the object in the accelerator's list (-1 for a miss), ``face`` the
    triangle index inside that object, ``t`` the distance (inf for a miss), ``points`` the hit points
    (the ray origin for a miss), ``normals`` the unit geometric normals (0 for a miss). Barycentric
    coordinates are computed on demand (:meth:`bary`): most surfaces need none.
    """

    obj: np.ndarray
    face: np.ndarray
    t: np.ndarray
    points: np.ndarray
    normals: np.ndarray
    gface: np.ndarray
    accel: Accelerator

    @property
    def hit(self) -> np.ndarray:
        return self.obj >= 0

    def by_object(self, mask: np.ndarray | None = None) -> list[tuple[int, np.ndarray]]:
        """(slot, ray indices in increasing order) for every object hit (by the rays where ``mask``),
        slots in increasing order; a bincount, not a sort, so it costs a pass per object."""
        obj = self.obj if mask is None else np.where(mask, self.obj, -1)
        counts = np.bincount(obj + 1)
        return [(int(s) - 1, np.flatnonzero(obj == s - 1)) for s in np.flatnonzero(counts[1:]) + 1]

    def bary(self, idx: np.ndarray) -> np.ndarray:
        """(u, v) of the hits ``idx`` on their triangles, (k, 2)."""
        return self.accel.barycentrics(self.gface[idx], self.points[idx])


class Accelerator:
    """Embree scene over triangle meshes (one geometry per mesh, geomID = slot).

    Parameters
    ----------
    meshes : list of (vertices (v, 3) float64 mm, faces (f, 3) int)
    """

    def __init__(self, meshes: list[tuple[np.ndarray, np.ndarray]]):
        if not meshes:
            raise ValueError("an accelerator needs at least one mesh")
        allv = np.concatenate([v for v, _ in meshes])
        self.center = 0.5 * (allv.min(axis=0) + allv.max(axis=0))
        self.extent = float(np.abs(allv - self.center).max())
        self._scene = EmbreeScene()
        v0s, e1s, e2s, ns, offsets = [], [], [], [], [0]
        for vertices, faces in meshes:
            local = (vertices - self.center).astype(np.float32)
            TriangleMesh(self._scene, local, np.ascontiguousarray(faces, dtype=np.int32))
            tri = vertices[faces]
            n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
            length = norm(n)[:, None]
            ns.append(np.divide(n, length, out=np.zeros_like(n), where=length > 0))
            v0s.append(tri[:, 0])
            e1s.append(tri[:, 1] - tri[:, 0])
            e2s.append(tri[:, 2] - tri[:, 0])
            offsets.append(offsets[-1] + len(faces))
        self._v0 = np.concatenate(v0s)
        self._e1, self._e2 = np.concatenate(e1s), np.concatenate(e2s)
        self._n = np.concatenate(ns)
        self._offsets = np.array(offsets[:-1], dtype=np.int64)
        self.rays_traced = 0

    def intersect(self, origins: np.ndarray, dirs: np.ndarray, tmax: np.ndarray | None = None) -> Hits:
        """Closest hits of rays (origins (n, 3), unit dirs (n, 3), world mm); one Embree call."""
        n = len(origins)
        self.rays_traced += n
        if n == 0:
            z = np.zeros(0, np.int64)
            return Hits(z, z, np.zeros(0), np.zeros((0, 3)), np.zeros((0, 3)), z, self)
        o32 = (origins - self.center).astype(np.float32)
        d32 = dirs.astype(np.float32)
        if tmax is None:
            res = self._scene.run(o32, d32, output=True)
        else:
            res = self._scene.run(o32, d32, dists=np.ascontiguousarray(tmax, dtype=np.float32), output=True)
        geom = res["geomID"]
        idx = np.flatnonzero(geom >= 0)
        obj = np.full(n, -1, np.int64)
        face = np.zeros(n, np.int64)
        gface = np.zeros(n, np.int64)
        t = np.full(n, np.inf)
        points = origins.copy()
        normals = np.zeros((n, 3))
        if len(idx):
            o_h, d_h = rows(origins, idx), rows(dirs, idx)
            obj_h = geom[idx].astype(np.int64)
            face_h = res["primID"][idx].astype(np.int64)
            g = self._offsets[obj_h] + face_h
            ng = rows(self._n, g)
            # Refine t in float64 against the triangle's plane (Embree's float32 t is off by ~1e-7 |t|).
            denom = dot(d_h, ng)
            ok = np.abs(denom) > 1e-9
            t_h = np.where(ok, dot(rows(self._v0, g) - o_h, ng) / np.where(ok, denom, 1.0),
                           res["tfar"][idx].astype(np.float64))
            obj[idx], face[idx], gface[idx], t[idx], normals[idx] = obj_h, face_h, g, t_h, ng
            points[idx] = axpy(t_h, d_h, o_h)
        return Hits(obj, face, t, points, normals, gface, self)

    def barycentrics(self, gface: np.ndarray, points: np.ndarray) -> np.ndarray:
        """(u, v) of points on their triangles (global face indices ``gface``), (n, 2), in float64
        from the geometry itself: finer than Embree's float32 values and independent of how Embree
        built its BVH, so a batch gives the same numbers in every process."""
        e1, e2 = rows(self._e1, gface), rows(self._e2, gface)
        w = points - rows(self._v0, gface)
        d11, d12, d22 = dot(e1, e1), dot(e1, e2), dot(e2, e2)
        w1, w2 = dot(w, e1), dot(w, e2)
        det = d11 * d22 - d12 * d12
        det = np.where(det > 0, det, 1.0)
        return np.stack([(d22 * w1 - d12 * w2) / det, (d11 * w2 - d12 * w1) / det], axis=1)

    def spawn(self, points: np.ndarray, normals: np.ndarray, dirs: np.ndarray) -> np.ndarray:
        """Origins for rays leaving surface ``points`` along ``dirs``: offset along the geometric
        normal to the side the ray goes, by a distance that scales with the coordinates' magnitude
        (float32 Embree resolves about 6e-8 of it)."""
        offset = OFFSET_SCALE * (1.0 + max3(np.abs(points - self.center)))
        side = np.where(dot(dirs, normals) >= 0, 1.0, -1.0)
        return axpy(side * offset, normals, points)
