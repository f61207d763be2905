"""The observer: a thin-lens eye with a finite pupil (paper sec. 1-2, eqs. 2-3).

Eye coordinates: origin at the pupil centre, x to the right, y up, z along the gaze. The pupil is a
disk of radius ``a`` in the plane z = 0 and is also the thin lens; the retina is a plane at
z = -f (f = ``focal_length_mm``, default 16.67 mm: the equivalent focal length of Emsley's reduced
eye). The lens is focused at the accommodation distance s: a point at z = s images sharply on the
retina, other points blur into a circle of angular diameter D |1/s_point - 1/s|.

Retina positions are given as perceived: ``(sx, sy)`` is the point where the chief ray of a scene
direction (sx, sy, f) meets the plane z = f, i.e. the inverted physical retina point (-sx, -sy, -f)
turned upright. Pixel (0, 0) is top-left, as the image is seen.

Points and directions are (3, n) planes (:mod:`tracer.core.vec`), pupil points (2, n).

Apparent luminance. The lens is ideal and lossless: the flux L cos(theta) dOmega dA that crosses
the pupil at x along a scene direction of angle theta to the axis lands, by the lens mapping
p = f (x / s + tan theta), on the retina area f^2 dOmega / cos^3(theta). The retinal illuminance is
therefore ``E(p) = integral over the pupil of L(x, p) cos^4(theta(x, p)) / f^2 dA_x`` (paper eq. 2),
where theta is the angle of the scene-side ray from x toward the point of the accommodation plane
that images at p. At infinite focus this is the paper's relation L = E f^2 / (A cos^4 theta). Each
pixel divides its flux by its exact extent ``G_pix = integral over the pixel and the pupil of
cos^4 theta / f^2``, which has a closed form through the view factor of a disk (:func:`disk_view_factor`),
so a uniform surround of luminance L0 renders L0 in every pixel for any pupil, focus or field angle
(the furnace test), and forward and backward tracing estimate the same number.
"""

from __future__ import annotations

import math

import numpy as np

from ..core.vec import F32, dot, normalize, take
from ..scene import EyeSpec


def disk_view_factor(rho: np.ndarray, h: float, a: float) -> np.ndarray:
    """View factor from a differential area to a parallel disk (radius ``a``, distance ``h``,
    lateral offset ``rho`` of the element from the disk axis; all mm).

    F = (1/2) [1 - (h^2 + rho^2 - a^2) / S],  S = sqrt((h^2 + rho^2 + a^2)^2 - 4 a^2 rho^2)
    (Howell, A Catalog of Radiation Heat Transfer Configuration Factors, factor B-13;
    Modest, Radiative Heat Transfer, 3rd ed., doi:10.1016/C2010-0-65874-3, app. D), evaluated as
    F = a^2 (S + h^2 + a^2 - rho^2) / (S (S + X)), X = h^2 + rho^2 + a^2, the same number without the
    cancellation of 1 - (...) / S, which loses every digit once a / h < 1e-8 (a pupil of 1e-5 mm, or
    focus at 1e10 mm: F ~ a^2 / h^2 then).
    """
    rho2 = np.asarray(rho, dtype=np.float64) ** 2
    h2, a2 = h * h, a * a
    x = h2 + rho2 + a2
    s = np.sqrt((x - 2.0 * a * np.sqrt(rho2)) * (x + 2.0 * a * np.sqrt(rho2)))
    return a2 * (s + h2 + a2 - rho2) / (s * (s + x))


class ThinLensEye:
    """Thin-lens eye built from an :class:`tracer.scene.EyeSpec` (all lengths in mm)."""

    def __init__(self, spec: EyeSpec):
        self.spec = spec
        self.position = np.asarray(spec.position, dtype=np.float64)
        self.gaze = spec.gaze / np.linalg.norm(spec.gaze)
        right = np.cross(self.gaze, spec.up)
        self.right = right / np.linalg.norm(right)
        self.up = np.cross(self.right, self.gaze)
        self._pos, self._right, self._up, self._gaze = (v.reshape(3, 1) for v in
                                                        (self.position, self.right, self.up, self.gaze))
        self.focal = float(spec.focal_length_mm)
        self.pupil_radius = 0.5 * float(spec.pupil_diameter_mm)
        self.pupil_area = math.pi * self.pupil_radius**2
        self.accommodation = float(spec.accommodation_distance_mm)
        self.width, self.height = spec.resolution
        self.half_x = self.focal * math.tan(math.radians(spec.fov_deg[0]) / 2)
        self.half_y = self.focal * math.tan(math.radians(spec.fov_deg[1]) / 2)
        self.pixel_w = 2 * self.half_x / self.width
        self.pixel_h = 2 * self.half_y / self.height
        self.pixel_area = self.pixel_w * self.pixel_h
        #: G_pix per flat pixel, filled as pixels are first asked for (:meth:`extent_of`): NaN until then.
        self._extent = np.full(self.width * self.height, np.nan)

    @property
    def extent(self) -> np.ndarray:
        """G_pix (mm^2) of every pixel, flat (H*W,) (:meth:`extent_of` of them all)."""
        return self.extent_of(np.arange(self.width * self.height))

    def extent_of(self, pix: np.ndarray) -> np.ndarray:
        """G_pix (mm^2) of the flat pixels ``pix`` (n,). Each pixel's is computed the first time it is asked
        for and kept: a render that samples part of a large retina (a short budget at 4K) computes only
        those, and the same numbers as computing all at once (each is its own elementwise sum)."""
        pix = np.asarray(pix, dtype=np.int64)
        got = self._extent[pix]
        missing = np.isnan(got)
        if missing.any():
            new = np.unique(pix[missing])
            self._extent[new] = self._pixel_extent(new)
            got = self._extent[pix]
        return got

    @property
    def smallest_extent(self) -> float:
        """The smallest G_pix (mm^2): a corner pixel's (G_pix falls with the distance from the axis, and a
        corner pixel's quadrature nodes lie farther out than those of any pixel of its quadrant)."""
        w, h = self.width, self.height
        return float(self.extent_of(np.array([0, w - 1, (h - 1) * w, h * w - 1])).min())

    # -- geometry ---------------------------------------------------------------------------
    def to_local(self, v: np.ndarray) -> np.ndarray:
        """World vectors (3, n) to eye coordinates (3, n)."""
        return np.stack([dot(v, self._right), dot(v, self._up), dot(v, self._gaze)])

    def to_world(self, v: np.ndarray) -> np.ndarray:
        """Eye-coordinate vectors (3, n) to world vectors (3, n)."""
        return v[0] * self._right + v[1] * self._up + v[2] * self._gaze

    def pixel_centers(self) -> tuple[np.ndarray, np.ndarray]:
        """Perceived retina coordinates (sx (W,), sy (H,)) of pixel centres, mm."""
        sx = (2 * (np.arange(self.width) + 0.5) / self.width - 1) * self.half_x
        sy = (1 - 2 * (np.arange(self.height) + 0.5) / self.height) * self.half_y
        return sx, sy

    def pixel_of(self, sx: np.ndarray, sy: np.ndarray) -> np.ndarray:
        """Flat pixel index (row-major, top row first) of retina points; -1 outside the retina."""
        i = np.floor((sx / self.half_x + 1) * 0.5 * self.width).astype(np.int64)
        j = np.floor((1 - sy / self.half_y) * 0.5 * self.height).astype(np.int64)
        inside = (i >= 0) & (i < self.width) & (j >= 0) & (j < self.height)
        return np.where(inside, j * self.width + i, -1)

    def _pixel_extent(self, pix: np.ndarray, order: int = 4) -> np.ndarray:
        """G_pix (mm^2) of the flat pixels ``pix``: the pixel integral (Gauss-Legendre, order^2) of the
        pupil integral of cos^4(theta) / f^2, which is (s/f)^2 pi F(s |p| / f; s, a) at accommodation
        distance s (the rays from the pupil converge to the point s p / f of the accommodation plane)
        and A cos^4(theta_p) / f^2 at infinity."""
        nodes, weights = np.polynomial.legendre.leggauss(order)
        sx, sy = self.pixel_centers()
        ox = 0.5 * self.pixel_w * nodes
        oy = 0.5 * self.pixel_h * nodes
        px = sx[pix % self.width][:, None, None] + ox[None, :, None]
        py = sy[pix // self.width][:, None, None] + oy[None, None, :]
        tan2 = (px**2 + py**2) / self.focal**2
        s = self.accommodation
        if math.isinf(s):
            f = self.pupil_area / (self.focal**2 * (1 + tan2) ** 2)
        else:
            f = (s / self.focal) ** 2 * np.pi * disk_view_factor(s * np.sqrt(tan2), s, self.pupil_radius)
        w = (weights[:, None] * weights[None, :]) * 0.25 * self.pixel_area
        total = np.zeros(len(pix))
        for a in range(order):  # fixed summation order (see tracer.core.vec)
            for b in range(order):
                total = total + f[:, a, b] * w[a, b]
        return total

    # -- backward: retina -> scene -------------------------------------------------------------
    def generate_rays(self, sx: np.ndarray, sy: np.ndarray, lens_xy: np.ndarray):
        """Rays from pupil points toward the scene for retina points (sx, sy).

        Parameters
        ----------
        sx, sy : (n,) perceived retina coordinates, mm.
        lens_xy : (2, n) pupil points in eye coordinates, mm.

        Returns
        -------
        origins (3, n) float64, directions (3, n) float32 unit, world space; cos^4(theta) / f^2 (n,)
        float32, 1/mm^2.
        """
        f, s = self.focal, self.accommodation
        if math.isinf(s):
            d_local = np.stack([sx, sy, np.full_like(sx, f)])
        else:
            d_local = np.stack([sx * (s / f) - lens_xy[0], sy * (s / f) - lens_xy[1], np.full_like(sx, s)])
        d_local = normalize(d_local)
        origins = self._pos + lens_xy[0] * self._right + lens_xy[1] * self._up
        cos2 = d_local[2] * d_local[2]
        return origins, self.to_world(d_local).astype(F32), (cos2 * cos2 / (f * f)).astype(F32)

    # -- forward: scene -> retina ---------------------------------------------------------------
    def pupil_hit(self, origins: np.ndarray, dirs: np.ndarray):
        """Intersections of rays with the pupil disk from the front (travelling against the gaze).

        Returns (t (n,) with inf where there is no hit, lens points (2, n) in eye coordinates, valid
        where t is finite).
        """
        n = origins.shape[1]
        t = np.full(n, np.inf)
        lens = np.zeros((2, n))
        dz = dot(dirs, self._gaze)
        oz = dot(origins, self._gaze) - float(self.position @ self.gaze)
        cand = np.flatnonzero((dz < 0) & (oz > 0))
        if len(cand) == 0:
            return t, lens
        o, d = take(origins, cand), take(dirs, cand)
        tc = -oz[cand] / dz[cand]
        rel = o - self._pos + tc * d
        lx, ly = dot(rel, self._right), dot(rel, self._up)
        ok = lx * lx + ly * ly <= self.pupil_radius**2
        keep = cand[ok]
        t[keep] = tc[ok]
        lens[0, keep], lens[1, keep] = lx[ok], ly[ok]
        return t, lens

    def retina_point(self, lens_xy: np.ndarray, dirs: np.ndarray):
        """Perceived retina coordinates (sx, sy) where the thin lens images rays (n,) that cross
        the pupil at ``lens_xy`` (2, n) travelling along world ``dirs`` (3, n) (toward the eye)."""
        dl = self.to_local(dirs)
        f, s = self.focal, self.accommodation
        inv_s = 0.0 if math.isinf(s) else 1.0 / s
        sx = f * (lens_xy[0] * inv_s + dl[0] / dl[2])
        sy = f * (lens_xy[1] * inv_s + dl[1] / dl[2])
        return sx, sy

    def blur_diameter_mm(self, distance_mm: float) -> float:
        """Retinal blur-circle diameter (perceived coordinates, mm) of a point at ``distance_mm``:
        f D |1/d - 1/s| (thin lens, geometric optics)."""
        inv_s = 0.0 if math.isinf(self.accommodation) else 1.0 / self.accommodation
        return self.focal * 2 * self.pupil_radius * abs(1.0 / distance_mm - inv_s)
