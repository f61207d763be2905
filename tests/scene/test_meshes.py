"""Mesh files of a scene (tracer/scene/meshes.py): every format the scene format names loads and renders
the same closed form; malformed files, OBJ indices of 0, non-finite texture coordinates, a suffix the tracer
does not read and open or inward-facing dielectrics are refused before the first ray in one line that names
scene.json, the field and the mesh file."""

import json
from pathlib import Path

import numpy as np
import pytest

from tests.support.cli import assert_one_line_error, hashes, run_cli
from tests.support.render import render
from tests.support.scenes import edit_json, set_field
from tracer.scene import MESH_SUFFIXES, load_scene


@pytest.mark.parametrize("ext", [s.removeprefix(".") for s in MESH_SUFFIXES if s != ".obj"])
def test_meshes_load_from_every_format_the_scene_format_names(preset, ext):
    """The mirror of analytic-mirror, re-saved as PLY, STL, OFF, GLB or glTF (tracer.scene.MESH_SUFFIXES
    but OBJ, the presets' own), renders the same closed-form value."""
    import trimesh

    from tracer.scene import load_scene

    folder = preset("analytic-mirror", resolution=(8, 6))
    src = load_scene(folder).object("mirror")
    m = json.loads((folder / "scene.json").read_text())
    world = trimesh.Trimesh(src.vertices, src.faces, process=False)
    world.export(folder / f"meshes/mirror.{ext}")
    m["objects"][0]["mesh"] = f"meshes/mirror.{ext}"
    m["objects"][0].pop("transform")
    (folder / "scene.json").write_text(json.dumps(m))
    loaded = load_scene(folder).object("mirror")
    np.testing.assert_allclose(np.sort(loaded.triangles.reshape(-1, 3), axis=0),
                               np.sort(src.triangles.reshape(-1, 3), axis=0), atol=1e-4)
    y, var, _ = render(folder, "backward", 300_000)
    assert y.max() == pytest.approx(850.0, rel=0.01)


_PLY_HEADER = ("ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
               "element face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n")
#: Mesh files that trimesh reads without complaint (a PLY face beyond its vertices, vertices of two
#: coordinates) or with an exception of its own (an OBJ face beyond its vertices): file, text, words.
BAD_MESHES = {
    "OBJ vertices of two coordinates": ("mirror.obj", "v 0 0\nv 1 0\nv 0 1\nf 1 2 3\n", "three coordinates"),
    "OBJ face beyond the vertices": ("mirror.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 7\n",
                                     "a face refers to vertex 7, but the file has 3 vertices"),
    "PLY face beyond the vertices": ("bad.ply", _PLY_HEADER + "3 0 1 5\n", "triangles of the file's 3 vertices"),
}


@pytest.mark.parametrize("case", sorted(BAD_MESHES))
def test_malformed_mesh_files_give_one_line_naming_file_and_field(mirror, earlier, case):
    """A mesh file that parses but does not hold triangles of three-coordinate vertices is refused
    before the first ray: exit 2, one line naming scene.json, the field and the mesh file, the earlier
    outputs untouched (before, a traceback from deep in the loader)."""
    out, before = earlier
    name, text, words = BAD_MESHES[case]
    (mirror / "meshes" / name).write_text(text)
    edit_json(mirror, lambda d: d["objects"][0].update(mesh=f"meshes/{name}"))
    code, err = run_cli("render", mirror, "--rays", 10**12, "--workers", 1, "--quiet", "--out", out)
    assert_one_line_error(code, err, "scene.json", "objects[0].mesh", f"meshes/{name}", words)
    assert hashes(out) == before


#: Files that trimesh reported in its parsers' words ("index 0 is out of bounds", "Unterminated string",
#: "'int' object has no attribute 'get'"): file, bytes, words.
BAD_CONTAINERS = {
    "an empty GLB": ("m.glb", b"", "the file is empty"),
    "a truncated GLB": ("m.glb", b"glTF" + (2).to_bytes(4, "little") + (4096).to_bytes(4, "little") + b"abcd",
                        "declares 4,096 bytes but the file has 16"),
    "not a GLB": ("m.glb", b"solid x\nendsolid x\n" * 2, "not a glTF binary"),
    "a glTF that is not JSON": ("m.gltf", b'{"asset": {"version": "2.0"}, "meshes": [', "not valid JSON"),
    "a glTF of the wrong shape": ("m.gltf", b'{"asset": {"version": "2.0"}, "meshes": 5}', '"meshes" must be a list'),
    "a glTF without its asset": ("m.gltf", b"[1, 2]", "not a glTF document"),
}


@pytest.mark.parametrize("case", sorted(BAD_CONTAINERS))
def test_broken_gltf_files_say_what_is_wrong_with_them(mirror, earlier, case):
    out, before = earlier
    name, data, words = BAD_CONTAINERS[case]
    (mirror / "meshes" / name).write_bytes(data)
    edit_json(mirror, lambda d: d["objects"][0].update(mesh=f"meshes/{name}"))
    code, err = run_cli("render", mirror, "--rays", 10**12, "--workers", 1, "--quiet", "--out", out)
    assert_one_line_error(code, err, "scene.json", "objects[0].mesh", f"meshes/{name}", words)
    assert hashes(out) == before


def _box_gltf(folder: Path, edit_tree=None, edit_bin=None) -> int:
    """A 100 x 100 x 10 mm box (trimesh's export) as meshes/model.gltf and its buffer meshes/model.bin,
    each spoiled by its ``edit_``, used by the scene's mirror; returns the buffer's length as exported."""
    import trimesh

    files = trimesh.creation.box(extents=[100, 100, 10]).export(file_type="gltf", merge_buffers=True)
    tree = json.loads(files["model.gltf"])
    data = files[tree["buffers"][0]["uri"]]
    tree["buffers"][0]["uri"] = "model.bin"
    if edit_tree:
        edit_tree(tree)
    (folder / "meshes" / "model.gltf").write_text(json.dumps(tree))
    (folder / "meshes" / "model.bin").write_bytes(edit_bin(data) if edit_bin else data)
    edit_json(folder, lambda d: d["objects"][0].update(mesh="meshes/model.gltf"))
    return len(data)


def _box_glb() -> tuple[bytes, int, int]:
    """The box of :func:`_box_gltf` as a GLB (a 12-byte header, a JSON chunk and a BIN chunk, each of a
    4-byte length, a 4-byte type and its data): (bytes, the JSON chunk's length, the BIN chunk's)."""
    import trimesh

    data = trimesh.creation.box(extents=[100, 100, 10]).export(file_type="glb")
    json_length = int.from_bytes(data[12:16], "little")
    return data, json_length, int.from_bytes(data[20 + json_length:24 + json_length], "little")


def _uint32(n: int) -> bytes:
    return n.to_bytes(4, "little")


def _gltf_case(words: str, edit_tree=None, edit_bin=None, remove_bin=False):
    """Build a .gltf case of :data:`BROKEN_GLTF` (``words`` formatted with the exported buffer's length n)."""
    def build(folder: Path) -> tuple[str, str]:
        n = _box_gltf(folder, edit_tree, edit_bin)
        if remove_bin:
            (folder / "meshes" / "model.bin").unlink()
        return "meshes/model.gltf", words.format(n=n)
    return build


def _glb_case(edit, words: str):
    """Build a GLB case of :data:`BROKEN_GLTF`: the box's GLB spoiled by ``edit(bytes, json length, bin
    length)`` as meshes/model.glb (``words`` formatted with the lengths j and b)."""
    def build(folder: Path) -> tuple[str, str]:
        data, j, b = _box_glb()
        (folder / "meshes" / "model.glb").write_bytes(edit(data, j, b))
        edit_json(folder, lambda d: d["objects"][0].update(mesh="meshes/model.glb"))
        return "meshes/model.glb", words.format(j=j, b=b)
    return build


#: Broken glTF files built from a good one, which trimesh reported as "cannot read mesh meshes/model.gltf:"
#: and nothing more (a buffer cut short), "[Errno 2] No such file or directory: '/.../model.bin'",
#: "cannot reshape array of size 36 into shape (999999,1)", "list index out of range" (read as a face
#: beyond the vertices), "Expecting value: line 1 column 1 (char 0)", "Extra data: line 1 column 701",
#: "chunk was not expected length!" and "only GLTF 2 is supported not `1`": case -> build(folder), which
#: writes the file and returns it and the words its one line must hold.
BROKEN_GLTF = {
    "a .gltf whose buffer is cut short": _gltf_case(
        "its binary buffer meshes/model.bin is 120 bytes, shorter than the {n:,} its bufferViews read",
        edit_bin=lambda b: b[:120]),
    "a .gltf whose buffer is missing": _gltf_case("meshes/model.bin, the buffer it names, does not exist",
                                                  remove_bin=True),
    "a .gltf whose accessor count is too large": _gltf_case(
        "its accessor 0 reads 999,999 SCALAR values (3,999,996 bytes, with its offset) from bufferView 0",
        edit_tree=lambda t: t["accessors"][0].update(count=999_999)),
    "a .gltf whose mesh names an accessor it lacks": _gltf_case(
        "its mesh 0's POSITION names accessor 7, but the file has 2 accessors",
        edit_tree=lambda t: t["meshes"][0]["primitives"][0]["attributes"].update(POSITION=7)),
    "a .gltf of glTF 1.0": _gltf_case('its asset.version is "1.0"',
                                      edit_tree=lambda t: t["asset"].update(version="1.0")),
    "a GLB whose JSON chunk is damaged": _glb_case(
        lambda d, j, b: d[:20] + bytes(10) + d[30:],
        "its JSON chunk is not valid JSON (Expecting value at byte 0 of the chunk"),
    "a GLB whose JSON chunk's length is too large": _glb_case(
        lambda d, j, b: d[:12] + _uint32(j + 8) + d[16:],
        "bytes but its JSON ends after {j:,} bytes (its length field is damaged)"),
    "a GLB whose JSON chunk's length passes its end": _glb_case(
        lambda d, j, b: d[:12] + _uint32(10**9) + d[16:],
        "its JSON chunk declares 1,000,000,000 bytes, more than the"),
    "a GLB whose binary chunk is cut short": _glb_case(
        lambda d, j, b: d[:8] + _uint32(len(d) - 40) + d[12:-40],
        "its binary chunk declares {b:,} bytes but the file holds"),
    "a GLB of glTF 1": _glb_case(lambda d, j, b: d[:4] + _uint32(1) + d[8:], "its header gives glTF version 1;"),
}


@pytest.mark.parametrize("case", sorted(BROKEN_GLTF))
def test_broken_gltf_buffers_and_chunks_are_named_in_one_line(mirror, earlier, case):
    """A glTF whose buffers, bufferViews, accessors or GLB chunks do not fit together is refused before
    the first ray in one line that names the file and says what is wrong in its own terms (bytes held
    and read, the buffer's file), never the parser's words; the earlier outputs untouched."""
    out, before = earlier
    name, words = BROKEN_GLTF[case](mirror)
    code, err = run_cli("render", mirror, "--rays", 10**12, "--workers", 1, "--quiet", "--out", out)
    assert_one_line_error(code, err, "scene.json", "objects[0].mesh", f"cannot read mesh {name}: ", words)
    for parser_words in ("Errno", "reshape", "Extra data", "line 1 column", "expected length", "GLTF 2"):
        assert parser_words not in err, err
    assert hashes(out) == before


def test_gltf_files_whose_buffers_lie_in_other_files_load(mirror):
    """The controls of the broken files: the box as a .gltf and its .bin, and as a GLB whose buffer lies
    in a .bin beside it (parsed from the GLB's bytes without trimesh's resolver, it failed "'NoneType'
    object is not subscriptable"); neither is kept by its own content (the .bin may change alone)."""
    import hashlib

    from tracer.scene import meshes

    _box_gltf(mirror)
    assert len(load_scene(mirror).objects[0].faces) == 12
    data, j, _ = _box_glb()
    tree = json.loads(data[20:20 + j])
    tree["buffers"][0]["uri"] = "model.bin"
    (mirror / "meshes" / "model.bin").write_bytes(data[28 + j:])
    text = json.dumps(tree).encode()
    text += b" " * (-len(text) % 4)  # a chunk is padded to 4 bytes (JSON with spaces)
    chunk = _uint32(len(text)) + b"JSON" + text
    glb = b"glTF" + _uint32(2) + _uint32(12 + len(chunk)) + chunk
    (mirror / "meshes" / "model.glb").write_bytes(glb)
    edit_json(mirror, lambda d: d["objects"][0].update(mesh="meshes/model.glb"))
    assert len(load_scene(mirror).objects[0].faces) == 12
    assert (".glb", hashlib.sha256(glb).digest()) not in set(meshes._READ)
    assert not any(k[0] == ".gltf" for k in meshes._READ)


def test_an_obj_quad_with_texture_coordinates_loads_without_warnings(mirror):
    """trimesh's median over the split quad's texture coordinates warned "All-NaN slice" twice on every
    load (the suite turns RuntimeWarnings into errors), and the quad lost its texture coordinates, on
    any object (a mirror here; an LCD in the test below)."""
    quad = "v -50 -50 0\nv 50 -50 0\nv 50 50 0\nv -50 50 0\nvt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nf 1/1 2/2 3/3 4/4\n"
    (mirror / "meshes" / "quad.obj").write_text(quad)
    edit_json(mirror, lambda d: d["objects"][0].update(mesh="meshes/quad.obj"))
    mirror_object = load_scene(mirror).objects[0]
    assert len(mirror_object.faces) == 2
    np.testing.assert_array_equal(mirror_object.uv, [[0, 0], [1, 0], [1, 1], [0, 1]])


def _corners(faces: np.ndarray) -> set:
    """The triangles ``faces`` as a set, each from its least index on (the same triangle, wound the same
    way, whichever corner a file or a split begins it with)."""
    return {tuple(np.roll(t, -int(np.argmin(t)))) for t in faces.tolist()}


#: An LCD's screen saved as faces of four corners or more with texture coordinates, and the same screen
#: as triangles: (the face lines, those of the triangles; one more vertex, the middle of the lower edge,
#: and its texture coordinate follow the preset's four).
LCD_POLYGONS = {
    "a quad": ("f 1/1 2/2 4/4 3/3\n", "f 1/1 2/2 4/4\nf 1/1 4/4 3/3\n"),
    "a quad with normals": ("vn 0 0 1\nf 1/1/1 2/2/1 4/4/1 3/3/1\n", "f 1/1 2/2 4/4\nf 1/1 4/4 3/3\n"),
    "a pentagon": ("f 1/1 5/5 2/2 4/4 3/3\n", "f 1/1 5/5 2/2\nf 1/1 2/2 4/4\nf 1/1 4/4 3/3\n"),
}


@pytest.mark.parametrize("case", sorted(LCD_POLYGONS))
def test_an_lcd_of_quads_or_polygons_keeps_its_texture_coordinates(preset, case):
    """hud-direct's LCD saved as one quad (or a pentagon) with vt lines was refused, "an LCD needs texture
    coordinates (an OBJ with vt lines)": trimesh, keeping the file's vertices (maintain_order), looked
    texture coordinates up in the first three corners of each face only. It loads as the same screen
    as its triangles: the same vertices, in the file's order, the same texture coordinates and triangles."""
    folder = preset("hud-direct", resolution=(8, 4))
    spec = next(o for o in json.loads((folder / "scene.json").read_text())["objects"] if o["name"] == "lcd")
    assert spec["material"]["type"] == "lcd"
    mesh = folder / spec["mesh"]
    lines = mesh.read_text().splitlines()
    v = [ln for ln in lines if ln.startswith("v ")]
    vt = [ln for ln in lines if ln.startswith("vt ")]
    assert len(v) == len(vt) == 4

    def middle(a: str, b: str) -> str:  # the line of the point halfway between two
        (key, *xa), (_, *xb) = a.split(), b.split()
        return " ".join([key] + [repr((float(x) + float(y)) / 2) for x, y in zip(xa, xb, strict=True)])

    head = "\n".join(v + [middle(v[0], v[1])] + vt + [middle(vt[0], vt[1])]) + "\n"
    polygon, triangles = LCD_POLYGONS[case]
    mesh.write_text(head + triangles)
    twin = load_scene(folder).object("lcd")
    mesh.write_text(head + polygon)
    lcd = load_scene(folder).object("lcd")
    assert lcd.uv is not None
    np.testing.assert_array_equal(lcd.vertices, twin.vertices)
    np.testing.assert_array_equal(lcd.uv, twin.uv)
    assert _corners(lcd.faces) == _corners(twin.faces)


def _glass(folder: Path, faces_edit) -> None:
    """Turn the mirror of analytic-mirror into a glass box whose faces ``faces_edit`` spoils."""
    import trimesh

    box = trimesh.creation.box(extents=[100, 100, 10])
    v, f = np.asarray(box.vertices), faces_edit(np.asarray(box.faces))
    lines = [f"v {x} {y} {z}" for x, y, z in v] + [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in f]
    (folder / "meshes" / "glass.obj").write_text("\n".join(lines) + "\n")
    edit_json(folder, lambda d: d["objects"][0].update(mesh="meshes/glass.obj",
                                                       material={"type": "dielectric", "ior": 1.5}))


@pytest.mark.parametrize("spoil,words", [(lambda f: f[:-1], "the surface is open"),
                                         (lambda f: f[:, ::-1], "inward"),
                                         (lambda f: np.concatenate([f[:2, ::-1], f[2:]]), "not consistently oriented"),
                                         (lambda f: f, None)],
                         ids=["missing face", "flipped normals", "one face flipped", "closed (control)"])
def test_dielectrics_must_be_closed_with_outward_normals(mirror, spoil, words):
    _glass(mirror, spoil)
    if words is None:
        load_scene(mirror)  # the closed box loads
        return
    code, err = run_cli("render", mirror, "--rays", 10**12, "--workers", 1, "--quiet", "--out", mirror / "o")
    assert_one_line_error(code, err, "objects[0]", words)


@pytest.mark.parametrize("text,words", [
    ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 2 3\n", "line 4: a face refers to element 0"),
    ("v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 0 1\nf 1/1 2/0 3/3\n", "line 7: a face refers to element 0"),
    ("v 0 0 0\nv 1 0 0\nv 0 1 0\nvt nan 0\nvt 1 0\nvt 0 1\nf 1/1 2/2 3/3\n", "non-finite texture coordinates"),
], ids=["vertex 0", "texture coordinate 0", "NaN texture coordinate"])
def test_obj_index_zero_and_non_finite_texture_coordinates_are_refused(mirror, earlier, text, words):
    """OBJ counts from 1; trimesh took a 0 for the last vertex and rendered as if nothing were wrong. A
    NaN texture coordinate looked an LCD's cell up from an undefined integer."""
    out, before = earlier
    (mirror / "meshes" / "mirror.obj").write_text(text)
    code, err = run_cli("render", mirror, "--rays", 10**12, "--workers", 1, "--quiet", "--out", out)
    assert_one_line_error(code, err, "scene.json", "objects[0].mesh", "meshes/mirror.obj", words)
    assert hashes(out) == before


def test_a_mesh_of_a_format_the_tracer_does_not_read_is_named_so(mirror, earlier):
    """trimesh read an OBJ named .xyz as a point cloud and failed on its 'v' ("could not convert string
    to float"); the suffix decides the format, so the message says which suffixes are read."""
    out, before = earlier
    (mirror / "meshes" / "mirror.obj").rename(mirror / "meshes" / "mirror.xyz")
    edit_json(mirror, set_field(("objects", 0, "mesh"), "meshes/mirror.xyz"))
    code, err = run_cli("render", mirror, "--rays", 10**12, "--workers", 1, "--quiet", "--out", out)
    assert_one_line_error(code, err, "scene.json", "objects[0].mesh", "meshes/mirror.xyz", ".obj, .ply")
    assert hashes(out) == before


def test_obj_indices_that_end_in_zero_are_not_taken_for_zero(mirror, tmp_path):
    """The check for index 0 reads whole tokens: faces 10, 20, 30 and 1/10 are good ones."""
    lines = [f"v {i % 7} {i // 7} 0" for i in range(31)] + [f"vt 0 {i / 31}" for i in range(31)]
    (mirror / "meshes" / "mirror.obj").write_text("\n".join(lines + ["f 10 20 30", "f 1/10 2/20 3/30", ""]))
    assert len(load_scene(mirror).objects[0].faces) == 2


def test_meshes_read_again_come_from_their_content_not_their_path(preset, tmp_path):
    """Meshes and exact surfaces already read are kept by their content (an F12 after F12 in Blender
    exports the same files into a new folder: reading them was 0.2 of hud-direct's 0.3 s of loading):
    the same bytes in another folder give the same arrays, as copies the caller may change; a file
    changed in place is read anew; a file refused once is refused again."""
    import shutil

    from tracer.core.errors import SceneError

    first = preset("hud-direct")
    second = tmp_path / "copy"
    shutil.copytree(first, second)
    a, b = load_scene(first), load_scene(second)
    for oa, ob in zip(a.objects, b.objects, strict=True):
        np.testing.assert_array_equal(oa.vertices, ob.vertices)
        np.testing.assert_array_equal(oa.faces, ob.faces)
        assert not np.shares_memory(oa.vertices, ob.vertices)
        for sa, sb in zip(oa.surfaces or [], ob.surfaces or [], strict=True):
            np.testing.assert_array_equal(sa.faces, sb.faces)
            np.testing.assert_array_equal(sa.gap_mm, sb.gap_mm)
    a.objects[0].vertices[:] = 0.0  # the caller's copy: a later load is not spoiled
    c = load_scene(second)
    np.testing.assert_array_equal(c.objects[0].vertices, b.objects[0].vertices)

    obj = json.loads((second / "scene.json").read_text())["objects"][0]
    mesh = second / obj["mesh"]
    text = mesh.read_text().splitlines()
    k = next(i for i, line in enumerate(text) if line.startswith("v "))
    x, y, z = map(float, text[k].split()[1:4])
    text[k] = f"v {x + 1.0} {y} {z}"
    mesh.write_text("\n".join(text) + "\n")
    moved = load_scene(second).objects[0]
    assert not np.array_equal(moved.vertices, b.objects[0].vertices)

    bad = text.copy()
    f = next(i for i, line in enumerate(bad) if line.startswith("f "))
    bad[f] = "f 0 1 2"
    mesh.write_text("\n".join(bad) + "\n")
    for _ in range(2):
        with pytest.raises(SceneError, match="element 0"):
            load_scene(second)


def test_an_obj_that_names_a_material_library_is_read_anew_each_time(preset):
    """trimesh packs a multi-material OBJ's textures into an atlas and moves its texture coordinates
    when the .mtl or its images change, which the .obj's own bytes do not show: such a mesh is not
    kept by its content (tracer.scene.meshes._READ), while one without a library is."""
    from tracer.scene import meshes

    folder = preset("analytic-mirror")
    obj = json.loads((folder / "scene.json").read_text())["objects"][0]
    mesh = folder / obj["mesh"]
    load_scene(folder)
    kept = len(meshes._READ)
    assert any(k[0] == ".obj" for k in meshes._READ)
    mesh.write_text("mtllib materials.mtl\n" + mesh.read_text())
    (folder / Path(obj["mesh"]).parent / "materials.mtl").write_text("newmtl m\nKd 1 1 1\n")
    load_scene(folder)
    assert len(meshes._READ) == kept  # read, not kept


def test_a_gltfs_buffer_is_part_of_the_scene_and_must_lie_in_its_folder(mirror):
    """A .gltf's buffer (.bin) is a file of the scene: the scene's hash changes with it (it did not: a
    worker or a kept result could take an edited buffer for the old scene), and one outside the scene
    folder is refused as a mesh file outside it is, unless external files are allowed (it was read)."""
    import shutil

    from tracer.core.errors import SceneError

    _box_gltf(mirror)
    before = load_scene(mirror).scene_hash
    path = mirror / "meshes" / "model.bin"
    path.write_bytes(path.read_bytes()[:-4] + b"\0\0\0\0")  # the last index moved: the same size
    assert load_scene(mirror).scene_hash != before
    _box_gltf(mirror, edit_tree=lambda t: t["buffers"][0].update(uri="../../outside.bin"))
    shutil.move(path, mirror.parent / "outside.bin")  # beside the scene folder, named by "../../"
    with pytest.raises(SceneError, match=r"objects\[0\]\.mesh.*outside\.bin: must be a path inside the scene folder"):
        load_scene(mirror)
    assert len(load_scene(mirror, allow_external=True).objects[0].faces) == 12
