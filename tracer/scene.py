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
              "adaptation_luminance_cd_m2": 300,  # this (default: the environment's mean luminance)
              "observer_age": 30, "focal_length_mm": 16.67,
              "accommodation_distance_mm": 2500.0,           # or "infinity"
              "resolution": [W, H], "fov_deg": [horizontal, vertical]},
      "environment": {"type": "none" | "uniform" | "hdri", ...},   # see tracer.environment
      "objects": [
        {"name": "mirror", "mesh": "meshes/mirror.obj",
         "transform": {"matrix": [[4 x 4]]} | {"translate": [..], "rotate_deg": [x, y, z], "scale": [..]},
         "smooth_normals": true,
         "material": {"type": "mirror", "reflectance": 0.9}}
      ],
      "backward": {"max_depth": 32, "exit_pupil": {"object": "name" | "center_mm": [x, y], "radius_mm": r,
                                                    "share": 0.5}},
      "forward": {"max_depth": 32}
    }

Material types (``material.type``) and their fields are listed in :data:`MATERIAL_FIELDS`; the
physics lives in :mod:`tracer.optics`. A scattering material and an emitter may carry
``"aim": {"target": "eye" | "<object name>", "share": w, "mode": "toward" | "away"}``: the paper's
directed split (sec. 2), used by the forward method. An object of type ``aperture`` is not traced:
it is a virtual surface that names where an optical system's pupil is, for aiming and for the backward eq. (3) strata.

Every error raises :class:`tracer.errors.SceneError` naming the file and the JSON field.
"""

from __future__ import annotations

import hashlib
import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .environment import Environment, environment_from_spec
from .errors import ImageReadError, SceneError
from .imageio import read_image
from .pupil import pupil_diameter_mm
from .units import lambertian_luminance_cd_m2, normalize_color
from .validate import FieldChecker
from .vec import norm

FORMAT = "hud-scene"
VERSION = 1
SCENE_FILE = "scene.json"

#: Allowed fields of each material type: name -> (required fields, optional fields).
MATERIAL_FIELDS: dict[str, tuple[set[str], set[str]]] = {
    "mirror": ({"reflectance"}, set()),
    "dielectric": ({"ior"}, {"ior_outside"}),
    "coating": ({"reflectance", "transmittance"}, set()),
    "absorber": (set(), set()),
    "lambertian": ({"reflectance"}, {"aim"}),
    "lambertian_transmitter": ({"transmittance"}, {"reflectance", "aim"}),
    "diffuser": ({"transmittance", "sigma_deg"}, {"aim"}),
    "lcd": ({"image"}, {"transmittance", "contrast_ratio", "image_encoding"}),
    "emitter": (set(), {"luminance", "flux", "color", "two_sided", "aim"}),
    "aperture": (set(), set()),
}



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


@dataclass
class SceneObject:
    """One object: a triangle mesh in world millimetres and its material.

    Attributes
    ----------
    vertices : (v, 3) float64, mm, world space.
    faces : (f, 3) int64.
    normals : (v, 3) float64 unit vertex normals when ``smooth`` else None.
    uv : (v, 2) float64 texture coordinates or None.
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

    @property
    def triangles(self) -> np.ndarray:
        """(f, 3, 3) float64 triangle corners, mm."""
        return self.vertices[self.faces]

    @property
    def area_mm2(self) -> float:
        t = self.triangles
        return float(0.5 * np.linalg.norm(np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]), axis=1).sum())


@dataclass
class EyeSpec:
    """The observer: a thin-lens eye (see :mod:`tracer.eye`). Lengths in mm, angles in degrees."""

    position: np.ndarray
    gaze: np.ndarray
    up: np.ndarray
    pupil_diameter_mm: float
    focal_length_mm: float
    accommodation_distance_mm: float
    resolution: tuple[int, int]
    fov_deg: tuple[float, float]


@dataclass
class ExitPupil:
    """Backward-method strata of eq. (3): a disk in the eye's pupil plane (eye coordinates, mm)."""

    center_mm: np.ndarray
    radius_mm: float
    share: float


@dataclass
class Scene:
    """A loaded, validated scene."""

    root: Path
    name: str
    description: str
    eye: EyeSpec
    environment: Environment
    objects: list[SceneObject]
    backward: dict
    forward: dict
    scene_hash: str
    raw: dict

    def object(self, name: str) -> SceneObject:
        for obj in self.objects:
            if obj.name == name:
                return obj
        raise KeyError(name)

    @property
    def traced_objects(self) -> list[SceneObject]:
        """Objects that take part in ray intersection (virtual apertures do not)."""
        return [o for o in self.objects if o.material.type != "aperture"]


def _rotation_xyz(deg: np.ndarray) -> np.ndarray:
    """Rotation matrix for Euler angles (degrees) applied about x, then y, then z (Blender's XYZ)."""
    ax, ay, az = np.radians(deg)
    cx, sx, cy, sy, cz, sz = np.cos(ax), np.sin(ax), np.cos(ay), np.sin(ay), np.cos(az), np.sin(az)
    rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    rz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    return rz @ ry @ rx


def _transform(ck: FieldChecker, spec, fld: str) -> np.ndarray:
    """A 4 x 4 world matrix (mm) from ``matrix`` or translate/rotate_deg/scale; rejects degenerate ones."""
    if spec is None:
        return np.eye(4)
    ck.obj(spec, fld)
    if "matrix" in spec:
        ck.keys(spec, fld, {"matrix"}, set())
        rows = spec["matrix"]
        if not isinstance(rows, list) or len(rows) != 4:
            ck.fail(f"{fld}.matrix", "expected 4 rows of 4 numbers")
        m = np.array([ck.vector(r, f"{fld}.matrix[{i}]", 4) for i, r in enumerate(rows)])
        if not np.allclose(m[3], [0, 0, 0, 1], atol=1e-9):
            ck.fail(f"{fld}.matrix[3]", "the last row must be [0, 0, 0, 1] (affine transforms only)")
    else:
        ck.keys(spec, fld, set(), {"translate", "rotate_deg", "scale"})
        t = ck.vector(spec.get("translate", [0, 0, 0]), f"{fld}.translate")
        r = ck.vector(spec.get("rotate_deg", [0, 0, 0]), f"{fld}.rotate_deg")
        s_raw = spec.get("scale", [1, 1, 1])
        if isinstance(s_raw, list):
            s = ck.vector(s_raw, f"{fld}.scale")
        else:
            s = np.full(3, ck.number(s_raw, f"{fld}.scale"))
        m = np.eye(4)
        m[:3, :3] = _rotation_xyz(r) @ np.diag(s)
        m[:3, 3] = t
    lin = m[:3, :3]
    sv = np.linalg.svd(lin, compute_uv=False)
    if sv.min() <= 1e-9 * max(sv.max(), 1e-300):
        ck.fail(fld, f"degenerate transform (singular values {np.array2string(sv, precision=3)}): "
                     "it flattens the mesh")
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


def _material(ck: FieldChecker, spec, fld: str, root: Path) -> Material:
    ck.obj(spec, fld)
    if "type" not in spec:
        ck.fail(f"{fld}.type", "missing required field")
    mtype = spec["type"]
    if mtype not in MATERIAL_FIELDS:
        ck.fail(f"{fld}.type", f"unknown material {json.dumps(mtype)} (known: {', '.join(MATERIAL_FIELDS)})")
    required, optional = MATERIAL_FIELDS[mtype]
    ck.keys(spec, fld, required | {"type"}, optional)
    p: dict = {}
    if mtype == "mirror":
        p["reflectance"] = ck.rgb(spec["reflectance"], f"{fld}.reflectance")
    elif mtype == "dielectric":
        p["ior"] = ck.number(spec["ior"], f"{fld}.ior", min_value=1.0)
        p["ior_outside"] = ck.number(spec.get("ior_outside", 1.0), f"{fld}.ior_outside", min_value=1.0)
    elif mtype == "coating":
        p["reflectance"] = ck.rgb(spec["reflectance"], f"{fld}.reflectance")
        p["transmittance"] = ck.rgb(spec["transmittance"], f"{fld}.transmittance")
        if np.any(p["reflectance"] + p["transmittance"] > 1 + 1e-12):
            ck.fail(fld, "reflectance + transmittance must not exceed 1 (energy conservation)")
    elif mtype == "lambertian":
        p["reflectance"] = ck.rgb(spec["reflectance"], f"{fld}.reflectance")
    elif mtype == "lambertian_transmitter":
        p["transmittance"] = ck.rgb(spec["transmittance"], f"{fld}.transmittance")
        p["reflectance"] = ck.rgb(spec.get("reflectance", 0.0), f"{fld}.reflectance")
        if np.any(p["reflectance"] + p["transmittance"] > 1 + 1e-12):
            ck.fail(fld, "reflectance + transmittance must not exceed 1 (energy conservation)")
    elif mtype == "diffuser":
        p["transmittance"] = ck.rgb(spec["transmittance"], f"{fld}.transmittance")
        s = spec["sigma_deg"]
        if isinstance(s, list):
            sig = ck.vector(s, f"{fld}.sigma_deg", 2)
        else:
            sig = np.full(2, ck.number(s, f"{fld}.sigma_deg"))
        if np.any(sig <= 0) or np.any(sig > 60):
            ck.fail(f"{fld}.sigma_deg", "lobe widths must lie in (0, 60] degrees")
        p["sigma"] = np.sin(np.radians(sig))  # width in direction-cosine space
        p["sigma_deg"] = sig
    elif mtype == "lcd":
        rel = ck.string(spec["image"], f"{fld}.image")
        enc = spec.get("image_encoding", "srgb")
        if enc not in ("srgb", "linear"):
            ck.fail(f"{fld}.image_encoding", 'expected "srgb" or "linear"')
        try:
            img = read_image(root / rel, linear=(enc == "linear"))
        except ImageReadError as e:
            raise SceneError(ck.file, f"{fld}.image", f"cannot read {rel}: {e.reason}") from None
        img = img[..., :3] if img.shape[2] >= 3 else np.repeat(img[..., :1], 3, axis=2)
        if not np.all(np.isfinite(img)) or img.min() < 0 or img.max() > 1 + 1e-6:
            ck.fail(f"{fld}.image", f"{rel}: transmittance values must lie in [0, 1]")
        p["image"] = np.clip(img.astype(np.float64), 0.0, 1.0)
        p["image_file"] = rel
        p["transmittance"] = ck.rgb(spec.get("transmittance", 1.0), f"{fld}.transmittance")
        p["contrast_ratio"] = ck.number(spec.get("contrast_ratio", 300.0), f"{fld}.contrast_ratio", min_value=1.0)
    elif mtype == "emitter":
        has_l, has_f = "luminance" in spec, "flux" in spec
        if has_l == has_f:
            ck.fail(fld, 'give exactly one of "luminance" (cd/m^2) or "flux" (lm)')
        if has_l:
            p["luminance"] = ck.number(spec["luminance"], f"{fld}.luminance", min_value=0.0)
        else:
            p["flux"] = ck.number(spec["flux"], f"{fld}.flux", min_value=0.0)
        try:
            p["color"] = normalize_color(ck.rgb(spec.get("color", [1.0, 1.0, 1.0]), f"{fld}.color", max_value=None))
        except ValueError as e:
            ck.fail(f"{fld}.color", str(e))
        p["two_sided"] = ck.boolean(spec.get("two_sided", False), f"{fld}.two_sided")
    aim = _aim(ck, spec["aim"], f"{fld}.aim") if "aim" in spec else None
    return Material(mtype, p, aim)


def _load_mesh(ck: FieldChecker, root: Path, rel: str, fld: str):
    """(vertices (v,3), faces (f,3), uv (v,2) or None) from PLY/OBJ/GLB through trimesh."""
    import trimesh

    path = root / rel
    if not path.is_file():
        ck.fail(fld, f"mesh file not found: {rel}")
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
    except Exception as e:  # trimesh raises many types on malformed files
        ck.fail(fld, f"cannot read mesh {rel}: {e}")
    v = np.asarray(getattr(loaded, "vertices", np.zeros((0, 3))), dtype=np.float64)
    f = np.asarray(getattr(loaded, "faces", np.zeros((0, 3))), dtype=np.int64)
    if len(v) == 0 or len(f) == 0:
        ck.fail(fld, f"{rel} contains no triangles")
    if not np.all(np.isfinite(v)):
        ck.fail(fld, f"{rel} has non-finite vertex coordinates")
    uv = None
    visual = getattr(loaded, "visual", None)
    if visual is not None and getattr(visual, "kind", None) == "texture" and getattr(visual, "uv", None) is not None:
        uv_arr = np.asarray(visual.uv, dtype=np.float64)
        if uv_arr.shape == (len(v), 2):
            uv = uv_arr
    return v, f, uv


def scene_hash(root: Path, raw_bytes: bytes, files: list[str]) -> str:
    """SHA-256 of scene.json and every file it references (first 16 hex digits)."""
    h = hashlib.sha256(raw_bytes)
    for rel in sorted(set(files)):
        p = root / rel
        h.update(rel.encode())
        if p.is_file():
            h.update(p.read_bytes())
    return h.hexdigest()[:16]


def _eye(ck: FieldChecker, spec, environment: Environment) -> EyeSpec:
    fld = "eye"
    ck.obj(spec, fld)
    ck.keys(spec, fld, {"position", "gaze", "up", "pupil_diameter_mm", "resolution", "fov_deg"},
            {"focal_length_mm", "accommodation_distance_mm", "adaptation_luminance_cd_m2", "observer_age"})
    pos = ck.vector(spec["position"], "eye.position")
    gaze = ck.unit_vector(spec["gaze"], "eye.gaze")
    up = ck.unit_vector(spec["up"], "eye.up")
    if np.linalg.norm(np.cross(gaze, up)) < 1e-6:
        ck.fail("eye.up", "must not be parallel to eye.gaze")
    if spec["pupil_diameter_mm"] == "auto":
        # Watson & Yellott (2012) for the adaptation luminance: given, or the environment's mean.
        if "adaptation_luminance_cd_m2" in spec:
            adapt = ck.number(spec["adaptation_luminance_cd_m2"], "eye.adaptation_luminance_cd_m2", min_value=0.0)
        elif not environment.is_black:
            adapt = environment.mean_luminance
        else:
            ck.fail("eye.pupil_diameter_mm", '"auto" needs eye.adaptation_luminance_cd_m2 or a lit environment')
        age = ck.number(spec.get("observer_age", 30.0), "eye.observer_age", min_value=1.0, max_value=120.0)
        pupil = pupil_diameter_mm(adapt, age_years=age)
    else:
        pupil = ck.number(spec["pupil_diameter_mm"], "eye.pupil_diameter_mm", min_value=0.0, min_exclusive=True)
    focal = ck.number(spec.get("focal_length_mm", 16.67), "eye.focal_length_mm", min_value=0.0, min_exclusive=True)
    acc_raw = spec.get("accommodation_distance_mm", "infinity")
    if acc_raw == "infinity":
        acc = math.inf
    else:
        acc = ck.number(acc_raw, "eye.accommodation_distance_mm", min_value=0.0, min_exclusive=True)
    res = spec["resolution"]
    if (not isinstance(res, list) or len(res) != 2
            or not all(isinstance(r, int) and not isinstance(r, bool) and 1 <= r <= 16384 for r in res)):
        ck.fail("eye.resolution", f"expected [width, height], integers in 1..16384, got {json.dumps(res)}")
    fov = ck.vector(spec["fov_deg"], "eye.fov_deg", 2)
    if np.any(fov <= 0) or np.any(fov >= 170):
        ck.fail("eye.fov_deg", "each field angle must lie in (0, 170) degrees")
    return EyeSpec(pos, gaze, up, pupil, focal, acc, (res[0], res[1]), (float(fov[0]), float(fov[1])))


def _method_block(ck: FieldChecker, spec, fld: str, optional: set[str]) -> dict:
    spec = {} if spec is None else ck.obj(spec, fld)
    ck.keys(spec, fld, set(), optional)
    out = {"max_depth": int(ck.number(spec.get("max_depth", 32), f"{fld}.max_depth", min_value=1, max_value=1000))}
    return out | {k: v for k, v in spec.items() if k != "max_depth"}


def _exit_pupil(ck: FieldChecker, spec, scene_objects: list[SceneObject], eye: EyeSpec) -> ExitPupil:
    """Eq. (3) strata: a disk given in pupil-plane coordinates or projected from a named object."""
    fld = "backward.exit_pupil"
    ck.obj(spec, fld)
    ck.keys(spec, fld, {"share"}, {"object", "center_mm", "radius_mm"})
    share = ck.number(spec["share"], f"{fld}.share", min_value=0.0)
    if share >= 1.0:
        ck.fail(f"{fld}.share", "must be < 1: the rest of the pupil keeps samples (unbiasedness)")
    if "object" in spec:
        if "center_mm" in spec or "radius_mm" in spec:
            ck.fail(fld, 'give either "object" or "center_mm" and "radius_mm", not both')
        name = ck.string(spec["object"], f"{fld}.object")
        matches = [o for o in scene_objects if o.name == name]
        if not matches:
            ck.fail(f"{fld}.object", f"no object named {json.dumps(name)}")
        # Project the object's vertices along the gaze onto the pupil plane (eye coordinates).
        right = np.cross(eye.gaze, eye.up)
        right /= np.linalg.norm(right)
        upv = np.cross(right, eye.gaze)
        rel = matches[0].vertices - eye.position
        xy = np.stack([rel @ right, rel @ upv], axis=1)
        center = 0.5 * (xy.min(axis=0) + xy.max(axis=0))
        radius = float(np.linalg.norm(xy - center, axis=1).max())
    else:
        center = ck.vector(spec.get("center_mm"), f"{fld}.center_mm", 2)
        radius = ck.number(spec.get("radius_mm"), f"{fld}.radius_mm", min_value=0.0, min_exclusive=True)
    return ExitPupil(center, radius, share)


def load_scene(path: str | Path) -> Scene:
    """Read and validate a scene folder (or a scene.json path).

    Raises
    ------
    SceneError
        For any problem, naming the file and the field.
    """
    path = Path(path)
    root = path.parent if path.is_file() else path
    file = root / SCENE_FILE
    fname = str(file)
    if not file.is_file():
        raise SceneError(fname, "", "scene file not found (a scene is a folder with scene.json)")
    raw_bytes = file.read_bytes()
    try:
        raw = json.loads(raw_bytes.decode("utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as e:
        raise SceneError(fname, "", f"malformed JSON: {e}") from None
    ck = FieldChecker(fname)
    ck.obj(raw, "")
    ck.keys(raw, "", {"format", "version", "eye", "objects"},
            {"name", "description", "environment", "backward", "forward"})
    if raw["format"] != FORMAT:
        ck.fail("format", f'expected "{FORMAT}", got {json.dumps(raw["format"])}')
    if raw["version"] != VERSION:
        ck.fail("version", f"this tracer reads version {VERSION}, got {json.dumps(raw['version'])}")
    env = environment_from_spec(raw.get("environment", {"type": "none"}), root, fname)
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
        ck.keys(o, fld, {"name", "mesh", "material"}, {"transform", "smooth_normals"})
        name = ck.string(o["name"], f"{fld}.name")
        if name in names:
            ck.fail(f"{fld}.name", f"duplicate object name {json.dumps(name)}")
        if name == "eye":
            ck.fail(f"{fld}.name", '"eye" is reserved for the observer\'s pupil')
        names.add(name)
        mat = _material(ck, o["material"], f"{fld}.material", root)
        if mat.type == "lcd":
            files.append(mat.params["image_file"])
        rel = ck.string(o["mesh"], f"{fld}.mesh")
        files.append(rel)
        m = _transform(ck, o.get("transform"), f"{fld}.transform")
        v, f, uv = _load_mesh(ck, root, rel, f"{fld}.mesh")
        if f.min() < 0 or f.max() >= len(v):
            ck.fail(f"{fld}.mesh", f"{rel}: face indices out of range")
        vw = v[:, :1] * m[:3, 0] + v[:, 1:2] * m[:3, 1] + v[:, 2:3] * m[:3, 2] + m[:3, 3]  # fixed order
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
            lengths = norm(vn)
            normals = np.divide(vn, lengths[:, None], out=np.zeros_like(vn), where=lengths[:, None] > 0)
        if mat.type == "lcd" and uv is None:
            ck.fail(f"{fld}.mesh", f"{rel}: an LCD needs texture coordinates (an OBJ with vt lines)")
        lx = m[:3, :3] @ np.array([1.0, 0.0, 0.0])
        objects.append(SceneObject(name, i, vw, f, mat, smooth, normals, uv, lx / np.linalg.norm(lx)))

    # Aim targets must exist; apertures must be planar for the solid-angle pdf to be exact.
    by_name = {o.name: o for o in objects}
    for o in objects:
        if o.material.aim is None:
            continue
        fld = f"objects[{o.index}].material.aim.target"
        target = o.material.aim.target
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

    backward = _method_block(ck, raw.get("backward"), "backward", {"max_depth", "exit_pupil"})
    if "exit_pupil" in backward:
        backward["exit_pupil"] = _exit_pupil(ck, backward["exit_pupil"], objects, eye)
    forward = _method_block(ck, raw.get("forward"), "forward", {"max_depth"})
    name = raw.get("name", root.name)
    if not isinstance(name, str):
        ck.fail("name", "expected a string")
    desc = raw.get("description", "")
    if not isinstance(desc, str):
        ck.fail("description", "expected a string")
    env_file = raw.get("environment", {}).get("file") if isinstance(raw.get("environment"), dict) else None
    if isinstance(env_file, str):
        files.append(env_file)
    return Scene(root, name, desc, eye, env, objects, backward, forward, scene_hash(root, raw_bytes, files), raw)


def emitter_luminance(obj: SceneObject) -> float:
    """Luminance (cd/m^2) of an emitter object, from its luminance or its flux (lm) and area."""
    p = obj.material.params
    if "luminance" in p:
        return p["luminance"]
    sides = 2.0 if p["two_sided"] else 1.0
    return lambertian_luminance_cd_m2(p["flux"], sides * obj.area_mm2)
