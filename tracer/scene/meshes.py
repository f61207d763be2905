"""Mesh files of a scene: read with trimesh, checked (OBJ indices, finite coordinates, triangles), and
the closed outward surface a dielectric must be. Every error names the file and the field."""

from __future__ import annotations

import hashlib
import io
import json
import re
import warnings
from pathlib import Path

import numpy as np

from ..core.errors import SceneError
from ..core.kept import Kept
from ..core.validate import FieldChecker
from .format import MESH_SUFFIXES

#: An index 0 in an OBJ face (of a vertex, texture coordinate or normal): OBJ counts from 1 (and from -1
#: backward), so 0 refers to nothing; trimesh would take it as the last element.
_OBJ_ZERO_INDEX = re.compile(rb"(?m)^f[ \t][^\n]*?(?:(?<=[ \t])|/)0(?=[/ \t\r]|$)")


#: Meshes read so far, by their file's format and content (sha256), least recently used first: an F12
#: after F12 in Blender exports the same files into a new folder, and a sweep's runs and the eyebox's
#: worlds read them again; parsing is most of loading a scene (hud-direct: 0.2 of 0.3 s). A kept mesh is
#: parsed from the bytes that were hashed. Not kept: a .gltf (its buffers may lie in other files) and an
#: OBJ that names a material library (trimesh packs a multi-material OBJ's textures into an atlas and
#: moves its texture coordinates when the .mtl or its images change). At most 256 MiB of arrays.
_READ = Kept(256 << 20)


def _check_obj_indices(ck: FieldChecker, data: bytes, rel: str, fld: str):
    bad = _OBJ_ZERO_INDEX.search(data)
    if bad:
        line = data.count(b"\n", 0, bad.start()) + 1
        ck.fail(fld, f"cannot read mesh {rel}: line {line}: a face refers to element 0 (OBJ counts from 1)")


def _check_container(ck: FieldChecker, path: Path, rel: str, fld: str):
    """Say what is wrong with a mesh file that trimesh would report in its parsers' words: an empty file,
    a glTF binary whose header is not one or that ends before the length it declares, a .gltf that is
    not a JSON object (Khronos glTF 2.0, sec. 4.4: the GLB header is magic "glTF", version, length)."""
    size = path.stat().st_size
    if size == 0:
        ck.fail(fld, f"cannot read mesh {rel}: the file is empty (0 bytes)")
    suffix = path.suffix.lower()
    if suffix == ".glb":
        with open(path, "rb") as fh:
            head = fh.read(12)
        if len(head) < 12 or head[:4] != b"glTF":
            ck.fail(fld, f"cannot read mesh {rel}: not a glTF binary (it does not begin with the 12-byte header "
                         "'glTF', version, length)")
        declared = int.from_bytes(head[8:12], "little")
        if declared != size:
            ck.fail(fld, f"cannot read mesh {rel}: its header declares {declared:,} bytes but the file has {size:,} "
                         "(truncated or damaged)")
    elif suffix == ".gltf":
        try:
            data = json.loads(path.read_text(encoding="utf-8"))
        except UnicodeDecodeError:
            ck.fail(fld, f"cannot read mesh {rel}: not a text file (a .gltf is JSON; a binary glTF ends in .glb)")
        except json.JSONDecodeError as e:
            ck.fail(fld, f"cannot read mesh {rel}: not valid JSON ({e.msg}, line {e.lineno} column {e.colno})")
        if not isinstance(data, dict) or not isinstance(data.get("asset"), dict):
            ck.fail(fld, f"cannot read mesh {rel}: not a glTF document (a JSON object with an \"asset\" block)")
        for key in ("meshes", "accessors", "bufferViews", "buffers"):
            if key in data and not isinstance(data[key], list):
                ck.fail(fld, f"cannot read mesh {rel}: its \"{key}\" must be a list")


def load_mesh(ck: FieldChecker, root: Path, rel: str, fld: str):
    """(vertices (v,3), faces (f,3), uv (v,2) or None) from OBJ, PLY, STL, OFF or glTF through trimesh."""
    import trimesh

    path = ck.path(root, rel, fld)
    try:
        found = path.is_file()
    except OSError as e:
        ck.fail(fld, f"{rel}: cannot be read ({e.strerror or e})")
    if not found:
        ck.fail(fld, f"mesh file not found: {rel}")
    if path.suffix.lower() not in MESH_SUFFIXES:
        ck.fail(fld, f"{rel}: not a mesh format the tracer reads (a file name ending in "
                     f"{', '.join(MESH_SUFFIXES)})")
    suffix = path.suffix.lower()
    try:
        data = path.read_bytes()
    except OSError as e:
        ck.fail(fld, f"{rel}: cannot be read ({e.strerror or e})")
    kept = suffix != ".gltf" and not (suffix == ".obj" and re.search(rb"(?m)^[ \t]*mtllib\b", data))
    key = (suffix, hashlib.sha256(data).digest()) if kept else None
    entry = _READ.get(key) if key is not None else None
    if entry is not None:  # the same bytes were read and checked before
        return entry
    if suffix == ".obj":
        _check_obj_indices(ck, data, rel, fld)
    try:
        _check_container(ck, path, rel, fld)
    except OSError as e:
        ck.fail(fld, f"{rel}: cannot be read ({e.strerror or e})")
    try:
        with warnings.catch_warnings():
            # trimesh takes the median of a quad's texture coordinates it splits (nanmedian of an all-NaN
            # slice where a face has none): RuntimeWarnings about its own bookkeeping, not the mesh
            warnings.simplefilter("ignore", RuntimeWarning)
            if key is not None:  # the bytes that were hashed (the file may change meanwhile)
                loaded = trimesh.load(io.BytesIO(data), file_type=suffix[1:], process=False, maintain_order=True)
            else:
                loaded = trimesh.load(str(path), process=False, maintain_order=True)
        if isinstance(loaded, trimesh.Scene):
            meshes = list(loaded.dump()) if hasattr(loaded, "dump") else list(loaded.geometry.values())
            if not meshes:
                ck.fail(fld, f"{rel} contains no triangles")
            if len(meshes) > 1:
                loaded = trimesh.util.concatenate(meshes)
            else:
                loaded = meshes[0]
    except SceneError:
        raise
    except IndexError as e:  # trimesh indexing its vertices with a face's (0-based; an OBJ counts from 1)
        found = re.search(r"index (-?\d+) is out of bounds for axis 0 with size (\d+)", str(e))
        if found and int(found[1]) >= 0 and path.suffix.lower() == ".obj":
            index, size = int(found[1]) + 1, int(found[2])
            ck.fail(fld, f"cannot read mesh {rel}: a face refers to vertex {index}, but the file has {size} vertices")
        ck.fail(fld, f"cannot read mesh {rel}: a face refers to a vertex the file does not have ({e})")
    except Exception as e:  # trimesh raises many types on malformed files
        ck.fail(fld, f"cannot read mesh {rel}: {e}")
    v = np.asarray(getattr(loaded, "vertices", np.zeros((0, 3))), dtype=np.float64)
    f = np.asarray(getattr(loaded, "faces", np.zeros((0, 3))), dtype=np.int64)
    if len(v) == 0 or len(f) == 0:
        ck.fail(fld, f"{rel} contains no triangles")
    if v.ndim != 2 or v.shape[1] != 3:
        ck.fail(fld, f"{rel}: every vertex needs three coordinates (x y z), the file gives "
                     f"{v.shape[1] if v.ndim == 2 else 0}")
    if f.ndim != 2 or f.shape[1] != 3 or f.min() < 0 or f.max() >= len(v):
        ck.fail(fld, f"{rel}: its faces must be triangles of the file's {len(v)} vertices")
    if not np.all(np.isfinite(v)):
        ck.fail(fld, f"{rel} has non-finite vertex coordinates")
    uv = None
    visual = getattr(loaded, "visual", None)
    if visual is not None and getattr(visual, "kind", None) == "texture" and getattr(visual, "uv", None) is not None:
        uv_arr = np.asarray(visual.uv, dtype=np.float64)
        if uv_arr.shape == (len(v), 2):
            if not np.all(np.isfinite(uv_arr)):
                ck.fail(fld, f"{rel} has non-finite texture coordinates")
            uv = uv_arr
    if key is not None:
        _READ.put(key, (v, f, uv))
    return v, f, uv


def check_closed_outward(ck: FieldChecker, vw: np.ndarray, faces: np.ndarray, fld: str, rel: str):
    """A dielectric bounds a volume of glass: its mesh must be closed (every edge shared by exactly two
    triangles), consistently oriented (the two run their edge in opposite directions) and face outward
    (a positive enclosed volume), or refraction would enter glass where there is none. Vertices at the
    same position (to 1e-7 of the mesh's size) are merged first: exporters split them at seams."""
    size = max(float(np.ptp(vw, axis=0).max()), 1e-300)
    key = np.round(vw / (1e-7 * size)).astype(np.int64)
    _, merged = np.unique(key, axis=0, return_inverse=True)
    tri = merged.reshape(-1)[faces]
    tri = tri[(tri[:, 0] != tri[:, 1]) & (tri[:, 1] != tri[:, 2]) & (tri[:, 2] != tri[:, 0])]
    n = int(merged.max()) + 1
    a = np.concatenate([tri[:, 0], tri[:, 1], tri[:, 2]])
    b = np.concatenate([tri[:, 1], tri[:, 2], tri[:, 0]])
    _, undirected_count = np.unique(np.minimum(a, b) * n + np.maximum(a, b), return_counts=True)
    _, directed_count = np.unique(a * n + b, return_counts=True)
    what = "a dielectric must be a closed surface with outward normals (it bounds the glass)"
    if np.any(undirected_count == 1):
        ck.fail(fld, f"{rel}: {what}: {int(np.sum(undirected_count == 1))} edges belong to one triangle only "
                     "(the surface is open; model a thin sheet of glass as a box of its thickness)")
    if np.any(undirected_count > 2):
        ck.fail(fld, f"{rel}: {what}: {int(np.sum(undirected_count > 2))} edges belong to more than two triangles")
    if np.any(directed_count > 1):
        ck.fail(fld, f"{rel}: {what}: {int(np.sum(directed_count > 1))} edges are run the same way by both their "
                     "triangles (the faces are not consistently oriented)")
    v0, v1, v2 = (vw[faces[:, k]] for k in range(3))
    volume = float(np.einsum("ij,ij->", v0, np.cross(v1 - v0, v2 - v0))) / 6.0
    if volume <= 0:
        ck.fail(fld, f"{rel}: {what}: the normals point inward (enclosed volume {volume:.4g} mm^3); reverse the "
                     "faces' winding")
