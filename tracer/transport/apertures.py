"""Targets of the paper's directed sampling (sec. 2): the eye pupil or a named planar aperture.

A target draws directions from given origins toward a uniformly sampled point of its surface and
reports the solid-angle pdf dist^2 / (A |cos|) of any direction (zero where the ray misses it), so
the integrators can form the one-sample mixture of directed and ordinary sampling
(:class:`tracer.transport.path.Aimed`), which stays unbiased for every share w < 1.
Points and directions are (3, n) planes.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from ..core.sampling import Distribution1D, TriangleSet, disk_aperture_pdf, sample_disk_aperture
from ..core.vec import F32, dot, norm
from .accel import Accelerator


class DiskTarget:
    """A disk (centre (3,), unit normal (3,), radius, mm): the eye pupil."""

    dims = 2

    def __init__(self, center: np.ndarray, normal: np.ndarray, radius: float):
        self.center, self.normal, self.radius = center, normal, radius

    def sample(self, origins: np.ndarray, u: np.ndarray):
        """(directions (3, n) float32, pdf per sr (n,) float32) toward uniform points of the disk; u is (2, n)."""
        d, _, pdf = sample_disk_aperture(origins, self.center, self.normal, self.radius, u.astype(np.float64))
        return d.astype(F32), pdf.astype(F32)

    def pdf(self, origins: np.ndarray, dirs: np.ndarray) -> np.ndarray:
        return disk_aperture_pdf(origins, dirs.astype(np.float64), self.center, self.normal, self.radius).astype(F32)


class MeshTarget:
    """A planar triangle mesh (world mm) used as an aperture: an LCD, a window, a virtual stop."""

    dims = 3

    def __init__(self, triangles: np.ndarray):
        self.tris = TriangleSet(triangles)
        self.area = float(self.tris.area.sum())  # mm^2
        n = (self.tris.normal * self.tris.area).sum(axis=1)
        self.normal = (n / np.linalg.norm(n)).reshape(3, 1)
        self._dist = Distribution1D(self.tris.area)
        faces = np.arange(3 * len(triangles)).reshape(-1, 3)
        mesh = SimpleNamespace(vertices=np.asarray(triangles).reshape(-1, 3), faces=faces, slot=0, normals=None,
                               uv=None, surfaces=[])
        self._accel = Accelerator([mesh])

    @property
    def rays_traced(self) -> int:
        return self._accel.rays_traced

    def sample(self, origins: np.ndarray, u: np.ndarray):
        """(directions (3, n) float32, pdf per sr (n,) float32) toward uniform points of the mesh; u is (3, n)."""
        tri, _ = self._dist.sample(u[0])
        v = self.tris.point(tri, u[1:3].astype(np.float64)) - origins
        dist = norm(v)
        d = v * (1.0 / np.maximum(dist, 1e-300))
        cos = np.abs(dot(d, self.normal))
        ok = (cos > 1e-9) & (dist > 0)
        pdf = np.where(ok, dist * dist / (self.area * np.where(ok, cos, 1.0)), 0.0)
        return d.astype(F32), pdf.astype(F32)

    def pdf(self, origins: np.ndarray, dirs: np.ndarray) -> np.ndarray:
        hits = self._accel.intersect(origins, dirs.astype(F32, copy=False))
        cos = np.abs(dot(dirs.astype(np.float64), self.normal))
        ok = hits.hit & (cos > 1e-9)
        t = np.where(ok, hits.t, 0.0)
        return np.where(ok, t * t / (self.area * np.where(ok, cos, 1.0)), 0.0).astype(F32)
