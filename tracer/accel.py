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

from .vec import dot, max3, norm

#: Relative size of the spawn offset: eps = OFFSET_SCALE * (1 + |p - centre|_max), mm.
OFFSET_SCALE = 2e-6


@dataclass
class Hits:
    """Closest hits of a ray batch; arrays of length n, world mm, float64.

    ``obj`` is the slot of the object in the accelerator's list (-1 for a miss), ``face`` the
    triangle index inside that object, ``bary`` (n, 2) the barycentric (u, v) of Embree.
    """

    obj: np.ndarray
    face: np.ndarray
    t: np.ndarray
    bary: np.ndarray
    points: np.ndarray
    normals: np.ndarray

    @property
    def hit(self) -> np.ndarray:
        return self.obj >= 0


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
            z = np.zeros(0)
            return Hits(np.zeros(0, np.int64), np.zeros(0, np.int64), z, np.zeros((0, 2)), np.zeros((0, 3)),
                        np.zeros((0, 3)))
        o32 = np.ascontiguousarray(origins - self.center, dtype=np.float32)
        d32 = np.ascontiguousarray(dirs, dtype=np.float32)
        if tmax is None:
            res = self._scene.run(o32, d32, output=True)
        else:
            res = self._scene.run(o32, d32, dists=np.ascontiguousarray(tmax, dtype=np.float32), output=True)
        obj = res["geomID"].astype(np.int64)
        hit = obj >= 0
        face = np.where(hit, res["primID"], 0).astype(np.int64)
        gface = np.where(hit, self._offsets[np.maximum(obj, 0)] + face, 0)
        ng = self._n[gface]
        t = res["tfar"].astype(np.float64)
        # Refine t in float64 against the triangle's plane (Embree's float32 t is off by ~1e-7 |t|).
        denom = dot(dirs, ng)
        num = dot(self._v0[gface] - origins, ng)
        ok = hit & (np.abs(denom) > 1e-9)
        t = np.where(ok, num / np.where(ok, denom, 1.0), t)
        t = np.where(hit, t, np.inf)
        points = origins + np.where(hit, t, 0.0)[:, None] * dirs
        bary = self._barycentrics(gface, points)
        return Hits(np.where(hit, obj, -1), face, t, bary, points, ng)

    def _barycentrics(self, gface: np.ndarray, points: np.ndarray) -> np.ndarray:
        """(u, v) of hit points on their triangles, (n, 2), in float64 from the geometry itself: finer
        than Embree's float32 values and independent of how Embree built its BVH, so a batch gives
        the same numbers in every process."""
        e1, e2 = self._e1[gface], self._e2[gface]
        w = points - self._v0[gface]
        d11, d12, d22 = dot(e1, e1), dot(e1, e2), dot(e2, e2)
        w1, w2 = dot(w, e1), dot(w, e2)
        det = d11 * d22 - d12 * d12
        det = np.where(det > 0, det, 1.0)
        return np.stack([(d22 * w1 - d12 * w2) / det, (d11 * w2 - d12 * w1) / det], axis=1)

    def spawn(self, points: np.ndarray, normals: np.ndarray, dirs: np.ndarray) -> np.ndarray:
        """Origins for rays leaving surface ``points`` along ``dirs``: offset along the geometric
        normal to the side the ray goes, by a distance that scales with the coordinates' magnitude
        (float32 Embree resolves about 6e-8 of it)."""
        scale = OFFSET_SCALE * (1.0 + max3(np.abs(points - self.center)))
        side = np.where(dot(dirs, normals) >= 0, 1.0, -1.0)
        return points + (side * scale)[:, None] * normals
