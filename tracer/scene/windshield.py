"""Windshields from their parameters (``objects[].windshield``, :data:`WINDSHIELD`): a closed glass shell,
flat or curved, of even thickness or wedged, meshed and given its two exact surfaces.

The object's own frame: the inner surface (the driver's side) passes through the origin with its normal
along +z, toward the driver; the glass lies behind it (-z); x runs across the car and y up the glass.
A layer ``depth_mm`` behind the inner surface (a laminate's PVB) is the same shell moved back.

- **Curvature.** ``radius_x_mm`` and ``radius_y_mm`` are the inner surface's radii in its x-z and y-z
  sections, positive with the centre of curvature on the driver's side (a windshield bulges outward, so
  seen from inside it is concave): a biconic (a cylinder with one radius 0, a sphere with two equal
  ones). Surfaces behind it are concentric: depth e gives radii R + e.
- **Wedge.** The outer surface is turned by ``wedge_mrad`` so that the glass thickens along
  ``wedge_direction_deg`` (from +x toward +y; 90: thicker toward the top): thickness t + delta s at
  distance s along that direction (small angles). A wedge deviates the ghost's reflection by about 2 n
  delta cos(theta') / cos(theta) (../shared/reference/hud-optical-metrics.md), which fuses it with the
  primary image when it equals the plate offset's angle d / VID.
- **Laminate.** Two objects: the glass at full thickness (index 1.52) and, inside it, the interlayer as a
  second windshield block with its own depth, thickness and index (``ior`` 1.48, ``ior_outside`` 1.52):
  nested dielectrics whose faces never coincide.

The mesh is a grid of ``cells`` on each face (the default keeps a facet's sagitta below 0.02 mm) and a
strip along each edge; the exact surfaces (tracer.scene.surfaces) make the facets irrelevant to the
optics.
"""

from __future__ import annotations

import math

import numpy as np

from ..core.schema import Field
from ..optics.shapes import SHAPES, surface_frame

#: A facet's sagitta, mm, that the default mesh keeps below (a square cell of side h on radius R: h^2 / (4 R)
#: over its diagonal).
SAGITTA_MM = 0.02
#: Most cells along either side.
MAX_CELLS = 400

WINDSHIELD = Field(
    "windshield", "group", None, label="Windshield",
    description="A glass shell made from parameters (in place of a mesh), with its exact surfaces",
    fields=(
        Field("size_mm", "vector2", unit="mm", minimum=1.0, maximum=5000.0,
              description="[width along x, height along y] of the inner surface's outline, projected on its "
                          "tangent plane"),
        Field("thickness_mm", "number", unit="mm", minimum=0.01, maximum=100.0,
              description="Thickness at the origin, along z"),
        Field("depth_mm", "number", 0.0, unit="mm", minimum=0.0, maximum=100.0,
              description="How far behind the inner surface this shell starts (a laminate's interlayer)"),
        Field("wedge_mrad", "number", 0.0, unit="mrad", minimum=-50.0, maximum=50.0,
              description="Angle between the outer and the inner surface"),
        Field("wedge_direction_deg", "number", 90.0, unit="deg", minimum=-360.0, maximum=360.0,
              description="Direction in which the glass thickens, from +x toward +y (90: thicker toward the top)"),
        Field("radius_x_mm", "number", 0.0, unit="mm", minimum=-1e7, maximum=1e7,
              description="Inner surface's radius in the x-z section, positive with the centre on the driver's "
                          "side (+z); 0 flat"),
        Field("radius_y_mm", "number", 0.0, unit="mm", minimum=-1e7, maximum=1e7,
              description="The same in the y-z section"),
        Field("cells", "int2", None, minimum=1, maximum=MAX_CELLS,
              description="Mesh cells [across, up] on each face; absent: 1 x 1 where flat, else a facet sagitta "
                          f"below {SAGITTA_MM:g} mm"),
    ))


def _surface_specs(p: dict) -> list[dict]:
    """The inner and outer surfaces as ``surfaces`` blocks (tracer.scene.format.SURFACE) in the object's frame."""
    depth, t = p["depth_mm"], p["thickness_mm"]
    delta = p["wedge_mrad"] * 1e-3
    phi = math.radians(p["wedge_direction_deg"])
    w = np.array([math.cos(phi), math.sin(phi)])
    axis_out = [math.sin(delta) * w[0], math.sin(delta) * w[1], math.cos(delta)]

    def shape(e):
        rx, ry = p["radius_x_mm"], p["radius_y_mm"]
        rx, ry = (rx + e if rx else 0.0), (ry + e if ry else 0.0)
        if rx == 0 and ry == 0:
            return {"type": "plane"}
        return {"type": "biconic", "radius_x_mm": rx, "radius_y_mm": ry}

    return [shape(depth) | {"origin": [0.0, 0.0, -depth]},
            shape(depth + t) | {"origin": [0.0, 0.0, -depth - t], "axis": axis_out, "x_axis": [1.0, 0.0, 0.0]}]


def _shape(spec: dict):
    schema, make = SHAPES[spec["type"]]
    params = {f.name: spec.get(f.name, f.default) for f in schema.fields}
    return make(params)


def _on_surface(spec: dict, x: np.ndarray, y: np.ndarray, z0: np.ndarray) -> np.ndarray:
    """z (n,) such that (x, y, z) lies on the surface ``spec``: Newton's method along z from ``z0``."""
    inv = np.linalg.inv(surface_frame(spec["origin"], spec.get("axis", (0.0, 0.0, 1.0)),
                                      spec.get("x_axis", (1.0, 0.0, 0.0))))
    shape = _shape(spec)
    z = z0.copy()
    a, b = inv[:3, :3], inv[:3, 3:4]
    for _ in range(30):
        q = a @ np.stack([x, y, z]) + b
        gx, gy = shape.gradient(q[0], q[1])
        f = q[2] - shape.sag(q[0], q[1])
        df = a[2, 2] - gx * a[0, 2] - gy * a[1, 2]
        step = f / df
        z = z - step
        if np.abs(step).max() < 1e-12:
            break
    return z


def radius_problem(p: dict) -> tuple[str, str] | None:
    """(field, what is wrong) where a radius of the parsed block ``p`` is neither 0 (flat) nor at least
    half the outline's larger side (a shell that closes on itself), else None."""
    least = 0.5 * max(p["size_mm"])
    for key in ("radius_x_mm", "radius_y_mm"):
        if 0 < abs(p[key]) < least:
            return key, f"|radius| must be 0 (flat) or at least half the size ({least:g} mm), got {p[key]:g}"
    return None


def cells_for(p: dict) -> tuple[int, int]:
    """The mesh cells [across, up] of a windshield block (its ``cells``, or the default)."""
    if p.get("cells") is not None:
        return tuple(p["cells"])
    radii = [abs(r) for r in (p["radius_x_mm"], p["radius_y_mm"]) if r]
    if not radii:
        return (1, 1)
    h = math.sqrt(4 * min(radii) * SAGITTA_MM)  # a cell's diagonal, h sqrt(2), of sagitta h^2 / (4 R)
    return tuple(int(min(MAX_CELLS, max(1, math.ceil(s / h)))) for s in p["size_mm"])


def windshield_mesh(p: dict) -> tuple[np.ndarray, np.ndarray, list[dict]]:
    """(vertices (v, 3) mm, faces (f, 3), surfaces blocks) of a parsed windshield block ``p``, in the
    object's frame: a closed shell with outward normals."""
    nx, ny = cells_for(p)
    inner, outer = _surface_specs(p)
    w, h = p["size_mm"]
    gx, gy = np.meshgrid(np.linspace(-w / 2, w / 2, nx + 1), np.linspace(-h / 2, h / 2, ny + 1))
    x, y = gx.ravel(), gy.ravel()
    z_in = _on_surface(inner, x, y, np.full(x.shape, -p["depth_mm"]))
    z_out = _on_surface(outer, x, y, z_in - p["thickness_mm"])
    if np.any(z_in - z_out <= 0):
        raise ValueError("the glass's thickness reaches 0 inside its outline: a smaller wedge or a thicker glass")
    verts = np.concatenate([np.stack([x, y, z_in], 1), np.stack([x, y, z_out], 1)])
    k = len(x)
    idx = np.arange(k).reshape(ny + 1, nx + 1)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel(), idx[1:, 1:].ravel(), idx[1:, :-1].ravel()
    top = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])  # normal +z
    bottom = top[:, ::-1] + k  # normal -z
    ring = np.concatenate([idx[0, :-1], idx[:-1, -1], idx[-1, :0:-1], idx[:0:-1, 0]])  # counter-clockwise from +z
    nxt = np.roll(ring, -1)
    sides = np.concatenate([np.stack([ring, ring + k, nxt + k], 1), np.stack([ring, nxt + k, nxt], 1)])
    return verts, np.concatenate([top, bottom, sides]), [inner, outer]
