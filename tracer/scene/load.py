"""The scene format: the one seam between Blender (or a preset) and the tracer.

A scene is a folder::

    scene.json          the description below (format "hud-scene", version 1)
    meshes/...          PLY, OBJ or GLB meshes, read with trimesh (OBJ keeps texture coordinates)
    textures/...        LCD slides and HDRI panoramas, read with OpenImageIO

Units: millimetres for every length and position, cd/m^2 for luminance, lm for flux, degrees
for angles (the names say so: ``pupil_diameter_mm``, ``fov_deg``). World axes: z is up.

scene.json, version 1::

    {
      "format": "hud-scene", "version": 1, "name": "...", "description": "...",
      "eye": {"position": [x, y, z], "gaze": [..], "up": [..],
              "pupil_diameter_mm": 4.0,           # or "auto": Watson & Yellott 2012 from
              "adaptation_luminance_cd_m2": 300,  # this, or "image": what the eye sees (a pilot render
                                                  # finds it); default: the environment's mean luminance
              "adaptation": "log_average",        # or "mean": how the image gives the adaptation luminance
              "observer_age": 30, "focal_length_mm": 16.67,
              "accommodation_distance_mm": 2500.0,           # or "infinity"
              "resolution": [W, H], "fov_deg": [horizontal, vertical]},
      "environment": {"type": "none" | "uniform" | "hdri", ...,    # see tracer.sources.environment
                      "sun": {"direction": [x, y, z], "illuminance_lux": 1e5, "angular_diameter_deg": 0.53}},
      "objects": [
        {"name": "mirror", "mesh": "meshes/mirror.obj",
         "transform": {"matrix": [[4 x 4]]} | {"translate": [..], "rotate_deg": [x, y, z], "scale": [..]},
         "smooth_normals": true,
         "material": {"type": "mirror", "reflectance": 0.9}},
        {"name": "led", "mesh": "meshes/led.obj", "material": {"type": "absorber"},
         "emission": {"luminance": 1e9, "aim": {"target": "scatterer", "share": 0.95}}}
      ],
      "methods": {"backward": {"max_depth": 32, "next_event": true,
                               "exit_pupil": {"object": "name" | "center_mm": [x, y], "radius_mm": r, "share": 0.5}},
                  "forward": {"max_depth": 32}}
    }

Materials (``material.type``) and their fields are the schemas of :mod:`tracer.optics.materials`;
the emission block is :data:`tracer.sources.lights.EMISSION` (any material can emit). The material type
``emitter`` of earlier files is short for an absorber with an emission block of the same fields.
A scattering material and an emission may carry
``"aim": {"target": "eye" | "<object name>", "share": w, "mode": "toward" | "away"}``: the paper's
directed split (sec. 2), used by the forward method, and ``"light_aim"`` of the same form: the
aperture through which the surface's light arrives (a condenser's face), toward which backward eye
paths draw a share of their directions (the same one-sample mixture, unbiased for every share). An
object of type ``aperture`` is not traced:
it is a virtual surface that names where an optical system's pupil is, for aiming and for the
backward eq. (3) strata.

Method options live under ``methods``, one block per method, each validated by its method's own
option schema (``Integrator.options``), so a new method adds options without touching this loader.
Top-level ``forward`` and ``backward`` blocks of earlier files are read as ``methods.forward`` and
``methods.backward``.

Every error raises :class:`tracer.core.errors.SceneError` naming the file and the JSON field.
"""

from __future__ import annotations

import hashlib
import json
import math
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..core.errors import SceneError
from ..core.schema import Field, fail_in, parse_block
from ..core.validate import (
    BYTES_PER_PIXEL,
    MAX_COORD_MM,
    MAX_DISTANCE_MM,
    MAX_FOCAL_MM,
    MAX_LUMINANCE,
    MAX_PIXELS,
    MAX_PUPIL_MM,
    MAX_SCALE,
    MIN_DISTANCE_MM,
    MIN_LUMINANCE,
    MIN_PUPIL_MM,
    MIN_SCALE,
    FieldChecker,
    parse_json,
    physical_memory_bytes,
)
from ..optics.materials import MATERIALS
from ..optics.pupil import pupil_diameter_mm
from ..sources.environment import Environment, environment_from_spec
from ..sources.lights import EMISSION, Emission, make_emission

FORMAT = "hud-scene"
VERSION = 1
SCENE_FILE = "scene.json"

#: The legacy material type that stands for an absorber with an emission block.
LEGACY_EMITTER = "emitter"


@dataclass
class Aim:
    """The paper's directed split (sec. 2): with probability ``share`` a direction is drawn
    toward ``target`` ("eye" or the name of an object), otherwise from the surface's own law.

    ``mode`` "toward" aims at the target; "away" draws directions as if they came from it: the
    target is then a virtual image behind the surface (an optical system's pupil imaged back).
    """

    target: str
    share: float
    mode: str = "toward"


@dataclass
class Material:
    """An optical material with validated parameters (RGB values as float64 arrays (3,))."""

    type: str
    params: dict
    aim: Aim | None = None
    #: Guidance of eye paths (backward tracing): a share of the directions drawn toward the aperture
    #: through which the surface's light arrives ("light_aim").
    light_aim: Aim | None = None


@dataclass
class SceneObject:
    """One object: a triangle mesh in world millimetres, its material and, if it emits, its emission.

    Attributes
    ----------
    index : position in scene.json's object list; it is also the object's ``slot`` in a render world.
    vertices : (v, 3) float64, mm, world space.
    faces : (f, 3) int64.
    normals : (v, 3) float64 unit vertex normals when ``smooth`` else None.
    uv : (v, 2) float64 texture coordinates or None.
    local_x : (3,) the object's local x axis in the world (anisotropic lobes follow it).
    local_y : (3,) its local y axis, made perpendicular to local_x (polariser and retarder axes are
    angles from local_x toward local_y).
    """

    name: str
    index: int
    vertices: np.ndarray
    faces: np.ndarray
    material: Material
    smooth: bool = False
    normals: np.ndarray | None = None
    uv: np.ndarray | None = None
    local_x: np.ndarray = field(default_factory=lambda: np.array([1.0, 0.0, 0.0]))
    emission: Emission | None = None
    local_y: np.ndarray = field(default_factory=lambda: np.array([0.0, 1.0, 0.0]))

    def axis(self, angle_deg: float) -> np.ndarray:
        """(3,) unit vector at ``angle_deg`` from the local x axis toward the local y axis (the axis of a
        polariser, a retarder film or a polarised emitter on this object)."""
        a = np.radians(angle_deg)
        return np.cos(a) * self.local_x + np.sin(a) * self.local_y

    @property
    def slot(self) -> int:
        return self.index

    @property
    def triangles(self) -> np.ndarray:
        """(f, 3, 3) float64 triangle corners, mm."""
        return self.vertices[self.faces]

    @property
    def area_mm2(self) -> float:
        t = self.triangles
        return float(0.5 * np.linalg.norm(np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]), axis=1).sum())


#: How the adaptation luminance follows from an image (EyeSpec.adaptation).
ADAPTATION_MODES = ("log_average", "mean")
#: The pupil's first guess when it follows the image and the environment is black: a lit interior, cd/m^2.
FIRST_GUESS_CD_M2 = 100.0


#: The eye's optional analyser, ``eye.analyser``: polarised sunglasses (a linear polariser before the eye).
ANALYSER = Field(
    "analyser", "group", None, label="Analyser (polarised sunglasses)",
    description="A linear polariser in front of the eye, as polarised sunglasses are",
    fields=(Field("axis_deg", "number", 90.0, unit="deg", minimum=-360.0, maximum=360.0, label="Axis",
                  description="Transmission axis, degrees from the eye's right toward its up (sunglasses: 90)"),
            Field("transmittance_along", "number", 1.0, unit="1", minimum=0.0, maximum=1.0, label="Transmittance along",
                  description="Transmittance for light polarised along the axis, 0..1"),
            Field("transmittance_across", "number", 0.0, unit="1", minimum=0.0, maximum=1.0,
                  label="Transmittance across", description="Transmittance for light polarised across the axis, 0..1")))

#: ``polarisation`` at the top of scene.json: "auto" carries Stokes vectors where an element of the
#: scene polarises (tracer.optics.polar); "off" uses the unpolarised Fresnel average at dielectrics
#: (what an RGB renderer does) and refuses elements that only mean something with polarisation.
POLARISATION_MODES = ("auto", "off")


@dataclass
class EyeSpec:
    """The observer: a thin-lens eye (see :mod:`tracer.transport.eye`). Lengths in mm, angles in degrees."""

    position: np.ndarray
    gaze: np.ndarray
    up: np.ndarray
    pupil_diameter_mm: float
    focal_length_mm: float
    accommodation_distance_mm: float
    resolution: tuple[int, int]
    fov_deg: tuple[float, float]
    #: How the adaptation luminance follows from the image the eye sees: "log_average" (Ward 1994's
    #: log-average, the default) or "mean" (the arithmetic mean; the paper's "average luminance").
    adaptation: str = "log_average"
    #: The pupil follows the image's adaptation luminance (Watson & Yellott 2012; "auto" with
    #: adaptation_luminance_cd_m2 "image"): a pilot render finds it (tracer.products.render.run_render).
    pupil_from_image: bool = False
    observer_age: float = 30.0
    #: The analyser in front of the eye (:data:`ANALYSER`'s parsed fields), or None.
    analyser: dict | None = None


@dataclass
class Scene:
    """A loaded, validated scene."""

    root: Path
    name: str
    description: str
    eye: EyeSpec
    environment: Environment
    objects: list[SceneObject]
    #: Validated options of each method named in scene.json (methods not named use their defaults).
    methods: dict[str, dict]
    scene_hash: str
    raw: dict
    file: str = SCENE_FILE
    #: Whether the scene's files may lie outside its folder (load_scene's ``allow_external``): worker
    #: processes load the folder again with the same rule.
    allow_external: bool = False
    #: :data:`POLARISATION_MODES`: "auto" (Stokes vectors where the scene polarises) or "off".
    polarisation: str = "auto"

    def object(self, name: str) -> SceneObject:
        for obj in self.objects:
            if obj.name == name:
                return obj
        raise KeyError(name)

    @property
    def traced_objects(self) -> list[SceneObject]:
        """Objects that take part in ray intersection (virtual apertures do not)."""
        return [o for o in self.objects if MATERIALS[o.material.type].traced]

    def method_options(self, name: str) -> dict:
        """The validated options of method ``name`` (its defaults when scene.json names none)."""
        if name not in self.methods:
            from ..methods import INTEGRATORS

            self.methods[name] = INTEGRATORS[name].parse_options(FieldChecker(self.file), None,
                                                                 f"methods.{name}", self)
        return self.methods[name]


def _rotation_xyz(deg: np.ndarray) -> np.ndarray:
    """Rotation matrix for Euler angles (degrees) applied about x, then y, then z (Blender's XYZ)."""
    ax, ay, az = np.radians(deg)
    cx, sx, cy, sy, cz, sz = np.cos(ax), np.sin(ax), np.cos(ay), np.sin(ay), np.cos(az), np.sin(az)
    rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    rz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    return rz @ ry @ rx


def _transform(ck: FieldChecker, spec, fld: str) -> np.ndarray:
    """A 4 x 4 world matrix (mm) from ``matrix`` or translate/rotate_deg/scale; rejects degenerate ones.
    An absent transform is the identity; a null one is refused (a null method block or analyser means "absent")."""
    ck.obj(spec, fld)
    if "matrix" in spec:
        ck.keys(spec, fld, {"matrix"}, set())
        rows = spec["matrix"]
        if not isinstance(rows, list) or len(rows) != 4:
            ck.fail(f"{fld}.matrix", "expected 4 rows of 4 numbers")
        m = np.array([ck.vector(r, f"{fld}.matrix[{i}]", 4, MAX_COORD_MM) for i, r in enumerate(rows)])
        if not np.allclose(m[3], [0, 0, 0, 1], atol=1e-9):
            ck.fail(f"{fld}.matrix[3]", "the last row must be [0, 0, 0, 1] (affine transforms only)")
        where = f"{fld}.matrix"
    else:
        ck.keys(spec, fld, set(), {"translate", "rotate_deg", "scale"})
        t = ck.position(spec.get("translate", [0, 0, 0]), f"{fld}.translate")
        r = ck.vector(spec.get("rotate_deg", [0, 0, 0]), f"{fld}.rotate_deg", 3, 1e6)
        s_raw = spec.get("scale", [1, 1, 1])
        where = f"{fld}.scale"
        if isinstance(s_raw, list):
            s = ck.vector(s_raw, where)
        else:
            s = np.full(3, ck.number(s_raw, where))
        for i in range(3):
            if not MIN_SCALE <= abs(s[i]) <= MAX_SCALE:
                ck.fail(where if not isinstance(s_raw, list) else f"{where}[{i}]",
                        f"must be {MIN_SCALE:g} to {MAX_SCALE:g} in magnitude, got {s[i]:g}")
        m = np.eye(4)
        m[:3, :3] = _rotation_xyz(r) @ np.diag(s)
        m[:3, 3] = t
    lin = m[:3, :3]
    sv = np.linalg.svd(lin, compute_uv=False)
    if sv.min() <= 1e-9 * max(sv.max(), 1e-300):
        ck.fail(fld, f"degenerate transform (singular values {np.array2string(sv, precision=3)}): "
                     "it flattens the mesh")
    if sv.min() < MIN_SCALE or sv.max() > MAX_SCALE:
        ck.fail(where, f"scales lengths by {sv.min():.3g} to {sv.max():.3g}; each must be {MIN_SCALE:g} to "
                       f"{MAX_SCALE:g}")
    return m


def _aim(ck: FieldChecker, spec, fld: str) -> Aim:
    ck.obj(spec, fld)
    ck.keys(spec, fld, {"target"}, {"share", "mode"})
    target = ck.string(spec["target"], f"{fld}.target")
    share = ck.number(spec.get("share", 0.5), f"{fld}.share", min_value=0.0)
    if share >= 1.0:
        ck.fail(f"{fld}.share", "must be < 1 so that every direction keeps a non-zero probability (unbiasedness)")
    mode = spec.get("mode", "toward")
    if mode not in ("toward", "away"):
        ck.fail(f"{fld}.mode", 'expected "toward" or "away"')
    return Aim(target, share, mode)


def _material(ck: FieldChecker, spec, fld: str, root: Path) -> tuple[Material, dict | None, Aim | None]:
    """(material, parsed emission fields of a legacy "emitter" or None, the emitter's aim or None)."""
    ck.obj(spec, fld)
    if "type" not in spec:
        ck.fail(f"{fld}.type", "missing required field")
    mtype = spec["type"]
    if mtype == LEGACY_EMITTER:
        params = parse_block(ck, spec, fld, EMISSION.fields, root, extra_keys={"type", "aim"},
                             alternatives=EMISSION.alternatives)
        EMISSION.check(params, fail_in(ck, fld))
        aim = _aim(ck, spec["aim"], f"{fld}.aim") if "aim" in spec else None
        return Material("absorber", {}, None), params, aim
    if not isinstance(mtype, str) or mtype not in MATERIALS:
        known = ", ".join([*MATERIALS, LEGACY_EMITTER])
        ck.fail(f"{fld}.type", f"unknown material {json.dumps(mtype)} (known: {known})")
    schema = MATERIALS[mtype].schema
    extra = {"type"} | ({"aim", "light_aim"} if schema.can_aim else set())
    params = parse_block(ck, spec, fld, schema.fields, root, extra_keys=extra, alternatives=schema.alternatives)
    if schema.check is not None:
        schema.check(params, fail_in(ck, fld))
    aim = _aim(ck, spec["aim"], f"{fld}.aim") if "aim" in spec else None
    light_aim = _aim(ck, spec["light_aim"], f"{fld}.light_aim") if "light_aim" in spec else None
    return Material(mtype, params, aim, light_aim), None, None


def _emission(ck: FieldChecker, spec, fld: str) -> tuple[dict, Aim | None]:
    params = parse_block(ck, spec, fld, EMISSION.fields, extra_keys={"aim"}, alternatives=EMISSION.alternatives)
    EMISSION.check(params, fail_in(ck, fld))
    return params, (_aim(ck, spec["aim"], f"{fld}.aim") if "aim" in spec else None)


#: An index 0 in an OBJ face (of a vertex, texture coordinate or normal): OBJ counts from 1 (and from -1
#: backward), so 0 refers to nothing; trimesh would take it as the last element.
_OBJ_ZERO_INDEX = re.compile(rb"(?m)^f[ \t][^\n]*?(?:(?<=[ \t])|/)0(?=[/ \t\r]|$)")


def _check_obj_indices(ck: FieldChecker, path: Path, rel: str, fld: str):
    try:
        data = path.read_bytes()
    except OSError as e:
        ck.fail(fld, f"{rel}: cannot be read ({e.strerror or e})")
    bad = _OBJ_ZERO_INDEX.search(data)
    if bad:
        line = data.count(b"\n", 0, bad.start()) + 1
        ck.fail(fld, f"cannot read mesh {rel}: line {line}: a face refers to element 0 (OBJ counts from 1)")


#: The mesh formats scene.json may name (trimesh reads them; it also guesses at others, and reads a
#: point cloud or a text file of numbers as a mesh of no faces or of garbage).
MESH_SUFFIXES = (".obj", ".ply", ".stl", ".off", ".glb", ".gltf")


def _load_mesh(ck: FieldChecker, root: Path, rel: str, fld: str):
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
    if path.suffix.lower() == ".obj":
        _check_obj_indices(ck, path, rel, fld)
    try:
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
    return v, f, uv


def _check_closed_outward(ck: FieldChecker, vw: np.ndarray, faces: np.ndarray, fld: str, rel: str):
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


def scene_hash(root: Path, raw_bytes: bytes, files: list[str]) -> str:
    """SHA-256 of scene.json and every file it references (first 16 hex digits)."""
    h = hashlib.sha256(raw_bytes)
    for rel in sorted(set(files)):
        p = root / rel
        h.update(rel.encode())
        try:
            h.update(p.read_bytes())
        except OSError:
            pass  # a file the loader could read and then not: hashed by name only
    return h.hexdigest()[:16]


def _polarisation(ck: FieldChecker, raw: dict, eye: EyeSpec, objects: list[SceneObject]) -> str:
    """The scene's polarisation mode, after checking what needs it: with "off", no element may be one
    that only polarisation can describe; LCD output polarisers are on every LCD or on none."""
    mode = raw.get("polarisation", "auto")
    if mode not in POLARISATION_MODES:
        ck.fail("polarisation", f"expected one of {', '.join(json.dumps(m) for m in POLARISATION_MODES)}, got "
                                f"{json.dumps(mode)[:40]}")
    needs = []  # (field, what)
    if eye.analyser is not None:
        needs.append(("eye.analyser", "an analyser"))
    lcds = []
    for o in objects:
        fld, p, t = f"objects[{o.index}].material", o.material.params, o.material.type
        if t == "lcd":
            lcds.append((o, p.get("polariser") is not None))
        if t == "lcd" and p.get("polariser") is not None:
            needs.append((f"{fld}.polariser", "an LCD output polariser"))
        elif t == "retarder":
            needs.append((f"{fld}.type", "a retarder film"))
        elif t == "coating" and "reflectance_s" in p:
            needs.append((f"{fld}.reflectance_s", "a coating given for s and p light"))
        elif t == "mirror" and p.get("metal") is not None:
            needs.append((f"{fld}.metal", "a metal mirror"))
        if o.emission is not None and o.emission.polarisation is not None:
            where = "emission" if "emission" in raw["objects"][o.index] else "material"
            needs.append((f"objects[{o.index}].{where}.polarisation", "polarised emission"))
    if mode == "off" and needs:
        fld, what = needs[0]
        ck.fail(fld, f'{what} needs polarisation: remove "polarisation": "off" (or this block)')
    if lcds and 0 < sum(has for _, has in lcds) < len(lcds):
        bare = next(o for o, has in lcds if not has)
        ck.fail(f"objects[{bare.index}].material.polariser", "give every LCD of the scene an output polariser, or none")
    return mode


def _eye(ck: FieldChecker, spec, environment: Environment) -> EyeSpec:
    fld = "eye"
    ck.obj(spec, fld)
    ck.keys(spec, fld, {"position", "gaze", "up", "pupil_diameter_mm", "resolution", "fov_deg"},
            {"focal_length_mm", "accommodation_distance_mm", "adaptation_luminance_cd_m2", "observer_age",
             "adaptation", "analyser"})
    pos = ck.position(spec["position"], "eye.position")
    gaze = ck.unit_vector(spec["gaze"], "eye.gaze")
    up = ck.unit_vector(spec["up"], "eye.up")
    if np.linalg.norm(np.cross(gaze, up)) < 1e-6:
        ck.fail("eye.up", "must not be parallel to eye.gaze")
    adaptation = spec.get("adaptation", "log_average")
    if adaptation not in ADAPTATION_MODES:
        ck.fail("eye.adaptation", f"expected one of {', '.join(json.dumps(m) for m in ADAPTATION_MODES)}, got "
                                  f"{json.dumps(adaptation)[:40]}")
    age = ck.number(spec.get("observer_age", 30.0), "eye.observer_age", min_value=1.0, max_value=120.0)
    from_image = False
    if spec["pupil_diameter_mm"] == "auto":
        # Watson & Yellott (2012) for the adaptation luminance: given, the image's (a pilot finds it), or
        # the environment's mean.
        given = spec.get("adaptation_luminance_cd_m2")
        if given == "image":
            from_image = True
            adapt = environment.mean_luminance if not environment.is_black else FIRST_GUESS_CD_M2
        elif given is not None:
            adapt = ck.number(given, "eye.adaptation_luminance_cd_m2", min_value=0.0, max_value=MAX_LUMINANCE)
        elif not environment.is_black:
            adapt = environment.mean_luminance
        else:
            ck.fail("eye.pupil_diameter_mm", '"auto" needs eye.adaptation_luminance_cd_m2 (a luminance, or "image") '
                                             'or a lit environment')
        pupil = pupil_diameter_mm(adapt, age_years=age)
    else:
        pupil = ck.number(spec["pupil_diameter_mm"], "eye.pupil_diameter_mm", min_value=MIN_PUPIL_MM,
                          max_value=MAX_PUPIL_MM)
    focal = ck.number(spec.get("focal_length_mm", 16.67), "eye.focal_length_mm", min_value=0.0, min_exclusive=True,
                      max_value=MAX_FOCAL_MM)
    acc_raw = spec.get("accommodation_distance_mm", "infinity")
    if acc_raw == "infinity":
        acc = math.inf
    else:
        acc = ck.number(acc_raw, "eye.accommodation_distance_mm", min_value=MIN_DISTANCE_MM,
                        max_value=MAX_DISTANCE_MM)
    res = spec["resolution"]
    if (not isinstance(res, list) or len(res) != 2
            or not all(isinstance(r, int) and not isinstance(r, bool) and 1 <= r <= 16384 for r in res)):
        ck.fail("eye.resolution", f"expected [width, height], integers in 1..16384, got {json.dumps(res)[:80]}")
    need = res[0] * res[1] * BYTES_PER_PIXEL
    memory = physical_memory_bytes()
    if res[0] * res[1] > MAX_PIXELS:
        ck.fail("eye.resolution", f"{res[0]} x {res[1]} = {res[0] * res[1]:,} pixels, above the limit of "
                                  f"{MAX_PIXELS:,} (a render needs about {need / 2**30:.1f} GiB per process)")
    if memory is not None and need > memory / 2:
        ck.fail("eye.resolution", f"{res[0]} x {res[1]} pixels need about {need / 2**30:.1f} GiB per process; this "
                                  f"machine has {memory / 2**30:.1f} GiB (the limit is half of it)")
    fov = ck.vector(spec["fov_deg"], "eye.fov_deg", 2)
    if np.any(fov <= 0) or np.any(fov >= 170):
        ck.fail("eye.fov_deg", f"each field angle must lie in (0, 170) degrees, got {fov[0]!r} x {fov[1]!r}")
    analyser = None
    if spec.get("analyser") is not None:
        analyser = parse_block(ck, spec["analyser"], "eye.analyser", ANALYSER.fields)
        if analyser["transmittance_along"] == 0 and analyser["transmittance_across"] == 0:
            ck.fail("eye.analyser", "transmittance_along and transmittance_across are both 0: the analyser passes no "
                                    "light and every image would be black")
    return EyeSpec(pos, gaze, up, pupil, focal, acc, (res[0], res[1]), (float(fov[0]), float(fov[1])), adaptation,
                   from_image, age, analyser)


def _methods(ck: FieldChecker, raw: dict, scene: Scene) -> dict[str, dict]:
    """Validate the "methods" block (and the legacy top-level "forward"/"backward" blocks) with each
    method's own option schema."""
    from ..methods import INTEGRATORS

    blocks = dict(ck.obj(raw["methods"], "methods")) if "methods" in raw else {}
    fields = {name: f"methods.{name}" for name in blocks}
    for legacy in ("forward", "backward"):
        if legacy in raw:
            if legacy in blocks:
                ck.fail(legacy, f'give the options once, under "methods.{legacy}"')
            blocks[legacy], fields[legacy] = raw[legacy], legacy
    out = {}
    for name, block in blocks.items():
        if name not in INTEGRATORS:
            ck.fail(fields[name], f"unknown method (known: {', '.join(INTEGRATORS)})")
        out[name] = INTEGRATORS[name].parse_options(ck, block, fields[name], scene)
    return out


def load_scene(path: str | Path, allow_external: bool = False) -> Scene:
    """Read and validate a scene folder (or a scene.json path).

    Files the scene names (meshes, images) must lie inside its folder unless ``allow_external``.

    Raises
    ------
    SceneError
        For any problem, naming the file and the field.
    """
    path = Path(path)
    fname = str(path)
    try:
        root = path.parent if path.is_file() else path
        file = root / SCENE_FILE
        fname = str(file)
        if not file.is_file():
            raise SceneError(fname, "", "scene file not found (a scene is a folder with scene.json)")
        raw_bytes = file.read_bytes()
    except OSError as e:
        raise SceneError(fname, "", f"cannot be read ({e.strerror or e})") from None
    try:
        text = raw_bytes.decode("utf-8-sig")  # a byte-order mark, which Windows editors write, is dropped
    except UnicodeDecodeError as e:
        raise SceneError(fname, "", f"malformed JSON: {e}") from None
    raw = parse_json(text, fname)
    ck = FieldChecker(fname, allow_external)
    ck.obj(raw, "")
    ck.keys(raw, "", {"format", "version", "eye", "objects"},
            {"name", "description", "environment", "methods", "backward", "forward", "polarisation"})
    if raw["format"] != FORMAT:
        ck.fail("format", f'expected "{FORMAT}", got {json.dumps(raw["format"])}')
    if type(raw["version"]) is not int or raw["version"] != VERSION:  # true and 1.0 equal 1 in Python
        ck.fail("version", f"this tracer reads version {VERSION}, got {json.dumps(raw['version'])}")
    env = environment_from_spec(raw.get("environment", {"type": "none"}), root, fname, allow_external)
    eye = _eye(ck, raw["eye"], env)

    objs_raw = raw["objects"]
    if not isinstance(objs_raw, list):
        ck.fail("objects", "expected a list of objects")
    files: list[str] = []
    objects: list[SceneObject] = []
    names: set[str] = set()
    for i, o in enumerate(objs_raw):
        fld = f"objects[{i}]"
        ck.obj(o, fld)
        ck.keys(o, fld, {"name", "mesh", "material"}, {"transform", "smooth_normals", "emission"})
        name = ck.string(o["name"], f"{fld}.name")
        if name in names:
            ck.fail(f"{fld}.name", f"duplicate object name {json.dumps(name)}")
        if name == "eye":
            ck.fail(f"{fld}.name", '"eye" is reserved for the observer\'s pupil')
        names.add(name)
        mat, emission, emission_aim = _material(ck, o["material"], f"{fld}.material", root)
        if "emission" in o:
            if emission is not None:
                ck.fail(f"{fld}.emission", 'an "emitter" material already emits: give the emission once')
            emission, emission_aim = _emission(ck, o["emission"], f"{fld}.emission")
            if not MATERIALS[mat.type].traced:
                ck.fail(f"{fld}.emission", f"material {mat.type} is not traced (rays pass through it), so it cannot "
                                           "emit: give the emission to a surface (an absorber for a bare source)")
        files += [v for k, v in mat.params.items() if k.endswith("_file")]
        rel = ck.string(o["mesh"], f"{fld}.mesh")
        files.append(rel)
        m = _transform(ck, o["transform"], f"{fld}.transform") if "transform" in o else np.eye(4)
        v, f, uv = _load_mesh(ck, root, rel, f"{fld}.mesh")
        if f.min() < 0 or f.max() >= len(v):
            ck.fail(f"{fld}.mesh", f"{rel}: face indices out of range")
        if np.abs(v).max() > MAX_COORD_MM:
            ck.fail(f"{fld}.mesh", f"{rel}: vertex coordinates reach {np.abs(v).max():.3g} mm; they must lie within "
                                   f"+-{MAX_COORD_MM:g} mm")
        vw = v[:, :1] * m[:3, 0] + v[:, 1:2] * m[:3, 1] + v[:, 2:3] * m[:3, 2] + m[:3, 3]  # fixed order
        if np.abs(vw).max() > MAX_COORD_MM:
            ck.fail(f"{fld}.transform", f"places {rel} {np.abs(vw).max():.3g} mm from the origin; the scene must lie "
                                        f"within +-{MAX_COORD_MM:g} mm")
        if np.linalg.det(m[:3, :3]) < 0:
            f = f[:, ::-1]  # a mirroring transform would turn the normals inside out
        smooth = ck.boolean(o.get("smooth_normals", False), f"{fld}.smooth_normals")
        tri = vw[f]
        cross = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        if np.linalg.norm(cross, axis=1).max() <= 0:
            ck.fail(f"{fld}.mesh", f"{rel}: all triangles are degenerate (zero area)")
        normals = None
        if smooth:
            vn = np.zeros_like(vw)
            for k in range(3):
                np.add.at(vn, f[:, k], cross)
            lengths = np.sqrt(vn[:, 0] * vn[:, 0] + vn[:, 1] * vn[:, 1] + vn[:, 2] * vn[:, 2])
            normals = np.divide(vn, lengths[:, None], out=np.zeros_like(vn), where=lengths[:, None] > 0)
        if mat.type == "dielectric":
            _check_closed_outward(ck, vw, f, f"{fld}.mesh", rel)
        if mat.type == "lcd" and uv is None:
            ck.fail(f"{fld}.mesh", f"{rel}: an LCD needs texture coordinates (an OBJ with vt lines)")
        lx = m[:3, :3] @ np.array([1.0, 0.0, 0.0])
        lx /= np.linalg.norm(lx)
        ly = m[:3, :3] @ np.array([0.0, 1.0, 0.0])
        ly -= (ly @ lx) * lx
        obj = SceneObject(name, i, vw, f, mat, smooth, normals, uv, lx, local_y=ly / np.linalg.norm(ly))
        if emission is not None:
            obj.emission = make_emission(emission, obj.area_mm2, emission_aim)
            lum = obj.emission.luminance
            if lum > MAX_LUMINANCE or 0 < lum < MIN_LUMINANCE:
                where = "emission" if "emission" in o else "material"
                ck.fail(f"{fld}.{where}.flux", f"gives a luminance of {lum:.3g} cd/m^2 over the object's "
                                               f"{obj.area_mm2:.3g} mm^2, outside [{MIN_LUMINANCE:g}, "
                                               f"{MAX_LUMINANCE:g}] (give 0 for a light that is off)")
        objects.append(obj)

    # Aim targets must exist; apertures must be planar for the solid-angle pdf to be exact.
    by_name = {o.name: o for o in objects}
    aims = [(o, o.material.aim, f"objects[{o.index}].material.aim.target") for o in objects]
    aims += [(o, o.material.light_aim, f"objects[{o.index}].material.light_aim.target") for o in objects]
    aims += [(o, o.emission.aim, f"objects[{o.index}].{'emission' if 'emission' in objs_raw[o.index] else 'material'}"
                                 ".aim.target") for o in objects if o.emission is not None]
    for o, aim, fld in aims:
        if aim is None:
            continue
        target = aim.target
        if target == "eye":
            continue
        if target not in by_name:
            ck.fail(fld, f"no object named {json.dumps(target)} (or use \"eye\")")
        if target == o.name:
            ck.fail(fld, "an object cannot aim at itself")
        t = by_name[target]
        centered = t.vertices - t.vertices.mean(axis=0)
        sv = np.linalg.svd(centered, compute_uv=False)
        if sv[-1] > 1e-6 * max(sv[0], 1e-12):
            ck.fail(fld, f"aim target {json.dumps(target)} must be a planar mesh (a window, a lens aperture, the LCD)")

    polarisation = _polarisation(ck, raw, eye, objects)

    name = raw.get("name", root.name)
    if not isinstance(name, str):
        ck.fail("name", "expected a string")
    desc = raw.get("description", "")
    if not isinstance(desc, str):
        ck.fail("description", "expected a string")
    env_file = raw.get("environment", {}).get("file") if isinstance(raw.get("environment"), dict) else None
    if isinstance(env_file, str):
        files.append(env_file)
    scene = Scene(root, name, desc, eye, env, objects, {}, scene_hash(root, raw_bytes, files), raw, fname,
                  allow_external, polarisation)
    scene.methods = _methods(ck, raw, scene)
    return scene
