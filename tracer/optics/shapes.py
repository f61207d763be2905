"""Analytic surface shapes: the exact form of the optics that make the image (a mirror, a windshield's
faces), as sags z = s(x, y) on a local frame (mm; the vertex at the origin, the axis along +z).

A scene object's mesh stays what Embree intersects; a hit on one of its faces that lies on such a surface
is refined onto the surface and takes its exact normal (:mod:`tracer.transport.surfaces`), so that
facets and interpolated normals do not bend the rays (a facet's error is mrad where the image's
specifications are tenths of a mrad). The sags are those of the lens-design programs (Zemax
OpticStudio's "Standard", "Biconic" and "Extended polynomial" surfaces; W. J. Smith, "Modern Optical
Engineering", 4th ed., sec. 18.3):

- conic: z = c r^2 / (1 + sqrt(1 - (1 + k) c^2 r^2)), c = 1 / R the vertex curvature, k the conic
  constant (0 sphere, -1 paraboloid, between -1 and 0 a prolate ellipsoid, < -1 a hyperboloid); a plane
  is c = 0;
- biconic: z = (c_x x^2 + c_y y^2) / (1 + sqrt(1 - (1 + k_x) c_x^2 x^2 - (1 + k_y) c_y^2 y^2)) (a
  cylinder with c_y = 0, a toroid-like surface of two curvatures);
- xy polynomial: a conic plus sum a_ij x^i y^j (a freeform).

Each shape gives its sag and its gradient (dz/dx, dz/dy) in closed form; outside its domain (where the
square root's argument is negative) the sag is NaN. :func:`implicit` gives the surface as F(q) = q_z -
sag(q_x, q_y) = 0 with its gradient, which is what ray intersection (Newton's method along the ray) and
normals (the gradient, carried to the world by the inverse transpose of the frame's map) need.
"""

from __future__ import annotations

import numpy as np

from ..core.schema import Field, Schema

#: Largest |curvature| of a shape, 1/mm (a radius of 0.1 mm).
MAX_CURVATURE = 10.0


class Shape:
    """A sag z = s(x, y) on the shape's local frame (mm)."""

    schema: Schema

    def sag(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        raise NotImplementedError

    def gradient(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        raise NotImplementedError


def _curvature(radius: float) -> float:
    """The curvature 1 / R of a signed radius (mm); 0 for a radius of 0 (flat)."""
    return 0.0 if radius == 0 else 1.0 / radius


class Conic(Shape):
    """z = c r^2 / (1 + sqrt(1 - (1 + k) c^2 r^2)); a sphere with k = 0, a plane with c = 0."""

    def __init__(self, c: float, k: float = 0.0):
        self.c, self.k = float(c), float(k)

    def _root(self, r2: np.ndarray) -> np.ndarray:
        arg = 1.0 - (1.0 + self.k) * self.c * self.c * r2
        with np.errstate(invalid="ignore"):
            return np.sqrt(np.where(arg >= 0, arg, np.nan))

    def sag(self, x, y):
        r2 = x * x + y * y
        return self.c * r2 / (1.0 + self._root(r2))

    def gradient(self, x, y):
        root = self._root(x * x + y * y)
        return self.c * x / root, self.c * y / root


class Biconic(Shape):
    """z = (c_x x^2 + c_y y^2) / (1 + sqrt(1 - (1 + k_x) c_x^2 x^2 - (1 + k_y) c_y^2 y^2))."""

    def __init__(self, cx: float, cy: float, kx: float = 0.0, ky: float = 0.0):
        self.cx, self.cy, self.kx, self.ky = float(cx), float(cy), float(kx), float(ky)

    def _parts(self, x, y):
        num = self.cx * x * x + self.cy * y * y
        arg = 1.0 - (1.0 + self.kx) * self.cx ** 2 * x * x - (1.0 + self.ky) * self.cy ** 2 * y * y
        with np.errstate(invalid="ignore"):
            root = np.sqrt(np.where(arg >= 0, arg, np.nan))
        return num, root

    def sag(self, x, y):
        num, root = self._parts(x, y)
        return num / (1.0 + root)

    def gradient(self, x, y):
        num, root = self._parts(x, y)
        den = (1.0 + root) ** 2
        # d root / dx = -(1 + k_x) c_x^2 x / root, and the same in y.
        gx = (2 * self.cx * x * (1.0 + root) + num * (1.0 + self.kx) * self.cx ** 2 * x / root) / den
        gy = (2 * self.cy * y * (1.0 + root) + num * (1.0 + self.ky) * self.cy ** 2 * y / root) / den
        return gx, gy


class XYPolynomial(Shape):
    """A conic plus sum a_ij x^i y^j (x, y in mm; a_ij in mm^(1 - i - j))."""

    def __init__(self, base: Conic, terms: list[tuple[int, int, float]]):
        self.base = base
        self.terms = [(int(i), int(j), float(a)) for i, j, a in terms]

    def sag(self, x, y):
        z = self.base.sag(x, y)
        for i, j, a in self.terms:
            z = z + a * x ** i * y ** j
        return z

    def gradient(self, x, y):
        gx, gy = self.base.gradient(x, y)
        for i, j, a in self.terms:
            if i:
                gx = gx + a * i * x ** (i - 1) * y ** j
            if j:
                gy = gy + a * j * x ** i * y ** (j - 1)
        return gx, gy


def implicit(shape: Shape, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """F(q) = q_z - sag(q_x, q_y) at points ``q`` (3, n) of the shape's frame, and its gradient (3, n):
    (-dz/dx, -dz/dy, 1). F is NaN outside the shape's domain."""
    gx, gy = shape.gradient(q[0], q[1])
    return q[2] - shape.sag(q[0], q[1]), np.stack([-gx, -gy, np.ones_like(q[0])])


def distance(shape: Shape, to_local: np.ndarray, p: np.ndarray) -> np.ndarray:
    """(n,) the distance (mm, to first order: |F| / |grad_p F|) of world points ``p`` (3, n) from the
    shape placed by ``to_local`` (4, 4: world mm -> the shape's frame); NaN outside its domain."""
    a = to_local[:3, :3]
    f, g = implicit(shape, a @ p + to_local[:3, 3:4])
    gw = a.T @ g
    return np.abs(f) / np.sqrt((gw * gw).sum(axis=0))


_RADIUS = Field("radius_mm", "number", unit="mm", minimum=-1e7, maximum=1e7,
                description="Vertex radius of curvature, signed: positive with the centre of curvature on +z "
                            "(0: flat)")
_CONIC = Field("conic", "number", 0.0, unit="1", minimum=-1e3, maximum=1e3,
               description="Conic constant k: 0 sphere, -1 paraboloid, -1 < k < 0 prolate ellipsoid, k < -1 "
                           "hyperboloid")

#: The shapes by their scene.json ``type``, each with the fields of its block (besides ``type`` and
#: ``frame``) and how its parsed fields make it.
SHAPES: dict[str, tuple[Schema, callable]] = {
    "plane": (Schema("plane", "Plane", "z = 0"), lambda p: Conic(0.0)),
    "sphere": (Schema("sphere", "Sphere", "z = c r^2 / (1 + sqrt(1 - c^2 r^2)), c = 1 / radius", (_RADIUS,)),
               lambda p: Conic(_curvature(p["radius_mm"]))),
    "conic": (Schema("conic", "Conic", "z = c r^2 / (1 + sqrt(1 - (1 + k) c^2 r^2))", (_RADIUS, _CONIC)),
              lambda p: Conic(_curvature(p["radius_mm"]), p["conic"])),
    "biconic": (Schema("biconic", "Biconic (toroid, cylinder)",
                       "z = (c_x x^2 + c_y y^2) / (1 + sqrt(1 - (1 + k_x) c_x^2 x^2 - (1 + k_y) c_y^2 y^2))", (
        Field("radius_x_mm", "number", unit="mm", minimum=-1e7, maximum=1e7,
              description="Vertex radius in the x-z section, signed (0: flat, a cylinder's straight direction)"),
        Field("radius_y_mm", "number", unit="mm", minimum=-1e7, maximum=1e7,
              description="Vertex radius in the y-z section, signed (0: flat)"),
        Field("conic_x", "number", 0.0, unit="1", minimum=-1e3, maximum=1e3, description="Conic constant in x"),
        Field("conic_y", "number", 0.0, unit="1", minimum=-1e3, maximum=1e3, description="Conic constant in y"))),
        lambda p: Biconic(_curvature(p["radius_x_mm"]), _curvature(p["radius_y_mm"]), p["conic_x"], p["conic_y"])),
    "xy_polynomial": (Schema("xy_polynomial", "XY polynomial (freeform)",
                             "z = conic(r) + sum a_ij x^i y^j", (
        Field("radius_mm", "number", 0.0, unit="mm", minimum=-1e7, maximum=1e7,
              description="Vertex radius of the base conic, signed (0: flat)"),
        _CONIC,
        Field("terms", "list", description="[[i, j, a_ij], ...]: the coefficient a_ij (mm^(1 - i - j)) of x^i y^j, "
                                           "i + j from 1 to 10"))),
        lambda p: XYPolynomial(Conic(_curvature(p["radius_mm"]), p["conic"]), p["terms"])),
}


def frame_matrix(origin, z: np.ndarray, x: np.ndarray) -> np.ndarray:
    """The 4 x 4 map from a shape's frame to the coordinates ``origin``, unit ``z`` and unit ``x`` (square
    to it) are given in: columns x, z x x, z and the origin."""
    m = np.eye(4)
    m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = x, np.cross(z, x), z, origin
    return m


def surface_frame(origin, axis, x_axis) -> np.ndarray:
    """:func:`frame_matrix` of a surface block's origin, ``axis`` (+z) and ``x_axis`` (+x, made square
    to it); the axes must not be parallel (the loader checks a block's, tracer.scene.surfaces)."""
    z = np.asarray(axis, dtype=np.float64)
    z = z / np.linalg.norm(z)
    x = np.asarray(x_axis, dtype=np.float64)
    x = x - (x @ z) * z
    return frame_matrix(origin, z, x / np.linalg.norm(x))
