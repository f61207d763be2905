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


def test_an_obj_quad_with_texture_coordinates_loads_without_warnings(mirror):
    """trimesh's median over the split quad's texture coordinates warned "All-NaN slice" twice on every
    load (the suite turns RuntimeWarnings into errors)."""
    quad = "v -50 -50 0\nv 50 -50 0\nv 50 50 0\nv -50 50 0\nvt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nf 1/1 2/2 3/3 4/4\n"
    (mirror / "meshes" / "quad.obj").write_text(quad)
    edit_json(mirror, lambda d: d["objects"][0].update(mesh="meshes/quad.obj"))
    assert len(load_scene(mirror).objects[0].faces) == 2


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
