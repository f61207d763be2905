"""Mesh files of a scene: read with trimesh, checked (OBJ indices, glTF containers and buffers, finite
coordinates, triangles), and the closed outward surface a dielectric must be. Every error names the file
and the field."""

from __future__ import annotations

import base64
import binascii
import hashlib
import io
import json
import os
import re
import struct
import warnings
from pathlib import Path, PurePosixPath

import numpy as np

from ..core.errors import SceneError, one_line, printable
from ..core.kept import Kept
from ..core.validate import FieldChecker
from .format import MESH_SUFFIXES

#: An index 0 in an OBJ face (of a vertex, texture coordinate or normal): OBJ counts from 1 (and from -1
#: backward), so 0 refers to nothing; trimesh would take it as the last element.
_OBJ_ZERO_INDEX = re.compile(rb"(?m)^f[ \t][^\n]*?(?:(?<=[ \t])|/)0(?=[/ \t\r]|$)")
#: An OBJ face of four corners or more (a quad, a polygon): its corners, up to a comment or the line's end.
_OBJ_POLYGON = re.compile(rb"(?m)^f[ \t]+([^\s#]+(?:[ \t]+[^\s#]+){3,})(?=[ \t]*(?:#|\r?$))")
#: A line of an OBJ's texture coordinates.
_OBJ_TEXTURE = re.compile(rb"(?m)^vt[ \t]")
#: A file named in a glTF's JSON (a buffer's or an image's "uri" that is not a data: URI).
_GLTF_FILE_URI = re.compile(rb'"uri"\s*:\s*"(?!data:)')

#: glTF 2.0 accessors (Khronos, sec. 3.6.2 and 5.1): bytes of one component of each componentType, and
#: components of each type (a matrix's columns unpadded, as trimesh reads them).
_GLTF_COMPONENT_BYTES = {5120: 1, 5121: 1, 5122: 2, 5123: 2, 5125: 4, 5126: 4}
_GLTF_TYPE_COMPONENTS = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT2": 4, "MAT3": 9, "MAT4": 16}


#: Meshes read so far, by their file's format and content (sha256), least recently used first: an F12
#: after F12 in Blender exports the same files into a new folder, and a sweep's runs and the eyebox's
#: worlds read them again; parsing is most of loading a scene (hud-direct: 0.2 of 0.3 s). A kept mesh is
#: parsed from the bytes that were hashed. Not kept: a mesh that reads other files, whose changes its own
#: bytes do not show: a .gltf or a GLB that names files (its buffers or images), and an OBJ that names a
#: material library (trimesh packs a multi-material OBJ's textures into an atlas and moves its texture
#: coordinates when the .mtl or its images change). At most 256 MiB of arrays.
_READ = Kept(256 << 20)


def _glb_json_end(data: bytes) -> int:
    """Where a GLB's JSON chunk ends: it begins at byte 20, after the 12-byte header and its own 8-byte
    chunk header, whose first 4 bytes give its length (Khronos glTF 2.0, sec. 4.4)."""
    return 20 + int.from_bytes(data[12:16], "little")


def _reads_other_files(suffix: str, data: bytes) -> bool:
    """Whether trimesh reads files beside the mesh file ``data`` (see :data:`_READ`)."""
    if suffix == ".gltf":
        return True
    if suffix == ".obj":
        return re.search(rb"(?m)^[ \t]*mtllib\b", data) is not None
    if suffix == ".glb" and len(data) >= 20:
        return _GLTF_FILE_URI.search(data, 20, _glb_json_end(data)) is not None
    return False


def _check_obj_indices(ck: FieldChecker, data: bytes, rel: str, fld: str):
    bad = _OBJ_ZERO_INDEX.search(data)
    if bad:
        line = data.count(b"\n", 0, bad.start()) + 1
        ck.fail(fld, f"cannot read mesh {rel}: line {line}: a face refers to element 0 (OBJ counts from 1)")


def _triangulated_obj(data: bytes) -> bytes:
    """The OBJ ``data`` with its faces of four corners or more written as triangles, split as trimesh
    splits them (a quad a b c d into a b c and c d a, a polygon into a fan from its first corner), where
    the file has texture coordinates. Why: keeping the file's vertices (maintain_order, see
    :func:`load_mesh`), trimesh looks each vertex's texture coordinate up in the first three corners of
    its faces only, and where all faces have the same number of corners it does so before splitting
    them: an OBJ of quads lost its texture coordinates (an LCD saved as one quad with vt lines was
    refused for having none). The corners are kept as written, and no line is added before a face;
    lines continued with a backslash are joined first, as trimesh joins them. A file without texture
    coordinates is left as it is: trimesh splits its faces alike."""
    if _OBJ_TEXTURE.search(data) is None or _OBJ_POLYGON.search(data) is None:
        return data
    data = data.replace(b"\\\r\n", b"").replace(b"\\\n", b"")

    def triangles(face: re.Match) -> bytes:
        c = face[1].split()
        tris = [(c[0], c[1], c[2]), (c[2], c[3], c[0])] if len(c) == 4 else \
            [(c[0], c[k], c[k + 1]) for k in range(1, len(c) - 1)]
        return b"\n".join(b"f " + b" ".join(t) for t in tris)

    return _OBJ_POLYGON.sub(triangles, data)


def _whole(ck: FieldChecker, block: dict, key: str, what: str, rel: str, fld: str, default=None,
           least: int = 0) -> int:
    """The whole number ``block[key]`` (at least ``least``) of a glTF's JSON, named ``what`` in a message."""
    value = block.get(key, default)
    if isinstance(value, bool) or not isinstance(value, int) or value < least:
        given = "missing" if key not in block else printable(json.dumps(value))[:40]
        ck.fail(fld, f"cannot read mesh {rel}: its {what} \"{key}\" must be a whole number, {least} or more (it is "
                     f"{given})")
    return value


def _glb_json(ck: FieldChecker, data: bytes, rel: str, fld: str) -> tuple[object, list[int]]:
    """The JSON of a glTF binary whose header was checked, and the lengths (bytes) of its binary chunks
    in the file's order (Khronos glTF 2.0, sec. 4.4: after the 12-byte header, chunks of a 4-byte length,
    a 4-byte type and the data; the first is "JSON", then "BIN\\0"). trimesh's words for each fault were
    "Expecting value: line 1 column 1", "Extra data" and "chunk was not expected length!"."""
    size = len(data)
    if size < 20:
        ck.fail(fld, f"cannot read mesh {rel}: the file ends after its header ({size} bytes): a GLB holds a "
                     "JSON chunk next")
    length, kind = struct.unpack_from("<I4s", data, 12)
    if kind != b"JSON":
        ck.fail(fld, f"cannot read mesh {rel}: its first chunk is of type '{printable(kind.decode('latin-1'))}', "
                     "not JSON (a GLB's first chunk is its JSON; damaged)")
    if 20 + length > size:
        ck.fail(fld, f"cannot read mesh {rel}: its JSON chunk declares {length:,} bytes, more than the "
                     f"{size - 20:,} the file holds after it (its length field is damaged)")
    try:
        tree = json.loads(data[20:20 + length].decode("utf-8", errors="replace"))
    except json.JSONDecodeError as e:
        if e.msg == "Extra data":
            ck.fail(fld, f"cannot read mesh {rel}: its JSON chunk declares {length:,} bytes but its JSON ends after "
                         f"{e.pos:,} bytes (its length field is damaged)")
        ck.fail(fld, f"cannot read mesh {rel}: its JSON chunk is not valid JSON ({e.msg.removesuffix(' at')} at byte "
                     f"{e.pos:,} of the chunk; damaged)")
    chunks, at = [], 20 + length
    while at < size:
        if at + 8 > size:
            ck.fail(fld, f"cannot read mesh {rel}: the file ends {size - at} bytes into the header of a chunk at "
                         f"byte {at:,} (truncated or damaged)")
        length, kind = struct.unpack_from("<I4s", data, at)
        if kind != b"BIN\0":
            ck.fail(fld, f"cannot read mesh {rel}: its chunk at byte {at:,} is of type "
                         f"'{printable(kind.decode('latin-1'))}', not a binary chunk (\"BIN\"): damaged, or a kind "
                         "the tracer does not read")
        if at + 8 + length > size:
            ck.fail(fld, f"cannot read mesh {rel}: its binary chunk declares {length:,} bytes but the file holds "
                         f"{size - at - 8:,} after the chunk's header (truncated, or its length field is damaged)")
        chunks.append(length)
        at += 8 + length
    return tree, chunks


def _gltf_buffers(ck: FieldChecker, tree: dict, path: Path, rel: str, fld: str,
                  chunks: list[int] | None) -> list[tuple[int, str]]:
    """(bytes it holds, its name in a message) of each buffer of the glTF ``tree`` (file ``path``, ``rel``
    to the scene): a file it names, found as trimesh finds it (beside the glTF, then without a leading
    "/", then by its base name), a base64 data: URI, or, in a GLB (``chunks``: its binary chunks' lengths),
    the next binary chunk."""
    buffers, left = [], list(chunks or [])
    for i, b in enumerate(tree.get("buffers", [])):
        if not isinstance(b, dict):
            ck.fail(fld, f"cannot read mesh {rel}: its buffer {i} must be a JSON object")
        uri = b.get("uri")
        if chunks is not None and "uri" not in b:
            if not left:
                ck.fail(fld, f"cannot read mesh {rel}: its buffer {i} lies in the file's binary chunk, but the file "
                             "has no binary chunk (left)")
            buffers.append((left.pop(0), "binary chunk"))
            continue
        if not isinstance(uri, str):
            ck.fail(fld, f"cannot read mesh {rel}: its buffer {i} names no file (\"uri\"): a .gltf keeps its data "
                         "in the files it names (or in data: URIs)")
        start = uri.find("base64,")
        if start >= 0:  # trimesh decodes whatever follows "base64,"
            try:
                buffers.append((len(base64.b64decode(uri[start + 7:])), f"buffer {i} (a data: URI)"))
            except (binascii.Error, ValueError):
                ck.fail(fld, f"cannot read mesh {rel}: its buffer {i} is a data: URI whose base64 is damaged")
            continue
        if uri.startswith("data:"):
            ck.fail(fld, f"cannot read mesh {rel}: its buffer {i} is a data: URI but not base64 (\"data:...;base64,\" "
                         "is what glTF writes)")
        shown = printable(str(PurePosixPath(rel).parent / uri.strip()))
        folder = str(path.parent)
        found = next((p for p in (os.path.join(folder, uri.strip()), os.path.join(folder, uri.strip().lstrip("/")),
                                  os.path.join(folder, os.path.split(uri)[-1])) if os.path.exists(p)), None)
        if found is None:
            ck.fail(fld, f"cannot read mesh {rel}: {shown}, the buffer it names, does not exist")
        if not os.path.isfile(found):
            ck.fail(fld, f"cannot read mesh {rel}: {shown}, the buffer it names, is not a file")
        buffers.append((os.path.getsize(found), f"binary buffer {shown}"))
    return buffers


def _check_gltf_layout(ck: FieldChecker, tree: dict, buffers: list[tuple[int, str]], rel: str, fld: str):
    """Every bufferView within its buffer and every accessor within its bufferView (Khronos glTF 2.0,
    sec. 3.6: a view is byteLength bytes from byteOffset of its buffer; an accessor reads count elements
    from byteOffset of its view, byteStride apart where the view gives one). trimesh's words were an
    empty AssertionError for a short buffer and "cannot reshape array of size 105600 into shape
    (999999,1)" for a count too large."""
    views = tree.get("bufferViews", [])
    spans = []
    need = [0] * len(buffers)
    for i, view in enumerate(views):
        if not isinstance(view, dict):
            ck.fail(fld, f"cannot read mesh {rel}: its bufferView {i} must be a JSON object")
        b = _whole(ck, view, "buffer", f"bufferView {i}'s", rel, fld)
        if b >= len(buffers):
            ck.fail(fld, f"cannot read mesh {rel}: its bufferView {i} reads buffer {b}, but the file has "
                         f"{len(buffers)} buffers")
        offset = _whole(ck, view, "byteOffset", f"bufferView {i}'s", rel, fld, default=0)
        length = _whole(ck, view, "byteLength", f"bufferView {i}'s", rel, fld, least=1)
        stride = _whole(ck, view, "byteStride", f"bufferView {i}'s", rel, fld, least=1) \
            if "byteStride" in view else None
        spans.append((length, stride))
        need[b] = max(need[b], offset + length)
    for (size, name), n in zip(buffers, need, strict=True):
        if size < n:
            ck.fail(fld, f"cannot read mesh {rel}: its {name} is {size:,} bytes, shorter than the {n:,} its "
                         "bufferViews read from it (truncated, or not the one written with it)")
    for i, a in enumerate(tree.get("accessors", [])):
        if not isinstance(a, dict):
            ck.fail(fld, f"cannot read mesh {rel}: its accessor {i} must be a JSON object")
        count = _whole(ck, a, "count", f"accessor {i}'s", rel, fld, least=1)
        component, kind = a.get("componentType"), a.get("type")
        if isinstance(component, bool) or not isinstance(component, int) or component not in _GLTF_COMPONENT_BYTES:
            ck.fail(fld, f"cannot read mesh {rel}: its accessor {i} has componentType "
                         f"{printable(json.dumps(component))[:40]}; glTF's are "
                         f"{', '.join(map(str, _GLTF_COMPONENT_BYTES))}")
        if not isinstance(kind, str) or kind not in _GLTF_TYPE_COMPONENTS:
            ck.fail(fld, f"cannot read mesh {rel}: its accessor {i} has type {printable(json.dumps(kind))[:40]}; "
                         f"glTF's are {', '.join(_GLTF_TYPE_COMPONENTS)}")
        if "bufferView" not in a:  # all zeros (a sparse accessor's base)
            continue
        v = _whole(ck, a, "bufferView", f"accessor {i}'s", rel, fld)
        if v >= len(spans):
            ck.fail(fld, f"cannot read mesh {rel}: its accessor {i} reads bufferView {v}, but the file has "
                         f"{len(spans)} bufferViews")
        offset = _whole(ck, a, "byteOffset", f"accessor {i}'s", rel, fld, default=0)
        element = _GLTF_COMPONENT_BYTES[component] * _GLTF_TYPE_COMPONENTS[kind]
        length, stride = spans[v]
        end = offset + (count - 1) * stride + element if stride else offset + count * element
        if end > length:
            ck.fail(fld, f"cannot read mesh {rel}: its accessor {i} reads {count:,} {kind} values ({end:,} bytes, "
                         f"with its offset) from bufferView {v}, which holds {length:,} bytes (its count or offset "
                         "is wrong, or the file is damaged)")
    accessors = len(tree.get("accessors", []))
    for m, mesh in enumerate(tree.get("meshes", [])):
        primitives = mesh.get("primitives") if isinstance(mesh, dict) else None
        if not isinstance(primitives, list) or not all(isinstance(p, dict) for p in primitives):
            ck.fail(fld, f"cannot read mesh {rel}: its mesh {m} must hold a list of primitives (JSON objects)")
        for p in primitives:
            attributes = p.get("attributes")
            if not isinstance(attributes, dict) or "POSITION" not in attributes:
                ck.fail(fld, f"cannot read mesh {rel}: its mesh {m} has a primitive without \"attributes\" that give "
                             "its vertices' POSITION")
            for name, ref in ([("indices", p["indices"])] if "indices" in p else []) + list(attributes.items()):
                if isinstance(ref, bool) or not isinstance(ref, int) or not 0 <= ref < accessors:
                    ck.fail(fld, f"cannot read mesh {rel}: its mesh {m}'s {printable(name)[:40]} names accessor "
                                 f"{printable(json.dumps(ref))[:40]}, but the file has {accessors} accessors")
                want = {"indices": "SCALAR", "POSITION": "VEC3"}.get(name)
                if want is not None and tree["accessors"][ref]["type"] != want:
                    ck.fail(fld, f"cannot read mesh {rel}: its mesh {m}'s {name} names accessor {ref}, of "
                                 f"{tree['accessors'][ref]['type']} values, not {want}")


def _check_container(ck: FieldChecker, path: Path, data: bytes, rel: str, fld: str):
    """Say what is wrong with a mesh file ``data`` that trimesh would report in its parsers' words: an
    empty file, a glTF binary whose header is not one or that ends before the length it declares, whose
    chunks or JSON are damaged, a .gltf that is not a JSON object (Khronos glTF 2.0, sec. 4.4: the GLB
    header is magic "glTF", version, length), and a glTF's buffers missing or shorter than its
    bufferViews and accessors read."""
    size = len(data)
    if size == 0:
        ck.fail(fld, f"cannot read mesh {rel}: the file is empty (0 bytes)")
    suffix = path.suffix.lower()
    chunks = None
    if suffix == ".glb":
        head = data[:12]
        if len(head) < 12 or head[:4] != b"glTF":
            ck.fail(fld, f"cannot read mesh {rel}: not a glTF binary (it does not begin with the 12-byte header "
                         "'glTF', version, length)")
        version, declared = int.from_bytes(head[4:8], "little"), int.from_bytes(head[8:12], "little")
        if version != 2:
            ck.fail(fld, f"cannot read mesh {rel}: its header gives glTF version {version:,}; the tracer reads "
                         "glTF 2.0 (re-export it as glTF 2.0)")
        if declared != size:
            ck.fail(fld, f"cannot read mesh {rel}: its header declares {declared:,} bytes but the file has {size:,} "
                         "(truncated or damaged)")
        tree, chunks = _glb_json(ck, data, rel, fld)
    elif suffix == ".gltf":
        try:
            tree = json.loads(data.decode("utf-8"))
        except UnicodeDecodeError:
            ck.fail(fld, f"cannot read mesh {rel}: not a text file (a .gltf is JSON; a binary glTF ends in .glb)")
        except json.JSONDecodeError as e:
            ck.fail(fld, f"cannot read mesh {rel}: not valid JSON ({e.msg}, line {e.lineno} column {e.colno})")
    else:
        return
    if not isinstance(tree, dict) or not isinstance(tree.get("asset"), dict):
        ck.fail(fld, f"cannot read mesh {rel}: not a glTF document (a JSON object with an \"asset\" block)")
    version = tree["asset"].get("version", "2.0")  # required by the format, but trimesh takes none for 2.0
    if not re.fullmatch(r"2(\.\d+)?", str(version)):
        ck.fail(fld, f"cannot read mesh {rel}: its asset.version is {printable(json.dumps(version))[:40]}; the tracer "
                     "reads glTF 2.0 (re-export it as glTF 2.0)")
    for key in ("meshes", "accessors", "bufferViews", "buffers"):
        if key in tree and not isinstance(tree[key], list):
            ck.fail(fld, f"cannot read mesh {rel}: its \"{key}\" must be a list")
    _check_gltf_layout(ck, tree, _gltf_buffers(ck, tree, path, rel, fld, chunks), rel, fld)


def _unreadable(ck: FieldChecker, rel: str, fld: str, suffix: str, e: Exception):
    """Refuse a mesh file that trimesh could not read for a fault the checks above do not name, in words
    around its own: they may be about its code ("'int' object has no attribute 'get'"), be only a key
    (a glTF's missing field) or be empty (an assertion)."""
    if isinstance(e, KeyError) and e.args and isinstance(e.args[0], str) and suffix in (".gltf", ".glb"):
        ck.fail(fld, f"cannot read mesh {rel}: it lacks a field glTF requires "
                     f"({printable(json.dumps(e.args[0]))[:40]})")
    if isinstance(e, KeyError):
        reason = f"no entry {printable(e)[:40]}"
    else:
        reason = one_line(printable(e)) or f"{type(e).__name__}, without a reason"
    ck.fail(fld, f"cannot read mesh {rel}: it is damaged or not a valid {suffix[1:].upper()} file (the reader "
                 f"stopped at: {reason})")


def load_mesh(ck: FieldChecker, root: Path, rel: str, fld: str):
    """(vertices (v,3), faces (f,3), uv (v,2) or None) from OBJ, PLY, STL, OFF or glTF through trimesh.

    An OBJ is read with trimesh's maintain_order: a vertex is a ``v`` line, in the file's order, shared by
    every face that names it, as smooth_normals (an average over the faces that share a vertex) and the
    Blender add-on (which rebuilds the mesh it imports from these vertices) need. trimesh's default splits
    a vertex wherever its faces' corners name different texture coordinates or normals: a flat-shaded
    export, which writes a normal per face, would come apart into loose triangles. In exchange a vertex
    has one texture coordinate, taken from its faces' corners (their median where they differ), and a
    quad's or polygon's are read only once it is split into triangles (:func:`_triangulated_obj`)."""
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
    kept = not _reads_other_files(suffix, data)
    key = (suffix, hashlib.sha256(data).digest()) if kept else None
    entry = _READ.get(key) if key is not None else None
    if entry is not None:  # the same bytes were read and checked before
        return entry
    if suffix == ".obj":
        _check_obj_indices(ck, data, rel, fld)
    try:
        _check_container(ck, path, data, rel, fld)
    except OSError as e:
        ck.fail(fld, f"{rel}: cannot be read ({e.strerror or e})")
    try:
        # the bytes that were checked (and hashed: the file may change meanwhile); the files a mesh names
        # (a glTF's buffers, an OBJ's material library) found beside it, as trimesh finds them for a path
        source = _triangulated_obj(data) if suffix == ".obj" else data
        resolver = trimesh.resolvers.FilePathResolver(str(path)) if key is None else None
        with warnings.catch_warnings():
            # trimesh takes the median of a vertex's texture coordinates over its faces' corners (nanmedian
            # of an all-NaN slice for a vertex no face names): RuntimeWarnings about its own bookkeeping
            warnings.simplefilter("ignore", RuntimeWarning)
            loaded = trimesh.load(io.BytesIO(source), file_type=suffix[1:], resolver=resolver, process=False,
                                  maintain_order=True)
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
        if found and int(found[1]) >= 0 and suffix == ".obj":
            index, size = int(found[1]) + 1, int(found[2])
            ck.fail(fld, f"cannot read mesh {rel}: a face refers to vertex {index}, but the file has {size} vertices")
        if suffix not in (".gltf", ".glb"):  # a glTF's faces are checked below; this is its structure
            ck.fail(fld, f"cannot read mesh {rel}: a face refers to a vertex the file does not have ({e})")
        _unreadable(ck, rel, fld, suffix, e)
    except Exception as e:  # trimesh raises many types on malformed files
        _unreadable(ck, rel, fld, suffix, e)
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


#: An OBJ's material libraries (``mtllib`` lines, names separated by blanks).
_OBJ_MTLLIB = re.compile(rb"(?m)^[ \t]*mtllib[ \t]+([^\r\n#]+)")


def files_beside(ck: FieldChecker, root: Path, rel: str, fld: str) -> list[str]:
    """The files mesh ``rel`` (read and checked by :func:`load_mesh`) reads beside itself, relative to the
    scene folder ``root``: a glTF's buffers and images named by "uri" (data: URIs aside), an OBJ's
    material libraries. Each must lie inside the scene folder unless external files are allowed
    (:meth:`FieldChecker.path`): the folder is what is copied, zipped for a cluster and hashed, and a
    buffer outside it was read all the same. Those that exist are returned, for the scene's hash (a
    changed .bin is another scene; its .gltf alone did not show it)."""
    from urllib.parse import unquote

    path = Path(root) / rel
    suffix = path.suffix.lower()
    if suffix not in (".obj", ".gltf", ".glb"):
        return []
    try:
        data = path.read_bytes()
    except OSError as e:
        ck.fail(fld, f"{rel}: cannot be read ({e.strerror or e})")
    if not _reads_other_files(suffix, data):
        return []
    if suffix == ".obj":
        names = [n.decode("utf-8", "replace") for m in _OBJ_MTLLIB.finditer(data) for n in m[1].split()]
    else:
        text = data if suffix == ".gltf" else data[20:_glb_json_end(data)]
        tree = json.loads(text.decode("utf-8", errors="replace"))  # valid: load_mesh checked it
        names = [unquote(b["uri"]) for key in ("buffers", "images") for b in tree.get(key, [])
                 if isinstance(b, dict) and isinstance(b.get("uri"), str) and not b["uri"].startswith("data:")]
    out = []
    for name in names:
        beside = str(PurePosixPath(rel).parent / name.strip().lstrip("/"))
        if ck.path(root, beside, fld).is_file():
            out.append(beside)
    return out


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
