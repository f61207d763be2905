"""Targets of the paper's directed sampling (sec. 2): the eye pupil or a named planar aperture.

A target draws directions from given origins toward a uniformly sampled point of its surface and
reports the solid-angle pdf dist^2 / (A |cos|) of any direction (zero where the ray misses it), so
the integrators can form the one-sample mixture of directed and ordinary sampling, which stays
unbiased for every share w < 1.
"""

from __future__ import annotations

import numpy as np

from .accel import Accelerator
from .sampling import disk_aperture_pdf, sample_disk_aperture, sample_triangles, triangle_areas
from .vec import dot, norm


class DiskTarget:
    """A disk (centre (3,), unit normal (3,), radius, mm): the eye pupil."""

    def __init__(self, center: np.ndarray, normal: np.ndarray, radius: float):
        self.center, self.normal, self.radius = center, normal, radius

    def sample(self, origins: np.ndarray, u: np.ndarray):
        """(directions (n, 3), pdf per sr (n,)) toward uniform points of the disk; u is (n, 3)."""
        d, _, pdf = sample_disk_aperture(origins, self.center, self.normal, self.radius, u[:, :2])
        return d, pdf

    def pdf(self, origins: np.ndarray, dirs: np.ndarray) -> np.ndarray:
        return disk_aperture_pdf(origins, dirs, self.center, self.normal, self.radius)


class MeshTarget:
    """A planar triangle mesh (world mm) used as an aperture: an LCD, a window, a virtual stop."""

    def __init__(self, triangles: np.ndarray):
        self.triangles = triangles
        self.areas = triangle_areas(triangles)  # mm^2
        self.area = float(self.areas.sum())
        n = np.cross(triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0]).sum(axis=0)
        self.normal = n / np.linalg.norm(n)
        faces = np.arange(3 * len(triangles)).reshape(-1, 3)
        self._accel = Accelerator([(triangles.reshape(-1, 3), faces)])

    def sample(self, origins: np.ndarray, u: np.ndarray):
        points, _, _ = sample_triangles(self.triangles, u, self.areas)
        v = points - origins
        dist = norm(v)
        d = v / np.maximum(dist, 1e-300)[:, None]
        cos = np.abs(dot(d, self.normal))
        ok = (cos > 1e-9) & (dist > 0)
        pdf = np.where(ok, dist**2 / (self.area * np.where(ok, cos, 1.0)), 0.0)
        return d, pdf

    def pdf(self, origins: np.ndarray, dirs: np.ndarray) -> np.ndarray:
        hits = self._accel.intersect(origins, dirs)
        cos = np.abs(dot(dirs, self.normal))
        ok = hits.hit & (cos > 1e-9)
        return np.where(ok, np.where(ok, hits.t, 0.0) ** 2 / (self.area * np.where(ok, cos, 1.0)), 0.0)
