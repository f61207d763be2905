"""Reading an object's exact surfaces (``objects[].surfaces``, :data:`tracer.scene.format.SURFACE`): each
block's shape and frame, and the faces of the mesh that lie on it.

A face belongs to the first surface on which its three corners lie within the surface's
``tolerance_mm``; a surface that owns no face is an error (its frame or its parameters do not match the
mesh), as is a surface on an object whose light is sampled on its triangles (an emitter) or that is not
traced. For every face a surface owns, the largest distance between the face and the shape (the
corners' residuals, and the facet's sagitta at its centre, its edges' midpoints and three inner points)
is kept: the path loop spawns rays leaving the shape beyond it (tracer.transport.surfaces).
"""

from __future__ import annotations

import hashlib
import json

import numpy as np

from ..core.kept import Kept
from ..core.schema import parse_block
from ..core.validate import FieldChecker
from ..optics.materials import MATERIALS
from ..optics.shapes import MAX_CURVATURE, SHAPES, distance, frame_matrix
from .format import SURFACE
from .model import Surface

#: Largest exponent i + j of an XY-polynomial term.
MAX_ORDER = 10
#: Points of a face (barycentric weights of its corners) where its distance from the shape is measured.
_FACE_POINTS = np.array([[1, 0, 0], [0, 1, 0], [0, 0, 1], [1 / 3, 1 / 3, 1 / 3], [0.5, 0.5, 0], [0, 0.5, 0.5],
                         [0.5, 0, 0.5], [2 / 3, 1 / 6, 1 / 6], [1 / 6, 2 / 3, 1 / 6], [1 / 6, 1 / 6, 2 / 3]])


def _terms(ck: FieldChecker, value, fld: str) -> list[tuple[int, int, float]]:
    if not isinstance(value, list):
        ck.fail(fld, f"expected a list of [i, j, a_ij], got {json.dumps(value)[:60]}")
    out = []
    for k, t in enumerate(value):
        where = f"{fld}[{k}]"
        if not isinstance(t, list) or len(t) != 3:
            ck.fail(where, f"expected [i, j, a_ij], got {json.dumps(t)[:60]}")
        i, j = (int(ck.number(t[m], f"{where}[{m}]", min_value=0, max_value=MAX_ORDER)) for m in (0, 1))
        if any(isinstance(t[m], bool) or float(t[m]) != int(t[m]) for m in (0, 1)):
            ck.fail(where, "the exponents i and j must be integers")
        if not 1 <= i + j <= MAX_ORDER:
            ck.fail(where, f"i + j must lie in [1, {MAX_ORDER}], got {i + j}")
        out.append((i, j, ck.number(t[2], f"{where}[2]")))
    return out


def _frame(ck: FieldChecker, params: dict, fld: str) -> np.ndarray:
    """The 4 x 4 map from the surface's frame to the object's coordinates."""
    z = params["axis"]
    zn = float(np.linalg.norm(z))
    if zn < 1e-12:
        ck.fail(f"{fld}.axis", "must not be the zero vector")
    z = z / zn
    x = params["x_axis"] - (params["x_axis"] @ z) * z
    xn = float(np.linalg.norm(x))
    if xn < 1e-6 * max(float(np.linalg.norm(params["x_axis"])), 1e-300):
        ck.fail(f"{fld}.x_axis", "must not be parallel to axis")
    return frame_matrix(params["origin"], z, x / xn)


#: Distances of faces' points from surfaces computed so far, by their inputs' digest, least recently used
#: first (an F12 after F12 in Blender loads the same surfaces on the same mesh again: 0.1 s of
#: hud-direct's 0.3 s of loading); at most 64 MiB of them.
_DISTANCES = Kept(64 << 20)


def _distances(shape, kind: str, params: dict, to_local: np.ndarray, points: np.ndarray) -> np.ndarray:
    """The distances (mm) of ``points`` (3, n) from ``shape`` (:func:`tracer.optics.shapes.distance`),
    remembered by the digest of the shape's type and parameters, the transform and the points."""
    h = hashlib.sha256(json.dumps([kind, {k: v for k, v in params.items() if k != "tolerance_mm"}], sort_keys=True,
                                  default=lambda a: np.asarray(a).tolist()).encode())
    h.update(np.ascontiguousarray(to_local, np.float64).tobytes())
    h.update(np.ascontiguousarray(points, np.float64).tobytes())
    key = h.digest()
    found = _DISTANCES.get(key)
    if found is not None:
        return found[0]
    with np.errstate(invalid="ignore", over="ignore", divide="ignore"):
        dist = distance(shape, to_local, points)
    _DISTANCES.put(key, (dist,))
    return dist


def load_surfaces(ck: FieldChecker, specs, fld: str, obj_name: str, material_type: str, emits: bool,
                  vertices: np.ndarray, faces: np.ndarray, matrix: np.ndarray, mesh: str) -> list[Surface]:
    """The surfaces of one object: ``specs`` the JSON list, ``fld`` its path; ``vertices`` (v, 3) world
    mm and ``faces`` (f, 3) the object's mesh (file ``mesh``), ``matrix`` its 4 x 4 transform."""
    if not isinstance(specs, list):
        ck.fail(fld, "expected a list of surfaces")
    if not specs:
        return []
    if not MATERIALS[material_type].traced:
        ck.fail(fld, f"material {material_type} is not traced, so it has no surfaces to refine")
    if emits:
        ck.fail(fld, "an emitting object's light is drawn on its triangles; give surfaces to the optics (a "
                     "mirror, a windshield, a lens) and keep emitters flat")
    owner = np.full(len(faces), -1)
    tri = vertices[faces]  # (f, 3, 3)
    points = (tri.transpose(2, 0, 1) @ _FACE_POINTS.T).reshape(3, -1)  # (3, f * 10); an einsum took 6 times longer
    out = []
    for j, spec in enumerate(specs):
        where = f"{fld}[{j}]"
        ck.obj(spec, where)
        kind = spec.get("type")
        if kind not in SHAPES:
            ck.fail(f"{where}.type", f"expected one of {', '.join(json.dumps(s) for s in SHAPES)}, got "
                                     f"{json.dumps(kind)}")
        schema, make = SHAPES[kind]
        listed = [f for f in schema.fields if f.kind == "list"]
        params = parse_block(ck, spec, where, SURFACE.fields + tuple(f for f in schema.fields if f.kind != "list"),
                             extra_keys={f.name for f in listed})
        for f in listed:
            params[f.name] = _terms(ck, spec.get(f.name, []), f"{where}.{f.name}")
        for f in schema.fields:
            if f.unit == "mm" and f.name.startswith("radius") and 0 < abs(params[f.name]) < 1 / MAX_CURVATURE:
                ck.fail(f"{where}.{f.name}", f"|radius| must be at least {1 / MAX_CURVATURE:g} mm (or 0 for flat), "
                                             f"got {params[f.name]:g}")
        to_local = np.linalg.inv(matrix @ _frame(ck, params, where))
        shape = make(params)
        dist = _distances(shape, kind, params, to_local, points).reshape(len(faces), len(_FACE_POINTS))
        corners = np.where(np.isfinite(dist[:, :3]), dist[:, :3], np.inf).max(axis=1)
        mine = np.flatnonzero((corners <= params["tolerance_mm"]) & (owner < 0))
        if len(mine) == 0:
            best = float(corners.min())
            near = f"the nearest face's corners lie {best:.3g} mm from it" if np.isfinite(best) else \
                "every face lies outside the shape's domain"
            ck.fail(where, f"no face of {mesh} lies on this {kind} ({near}; tolerance_mm {params['tolerance_mm']:g}): "
                           "check origin, axis and the shape's parameters against the mesh")
        gap = dist[mine]
        if not np.isfinite(gap).all():
            ck.fail(where, f"faces of {mesh} reach outside the {kind}'s domain (where its sag is undefined)")
        owner[mine] = j
        out.append(Surface(kind, shape, to_local, mine, gap.max(axis=1),
                           {k: v for k, v in params.items() if k != "type"}))
    return out
