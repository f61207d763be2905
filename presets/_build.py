"""Small geometry and scene-writing helpers shared by the presets (no large binaries are committed:
every preset writes its meshes and textures from code)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np


def rectangle(width: float, height: float, nx: int = 1, ny: int = 1):
    """A rectangle in the local xy plane, centred, normal +z: (vertices (v, 3), faces (f, 3), uv (v, 2))."""
    u, v = np.meshgrid(np.linspace(0, 1, nx + 1), np.linspace(0, 1, ny + 1), indexing="xy")
    verts = np.stack([(u - 0.5) * width, (v - 0.5) * height, np.zeros_like(u)], axis=-1).reshape(-1, 3)
    uv = np.stack([u, v], axis=-1).reshape(-1, 2)
    idx = np.arange((nx + 1) * (ny + 1)).reshape(ny + 1, nx + 1)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel(), idx[1:, 1:].ravel(), idx[1:, :-1].ravel()
    faces = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])
    return verts, faces, uv


def disk(radius: float, segments: int = 128):
    """A disk in the local xy plane, centred, normal +z: (vertices, faces)."""
    ang = np.linspace(0, 2 * np.pi, segments, endpoint=False)
    verts = np.concatenate([[[0.0, 0.0, 0.0]], np.stack([radius * np.cos(ang), radius * np.sin(ang),
                                                         np.zeros(segments)], 1)])
    k = np.arange(segments)
    faces = np.stack([np.zeros(segments, int), 1 + k, 1 + (k + 1) % segments], 1)
    return verts, faces


def annulus(r_inner: float, r_outer: float, segments: int = 128):
    """A flat ring in the local xy plane, centred, normal +z: (vertices, faces)."""
    ang = np.linspace(0, 2 * np.pi, segments, endpoint=False)
    ring = lambda r: np.stack([r * np.cos(ang), r * np.sin(ang), np.zeros(segments)], 1)  # noqa: E731
    verts = np.concatenate([ring(r_inner), ring(r_outer)])
    k = np.arange(segments)
    a, b, c, d = k, (k + 1) % segments, segments + (k + 1) % segments, segments + k
    return verts, np.concatenate([np.stack([a, d, c], 1), np.stack([a, c, b], 1)])


def box(size_x: float, size_y: float, size_z: float):
    """A closed box centred at the origin with outward normals: (vertices, faces)."""
    import trimesh

    m = trimesh.creation.box(extents=[size_x, size_y, size_z])
    return np.asarray(m.vertices), np.asarray(m.faces)


def sphere(radius: float, subdivisions: int = 4, inward: bool = False):
    import trimesh

    m = trimesh.creation.icosphere(subdivisions=subdivisions, radius=radius)
    f = np.asarray(m.faces)
    return np.asarray(m.vertices), (f[:, ::-1] if inward else f)


def frame_bars(sb, name: str, inner: tuple[float, float], bar: float, frame: list):
    """Four absorbing bars, ``bar`` mm wide, framing an inner rectangle (w, h) mm in the plane of
    ``frame`` (so that no light passes beside an LCD or a screen): objects "<name>_0" to "<name>_3"."""
    w, h = inner
    for i, (cx, cy, sx, sy) in enumerate([(0, (h + bar) / 2, w + 2 * bar, bar), (0, -(h + bar) / 2, w + 2 * bar, bar),
                                          ((w + bar) / 2, 0, bar, h), (-(w + bar) / 2, 0, bar, h)]):
        bv, bf, _ = rectangle(sx, sy)
        sb.add(f"{name}_{i}", (bv + [cx, cy, 0.0], bf), {"type": "absorber"}, frame)


def _sag(radius: float, rho: np.ndarray) -> np.ndarray:
    """Sag (mm) of a spherical surface of radius ``radius`` (0: flat) at heights ``rho`` from its axis."""
    if radius == 0:
        return np.zeros_like(rho)
    return radius - np.sign(radius) * np.sqrt(radius * radius - rho * rho)


def lens(r_front: float, r_back: float, thickness: float, semi_diameter: float, rings: int = 48,
         segments: int = 128):
    """A closed thick lens with outward normals, axis along local z, centred between its apexes:
    (vertices, faces). The front surface faces +z with its apex at z = thickness / 2; ``r_front`` > 0
    is convex there, ``r_back`` > 0 convex on the -z side, 0 flat (a plano-convex lens has one 0). The
    two caps and the cylindrical edge have their own vertices, so smooth normals stay those of each
    surface (the loader merges coincident vertices when it checks that the glass is closed)."""
    rho = semi_diameter * np.arange(1, rings + 1) / rings
    ang = np.linspace(0, 2 * np.pi, segments, endpoint=False)
    cos, sin = np.cos(ang), np.sin(ang)
    z_front = 0.5 * thickness - _sag(r_front, rho)
    z_back = -0.5 * thickness + _sag(r_back, rho)
    if z_front[-1] - z_back[-1] <= 0:
        raise ValueError("the lens's edge thickness is not positive: make it thicker")

    def cap(z_apex, z_rings, up: bool):
        verts = [[0.0, 0.0, z_apex]]
        for r, z in zip(rho, z_rings, strict=True):
            verts += np.stack([r * cos, r * sin, np.full(segments, z)], 1).tolist()
        k = np.arange(segments)
        faces = [np.stack([np.zeros(segments, int), 1 + k, 1 + (k + 1) % segments], 1)]
        for i in range(rings - 1):
            a = 1 + i * segments + k
            b = 1 + i * segments + (k + 1) % segments
            c, d = a + segments, b + segments
            faces += [np.stack([a, c, d], 1), np.stack([a, d, b], 1)]
        f = np.concatenate(faces)
        return np.array(verts), (f if up else f[:, ::-1])

    vf, ff = cap(0.5 * thickness, z_front, True)
    vb, fb = cap(-0.5 * thickness, z_back, False)
    r = semi_diameter
    edge_v = np.concatenate([np.stack([r * cos, r * sin, np.full(segments, z_front[-1])], 1),
                             np.stack([r * cos, r * sin, np.full(segments, z_back[-1])], 1)])
    k = np.arange(segments)
    top, bottom = k, segments + k
    top2, bottom2 = (k + 1) % segments, segments + (k + 1) % segments
    edge_f = np.concatenate([np.stack([top, bottom, bottom2], 1), np.stack([top, bottom2, top2], 1)])
    verts = np.concatenate([vf, vb, edge_v])
    faces = np.concatenate([ff, fb + len(vf), edge_f + len(vf) + len(vb)])
    return verts, faces


def lens_focal_length(r_front: float, r_back: float, thickness: float, ior: float) -> float:
    """Effective focal length (mm) of a thick lens in air (lensmaker's equation; Hecht, Optics, eq. 6.2),
    radii signed as in :func:`lens` (convex > 0 on either side, 0 flat)."""
    c1 = 1.0 / r_front if r_front else 0.0
    c2 = -1.0 / r_back if r_back else 0.0
    power = (ior - 1) * (c1 - c2 + (ior - 1) * thickness * c1 * c2 / ior)
    return 1.0 / power


def frame_matrix(origin, x_axis, normal) -> list[list[float]]:
    """4 x 4 matrix placing local (x, y, z) at ``origin`` with local x along ``x_axis`` and local z
    along ``normal`` (y completes a right-handed frame)."""
    z = np.asarray(normal, float)
    z /= np.linalg.norm(z)
    x = np.asarray(x_axis, float)
    x = x - (x @ z) * z
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    m = np.eye(4)
    m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = x, y, z, origin
    return m.tolist()


def write_obj(path: Path, vertices: np.ndarray, faces: np.ndarray, uv: np.ndarray | None = None):
    """Write a triangle mesh as Wavefront OBJ (with per-vertex texture coordinates if given)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    # Python numbers (tolist) format three times as fast as numpy scalars, to the same text: Blender
    # writes every mesh so on each F12 (hud_addon/export_files.py)
    lines = [f"v {x:.9g} {y:.9g} {z:.9g}" for x, y, z in np.asarray(vertices).tolist()]
    one_based = (np.asarray(faces) + 1).tolist()
    if uv is not None:
        lines += [f"vt {s:.9g} {t:.9g}" for s, t in np.asarray(uv).tolist()]
        lines += [f"f {a}/{a} {b}/{b} {c}/{c}" for a, b, c in one_based]
    else:
        lines += [f"f {a} {b} {c}" for a, b, c in one_based]
    path.write_text("\n".join(lines) + "\n")


class SceneBuilder:
    """Collects objects and writes a scene folder (scene.json, meshes/, textures/)."""

    def __init__(self, folder: Path, name: str, description: str):
        self.folder = Path(folder)
        self.folder.mkdir(parents=True, exist_ok=True)
        self.data = {"format": "hud-scene", "version": 1, "name": name, "description": description,
                     "environment": {"type": "none"}, "objects": []}

    def add(self, name: str, mesh, material: dict, transform: list | None = None, smooth: bool = False,
            uv: np.ndarray | None = None, emission: dict | None = None, surfaces: list[dict] | None = None):
        """Add an object: its mesh (vertices, faces), material block, 4 x 4 transform, the emission block
        of an object that emits (tracer.sources.lights.EMISSION) and its exact surfaces
        (tracer.scene.format.SURFACE blocks)."""
        vertices, faces = mesh[0], mesh[1]
        rel = f"meshes/{name}.obj"
        write_obj(self.folder / rel, np.asarray(vertices), np.asarray(faces), uv)
        obj = {"name": name, "mesh": rel, "material": material}
        if emission is not None:
            obj["emission"] = emission
        if transform is not None:
            obj["transform"] = {"matrix": transform}
        if smooth:
            obj["smooth_normals"] = True
        if surfaces:
            obj["surfaces"] = surfaces
        self.data["objects"].append(obj)

    def add_windshield(self, name: str, windshield: dict, material: dict, transform: list):
        """Add a windshield made from its parameters (tracer.scene.windshield.WINDSHIELD) in place of a mesh."""
        self.data["objects"].append({"name": name, "material": material, "transform": {"matrix": transform},
                                     "windshield": windshield})

    def write(self, **blocks):
        self.data.update(blocks)
        (self.folder / "scene.json").write_text(json.dumps(self.data, indent=2) + "\n")
        return self.folder
