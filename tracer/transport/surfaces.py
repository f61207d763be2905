"""Exact surfaces in the path loop: a hit on a face that lies on an analytic surface
(:class:`tracer.scene.Surface`) is moved onto the surface, and takes its normal.

A mirror meshed into facets with interpolated normals bends rays by the facet's error; for the image's
metrics (virtual image distance, distortion, disparity) that error is of the order of the
specifications. So every closest hit Embree finds on such a face is refined in float64 by Newton's
method along the ray, from the mesh's distance, on F(q(t)) = q_z - sag(q_x, q_y) = 0 in the surface's
frame (q(t) = A (o + t d) + b: the affine frame map; F' = grad F . A d); it converges in two to four
steps from a hit within a facet's sagitta. The normal is the gradient of F carried to the world by the
inverse transpose, A^T grad F, turned to the mesh face's side so that materials see the same front and
back. A hit where Newton fails (outside the shape's domain, or a root farther than a few facet gaps from
the mesh: a ray grazing the surface) keeps the mesh's distance and normal.

Rays leave a refined point beyond the mesh: the face's spawn offset grows by twice its largest
distance from the surface (``gap_mm``), so that a ray reflected on the concave side of a mirror, where
the facets lie in front of the surface, does not meet them again.
"""

from __future__ import annotations

import numpy as np

from ..core.vec import dot, norm, take
from ..optics.shapes import implicit

#: Newton steps at most; a step below NEWTON_TOL (mm) ends them.
NEWTON_STEPS = 8
NEWTON_TOL = 1e-9
#: A refined hit may lie at most this many times the face's gap (along the normal) from the mesh's.
ACCEPT_GAPS = 8.0


class SurfaceTable:
    """The exact surfaces of the traced objects, by global face.

    Attributes
    ----------
    face_surface : (F,) the index into ``surfaces`` of every global face's surface, or -1.
    gap : (F,) the largest distance between a face and its surface, mm (0 for faces without one).
    surfaces : list of (tracer.scene.Surface, the object's name).
    refined, kept : hits refined onto a surface, and hits on a surface's faces where Newton failed.
    """

    def __init__(self, objects: list, first_face: dict[int, int], faces: int):
        self.face_surface = np.full(faces, -1, np.int64)
        self.gap = np.zeros(faces)
        self.surfaces = []
        for o in objects:
            for s in o.surfaces:
                idx = first_face[o.slot] + s.faces
                self.face_surface[idx] = len(self.surfaces)
                self.gap[idx] = s.gap_mm
                self.surfaces.append((s, o.name))
        self._a = [s.to_local[:3, :3] for s, _ in self.surfaces]
        self._b = [s.to_local[:3, 3:4] for s, _ in self.surfaces]
        self.refined = 0
        self.kept = 0

    def __len__(self) -> int:
        return len(self.surfaces)

    def _groups(self, face: np.ndarray):
        """(surface index, positions into ``face``) of every surface the faces lie on."""
        sid = np.where(face >= 0, take(self.face_surface, np.maximum(face, 0)), -1)
        on = np.flatnonzero(sid >= 0)
        if len(on) == 0:
            return
        order = on[np.argsort(sid[on], kind="stable")]
        ids, starts = np.unique(sid[order], return_index=True)
        ends = np.append(starts[1:], len(order))
        for k, a, b in zip(ids.tolist(), starts.tolist(), ends.tolist(), strict=True):
            yield k, order[a:b]

    def refine(self, o: np.ndarray, d: np.ndarray, face: np.ndarray, t: np.ndarray) -> np.ndarray:
        """Distances (n,) mm of rays ``o`` (3, n) mm, ``d`` (3, n) unit, to their hits on faces ``face``
        (n,; -1 a miss), refined onto the exact surfaces; ``t`` (n,) the mesh's distances (unchanged
        where a face has no surface or Newton fails)."""
        out = t
        for k, idx in self._groups(face):
            if out is t:
                out = t.copy()
            shape = self.surfaces[k][0].shape
            a, b = self._a[k], self._b[k]
            ok_, dd = take(o, idx), take(d, idx).astype(np.float64)
            q0 = a @ ok_ + b
            dq = a @ dd
            tk = t[idx].copy()
            with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
                for _ in range(NEWTON_STEPS):
                    q = q0 + tk * dq
                    f, g = implicit(shape, q)
                    step = f / (g * dq).sum(axis=0)
                    tk -= step
                    if not np.any(np.abs(step) > NEWTON_TOL * (1.0 + np.abs(tk))):
                        break
                f, g = implicit(shape, q0 + tk * dq)
                gw = a.T @ g
                cos = np.abs((gw * dd).sum(axis=0)) / np.sqrt((gw * gw).sum(axis=0))
                bound = ACCEPT_GAPS * (self.gap[face[idx]] + 1e-6) / np.maximum(cos, 1e-3)
                good = np.isfinite(tk) & np.isfinite(f) & (np.abs(tk - t[idx]) <= bound) & (tk > 0)
                good &= np.abs(f) / np.sqrt((gw * gw).sum(axis=0)) <= 1e-6 * (1.0 + np.abs(tk))
            out[idx[good]] = tk[good]
            self.refined += int(good.sum())
            self.kept += int((~good).sum())
        return out

    def normals(self, face: np.ndarray, p: np.ndarray, ng: np.ndarray) -> np.ndarray:
        """Unit normals (3, n) float32 at points ``p`` (3, n) of faces ``face``: the exact surface's where
        the face lies on one, on the side of the mesh's normal ``ng`` (3, n), else ``ng`` itself."""
        out = ng
        for k, idx in self._groups(face):
            if out is ng:
                out = ng.copy()
            a, b = self._a[k], self._b[k]
            with np.errstate(invalid="ignore", divide="ignore"):
                _, g = implicit(self.surfaces[k][0].shape, a @ take(p, idx) + b)
                n = a.T @ g
                n = n / norm(n)
            good = np.isfinite(n).all(axis=0)
            m = take(ng, idx)
            n = np.where(dot(n, m) < 0, -n, n)
            out[:, idx[good]] = n[:, good]
        return out
