"""Reading a scene folder: scene.json checked block by block against the format
(:mod:`tracer.scene.format`; docs/user/scene-format.md), the meshes and images it names loaded, and the
result built as plain data (:mod:`tracer.scene.model`). Every error raises
:class:`tracer.core.errors.SceneError` naming the file and the JSON field.
"""

from __future__ import annotations

import hashlib
import json
import math
from pathlib import Path

import numpy as np

from ..core.errors import SceneError
from ..core.jsonpath import parse_requirement
from ..core.schema import fail_in, number_field, parse_block
from ..core.validate import (
    BYTES_PER_PIXEL,
    MAX_COORD_MM,
    MAX_LUMINANCE,
    MAX_PIXELS,
    MAX_SCALE,
    MIN_LUMINANCE,
    MIN_SCALE,
    FieldChecker,
    parse_json,
    physical_memory_bytes,
)
from ..optics.materials import MATERIALS
from ..optics.pupil import pupil_diameter_mm
from ..sources.environment import Environment
from ..sources.lights import EMISSION, make_emission
from .environment import environment_from_spec
from .format import (
    AIM,
    ANALYSER,
    EYE,
    FORMAT,
    LEGACY_EMITTER,
    OBJECT,
    POLARISATION_MODES,
    SCENE_FILE,
    TARGET,
    TOP,
    TRANSFORM_MATRIX,
    TRANSFORM_PARTS,
    VERSION,
)
from .meshes import check_closed_outward, files_beside, load_mesh
from .methods import parse_methods
from .model import Aim, EyeSpec, Material, Scene, SceneObject
from .surfaces import load_surfaces
from .windshield import WINDSHIELD, radius_problem, windshield_mesh

#: The pupil's first guess when it follows the image and the environment is black: a lit interior, cd/m^2.
FIRST_GUESS_CD_M2 = 100.0


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
        ck.keys(spec, fld, *TRANSFORM_MATRIX.keys)
        rows = spec["matrix"]
        if not isinstance(rows, list) or len(rows) != 4:
            ck.fail(f"{fld}.matrix", "expected 4 rows of 4 numbers")
        limit = TRANSFORM_MATRIX.field("matrix").maximum
        m = np.array([ck.vector(r, f"{fld}.matrix[{i}]", 4, limit) for i, r in enumerate(rows)])
        if not np.allclose(m[3], [0, 0, 0, 1], atol=1e-9):
            ck.fail(f"{fld}.matrix[3]", "the last row must be [0, 0, 0, 1] (affine transforms only)")
        where = f"{fld}.matrix"
    else:
        ck.keys(spec, fld, *TRANSFORM_PARTS.keys)
        translate, rotate, scale = (TRANSFORM_PARTS.field(k) for k in ("translate", "rotate_deg", "scale"))
        t = ck.vector(spec.get("translate", translate.default), f"{fld}.translate", 3, translate.maximum)
        r = ck.vector(spec.get("rotate_deg", rotate.default), f"{fld}.rotate_deg", 3, rotate.maximum)
        s_raw = spec.get("scale", scale.default)
        where = f"{fld}.scale"
        if isinstance(s_raw, list):
            s = ck.vector(s_raw, where)
        else:
            s = np.full(3, ck.number(s_raw, where))
        for i in range(3):
            if not scale.minimum <= abs(s[i]) <= scale.maximum:
                ck.fail(where if not isinstance(s_raw, list) else f"{where}[{i}]",
                        f"must be {scale.minimum:g} to {scale.maximum:g} in magnitude, got {s[i]:g}")
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
    ck.keys(spec, fld, *AIM.keys)
    target = ck.string(spec["target"], f"{fld}.target")
    share = ck.number(spec.get("share", AIM.field("share").default), f"{fld}.share", min_value=0.0)
    if share >= 1.0:
        ck.fail(f"{fld}.share", "must be < 1 so that every direction keeps a non-zero probability (unbiasedness)")
    modes = AIM.field("mode")
    mode = spec.get("mode", modes.default)
    if mode not in modes.choices:
        ck.fail(f"{fld}.mode", f"expected {' or '.join(json.dumps(c) for c in modes.choices)}")
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
    mode = raw.get("polarisation", TOP.field("polarisation").default)
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
    ck.keys(spec, fld, *EYE.keys)
    pos = ck.vector(spec["position"], "eye.position", 3, EYE.field("position").maximum)
    gaze = ck.unit_vector(spec["gaze"], "eye.gaze")
    up = ck.unit_vector(spec["up"], "eye.up")
    if np.linalg.norm(np.cross(gaze, up)) < 1e-6:
        ck.fail("eye.up", "must not be parallel to eye.gaze")
    modes = EYE.field("adaptation")
    adaptation = spec.get("adaptation", modes.default)
    if adaptation not in modes.choices:
        ck.fail("eye.adaptation", f"expected one of {', '.join(json.dumps(m) for m in modes.choices)}, got "
                                  f"{json.dumps(adaptation)[:40]}")
    age = number_field(ck, EYE.field("observer_age"), spec, fld)
    from_image = False
    if spec["pupil_diameter_mm"] == "auto":
        # Watson & Yellott (2012) for the adaptation luminance: given, the image's (a pilot finds it), or
        # the environment's mean.
        given = spec.get("adaptation_luminance_cd_m2")
        if given == "image":
            from_image = True
            adapt = environment.mean_luminance if not environment.is_black else FIRST_GUESS_CD_M2
        elif given is not None:
            adapt = number_field(ck, EYE.field("adaptation_luminance_cd_m2"), {"adaptation_luminance_cd_m2": given},
                                 fld)
        elif not environment.is_black:
            adapt = environment.mean_luminance
        else:
            ck.fail("eye.pupil_diameter_mm", '"auto" needs eye.adaptation_luminance_cd_m2 (a luminance, or "image") '
                                             'or a lit environment')
        pupil = pupil_diameter_mm(adapt, age_years=age)
    else:
        pupil = ck.number(spec["pupil_diameter_mm"], "eye.pupil_diameter_mm",
                          min_value=EYE.field("pupil_diameter_mm").minimum,
                          max_value=EYE.field("pupil_diameter_mm").maximum)
    focal = number_field(ck, EYE.field("focal_length_mm"), spec, fld)
    acc = number_field(ck, EYE.field("accommodation_distance_mm"), spec, fld)
    acc = math.inf if acc == "infinity" else acc
    res = spec["resolution"]
    most = EYE.field("resolution").maximum
    if (not isinstance(res, list) or len(res) != 2
            or not all(isinstance(r, int) and not isinstance(r, bool) and 1 <= r <= most for r in res)):
        ck.fail("eye.resolution", f"expected [width, height], integers in 1..{most}, got {json.dumps(res)[:80]}")
    need = res[0] * res[1] * BYTES_PER_PIXEL
    memory = physical_memory_bytes()
    if res[0] * res[1] > MAX_PIXELS:
        ck.fail("eye.resolution", f"{res[0]} x {res[1]} = {res[0] * res[1]:,} pixels, above the limit of "
                                  f"{MAX_PIXELS:,} (a render needs about {need / 2**30:.1f} GiB per process)")
    if memory is not None and need > memory / 2:
        ck.fail("eye.resolution", f"{res[0]} x {res[1]} pixels need about {need / 2**30:.1f} GiB per process; this "
                                  f"machine has {memory / 2**30:.1f} GiB (the limit is half of it)")
    fov = ck.vector(spec["fov_deg"], "eye.fov_deg", 2)
    widest = EYE.field("fov_deg").maximum
    if np.any(fov <= 0) or np.any(fov >= widest):
        ck.fail("eye.fov_deg", f"each field angle must lie in (0, {widest:g}) degrees, got {fov[0]!r} x {fov[1]!r}")
    analyser = None
    if spec.get("analyser") is not None:
        analyser = parse_block(ck, spec["analyser"], "eye.analyser", ANALYSER.fields)
        if analyser["transmittance_along"] == 0 and analyser["transmittance_across"] == 0:
            ck.fail("eye.analyser", "transmittance_along and transmittance_across are both 0: the analyser passes no "
                                    "light and every image would be black")
    return EyeSpec(pos, gaze, up, pupil, focal, acc, (res[0], res[1]), (float(fov[0]), float(fov[1])), adaptation,
                   from_image, age, analyser)


def _windshield(ck: FieldChecker, o: dict, fld: str, mat: Material):
    """(vertices, faces, None, surfaces blocks) of an object's windshield block (tracer.scene.windshield)."""
    where = f"{fld}.windshield"
    if mat.type != "dielectric":
        ck.fail(f"{fld}.material.type", f'a windshield is glass: "dielectric", got {json.dumps(mat.type)}')
    if o.get("surfaces") is not None:
        ck.fail(f"{fld}.surfaces", "a windshield brings its own surfaces")
    p = parse_block(ck, o["windshield"], where, WINDSHIELD.fields)
    if (bad := radius_problem(p)) is not None:
        ck.fail(f"{where}.{bad[0]}", bad[1])
    try:
        v, f, specs = windshield_mesh(p)
    except ValueError as e:
        ck.fail(where, str(e))
    return v, f, None, specs


def _target(ck: FieldChecker, spec) -> dict:
    """The target block (:data:`TARGET`; absent: every default): the parsed fields, ``forward`` and
    ``up`` normalised (None for an absent forward), ``requirements`` as
    :class:`tracer.core.jsonpath.Requirement` objects."""
    spec = {} if spec is None else spec
    listed = {f.name for f in TARGET.fields if f.kind == "list"}
    out = parse_block(ck, spec, "target", tuple(f for f in TARGET.fields if f.name not in listed), extra_keys=listed)
    for key in ("forward", "up"):
        if key in out:
            n = float(np.linalg.norm(out[key]))
            if n < 1e-12:
                ck.fail(f"target.{key}", "must not be the zero vector")
            out[key] = out[key] / n
    if "forward" in out and abs(float(out["forward"] @ out["up"])) > 0.999:
        ck.fail("target.forward", "must not be parallel to target.up")
    reqs = spec.get("requirements", [])
    if not isinstance(reqs, list):
        ck.fail("target.requirements", 'expected a list of "KEY OP VALUE" strings')
    out["requirements"] = []
    for i, text in enumerate(reqs):
        try:
            out["requirements"].append(parse_requirement(text))
        except ValueError as e:
            ck.fail(f"target.requirements[{i}]", str(e))
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
    ck.keys(raw, "", *TOP.keys)
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
        ck.keys(o, fld, *OBJECT.keys)
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
        m = _transform(ck, o["transform"], f"{fld}.transform") if "transform" in o else np.eye(4)
        if ("mesh" in o) == (o.get("windshield") is not None):
            ck.fail(fld, 'give exactly one of "mesh" or "windshield"')
        surfaces_spec = o.get("surfaces")
        if "mesh" in o:
            rel = ck.string(o["mesh"], f"{fld}.mesh")
            files.append(rel)
            v, f, uv = load_mesh(ck, root, rel, f"{fld}.mesh")
            files += files_beside(ck, root, rel, f"{fld}.mesh")
        else:
            rel = f"{fld}.windshield"
            v, f, uv, surfaces_spec = _windshield(ck, o, fld, mat)
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
            check_closed_outward(ck, vw, f, f"{fld}.mesh", rel)
        if mat.type == "lcd" and uv is None:
            ck.fail(f"{fld}.mesh", f"{rel}: an LCD needs texture coordinates (an OBJ with vt lines)")
        lx = m[:3, :3] @ np.array([1.0, 0.0, 0.0])
        lx /= np.linalg.norm(lx)
        ly = m[:3, :3] @ np.array([0.0, 1.0, 0.0])
        ly -= (ly @ lx) * lx
        obj = SceneObject(name, i, vw, f, mat, smooth, normals, uv, lx, local_y=ly / np.linalg.norm(ly))
        if surfaces_spec is not None:
            where = f"{fld}.surfaces" if "mesh" in o else f"{fld}.windshield"
            obj.surfaces = load_surfaces(ck, surfaces_spec, where, name, mat.type, emission is not None, vw, f, m, rel)
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
    target = _target(ck, raw.get("target"))
    if target.get("pgu") is not None and target["pgu"] not in by_name:
        ck.fail("target.pgu", f"no object named {json.dumps(target['pgu'])}")

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
                  allow_external, polarisation, target)
    scene.methods = parse_methods(ck, raw, scene)
    return scene
