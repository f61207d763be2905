"""One description of every field a user can set: materials, the emission block, method options.

A :class:`Schema` lists :class:`Field` s with their kind, default, unit and range. From it come
(1) the scene loader's validation (:func:`parse_block`, every error naming the file and the field),
(2) the Blender add-on's properties, panels and export (hud_addon/properties.py, ui.py, export.py),
(3) the preset builder's reverse mapping (hud_addon/build.py), and (4) the Mitsuba converter's check
that it maps every material (benchmarks/mitsuba_scene.py). A new material is one class in
:mod:`tracer.optics.materials` that carries its schema; a new method option is one field in the
method's ``options``.

Kinds (JSON value -> parsed value):

- ``"number"``: a finite number -> float; ``"int"``: an integer -> int;
- ``"rgb"``: a number or [r, g, b] -> float64 array (3,);
- ``"pair"``: a number or [a, b] -> float64 array (2,) (e.g. lobe widths in degrees);
- ``"vector2"``: [x, y] -> float64 array (2,);
- ``"bool"``; ``"choice"`` (one of ``choices``); ``"string"``; ``"object_ref"`` (the name of a scene object);
- ``"image"``: a path relative to the scene folder -> float64 array (H, W, 3) in [0, 1], decoded with the
  sibling field ``<name>_encoding`` when the schema has one (the path is kept as ``<name>_file``);
- ``"group"``: a nested block of ``fields`` (optional as a whole when its default is ``None``).

A field whose range is [0, 1] holds factors (a transmittance, a reflectance, a share): a positive number
below :data:`tracer.core.validate.MIN_FACTOR`, or a positive component below it of an ``"rgb"`` or other
list, is refused (it would underflow the float32 path weights); 0 stays allowed.

Kinds of the scene format's own blocks (tracer.scene.format), which the scene loader reads itself:
``"vector3"`` ([x, y, z]), ``"int2"`` (two integers), ``"matrix4"`` (four rows of four numbers) and
``"list"`` (a list of blocks). A number field may also take one of its ``keywords`` (the pupil's
``"auto"``, the accommodation's ``"infinity"``).
"""

from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .errors import ImageReadError, SceneError
from .validate import MIN_FACTOR, FieldChecker

#: Default of a field that must be given.
REQUIRED = object()

KINDS = ("number", "int", "rgb", "pair", "vector2", "bool", "choice", "string", "object_ref", "image", "group",
         "vector3", "int2", "matrix4", "list")


@dataclass(frozen=True)
class Field:
    """One settable value.

    Parameters
    ----------
    name : JSON key.
    kind : one of :data:`KINDS`.
    default : the value when the key is absent (JSON form); :data:`REQUIRED` when it must be given;
        ``None`` for an optional value with no default (an optional group, an alternative field).
    unit : the physical unit ("cd/m^2", "lm", "mm", "deg", "1" for dimensionless ratios, "" for none).
    minimum, maximum : inclusive bounds of numbers and of each component of vectors (None: unbounded);
        ``exclusive_min`` and ``exclusive_max`` make them strict.
    choices : the allowed strings of a ``choice``.
    label, description : short name and one-sentence tooltip (the add-on shows both).
    fields : the fields of a ``group``.
    alternatives : for a ``group``, sets of its fields of which exactly one set must be given
        (see :class:`Schema`).
    ui_default : the value a user interface starts from when there is no default (JSON form).
    keywords : strings a number field also takes in place of a number (each with its meaning in
        ``description``).
    """

    name: str
    kind: str
    default: object = REQUIRED
    unit: str = ""
    minimum: float | None = None
    maximum: float | None = None
    exclusive_min: bool = False
    exclusive_max: bool = False
    choices: tuple[str, ...] = ()
    label: str = ""
    description: str = ""
    fields: tuple[Field, ...] = ()
    alternatives: tuple[tuple[str, ...], ...] = ()
    ui_default: object = None
    keywords: tuple[str, ...] = ()

    def __post_init__(self):
        if self.kind not in KINDS:
            raise ValueError(f"field {self.name!r}: unknown kind {self.kind!r}")

    @property
    def required(self) -> bool:
        return self.default is REQUIRED

    @property
    def title(self) -> str:
        return self.label or self.name.replace("_", " ").capitalize()


@dataclass(frozen=True)
class Schema:
    """A named block of fields: a material, the emission block, or a method's options.

    ``alternatives`` lists sets of optional fields of which exactly one set must be given (an emission
    by luminance or by flux); ``check(params, fail)`` validates other relations between fields
    (``fail(field, message)`` raises); ``can_aim`` says whether the block accepts the paper's directed
    split (sec. 2), the "aim" block.
    """

    name: str
    label: str
    description: str
    fields: tuple[Field, ...] = ()
    can_aim: bool = False
    alternatives: tuple[tuple[str, ...], ...] = ()
    check: Callable[[dict, Callable[[str, str], None]], None] | None = field(default=None, compare=False)

    def field(self, name: str) -> Field:
        for f in self.fields:
            if f.name == name:
                return f
        raise KeyError(name)

    @property
    def keys(self) -> tuple[set[str], set[str]]:
        """(required JSON keys, optional JSON keys)."""
        req = {f.name for f in self.fields if f.required}
        opt = {f.name for f in self.fields if not f.required}
        return req, opt | ({"aim"} if self.can_aim else set())


def _is_factor(f: Field) -> bool:
    """Whether field ``f`` holds factors: numbers in [0, 1] (a transmittance, a reflectance, a share; each
    component of an RGB one), by which a path's weight is multiplied."""
    return f.minimum == 0.0 and f.maximum == 1.0


def _refuse_underflow(ck: FieldChecker, f: Field, v: float, where: str, channel: str = ""):
    """Refuse a positive factor below :data:`~tracer.core.validate.MIN_FACTOR` (0 stays allowed where the
    field's range allows it: no light passes): the float32 path weights hold about 1e-38, and a path meets
    several such factors, so the image would come out black without a warning. ``channel`` names the
    component of a list ("red")."""
    if _is_factor(f) and 0.0 < v < MIN_FACTOR:
        of = f" ({channel})" if channel else ""
        ck.fail(where, f"{v:g}{of} is below {MIN_FACTOR:g}: a factor this small underflows the tracer's float32 "
                       "path weights (the image would come out black); give 0 or at least that")


#: Names of the components of an RGB list, for messages.
_CHANNELS = ("red", "green", "blue")


def _vector(ck: FieldChecker, value, fld: str, f: Field, n: int, scalar_ok: bool) -> np.ndarray:
    if isinstance(value, list):
        v = ck.vector(value, fld, n)
        where = [f"{fld}[{i}]" for i in range(n)]
    elif scalar_ok:
        v = np.full(n, ck.number(value, fld))
        where = [fld] * n
    else:
        ck.fail(fld, f"expected a list of {n} numbers, got {json.dumps(value)}")
    channels = _CHANNELS if isinstance(value, list) and f.kind == "rgb" else ("",) * n
    for i in range(n):
        lo_bad = f.minimum is not None and (v[i] < f.minimum or (f.exclusive_min and v[i] == f.minimum))
        hi_bad = f.maximum is not None and (v[i] > f.maximum or (f.exclusive_max and v[i] == f.maximum))
        if lo_bad or hi_bad:
            lo = "-inf" if f.minimum is None else f"{f.minimum:g}"
            hi = "inf" if f.maximum is None else f"{f.maximum:g}"
            opening, closing = "(" if f.exclusive_min else "[", ")" if f.exclusive_max else "]"
            ck.fail(where[i], f"must lie in {opening}{lo}, {hi}{closing}, got {v[i]:g}")
        _refuse_underflow(ck, f, float(v[i]), where[i], channels[i])
    return v


def parse_value(ck: FieldChecker, f: Field, value, fld: str, root: Path | None, spec: dict):
    """The parsed value of field ``f`` from its JSON ``value`` (see the module docstring)."""
    k = f.kind
    if k == "number":
        v = ck.number(value, fld, min_value=f.minimum, min_exclusive=f.exclusive_min, max_value=f.maximum,
                      max_exclusive=f.exclusive_max)
        _refuse_underflow(ck, f, v, fld)
        return v
    if k == "int":
        if isinstance(value, bool) or not isinstance(value, int):
            if not (isinstance(value, float) and value.is_integer()):
                ck.fail(fld, f"expected an integer, got {json.dumps(value)}")
        return int(ck.number(value, fld, min_value=f.minimum, min_exclusive=f.exclusive_min, max_value=f.maximum,
                             max_exclusive=f.exclusive_max))
    if k == "rgb":
        return _vector(ck, value, fld, f, 3, scalar_ok=True)
    if k == "pair":
        return _vector(ck, value, fld, f, 2, scalar_ok=True)
    if k == "vector2":
        return _vector(ck, value, fld, f, 2, scalar_ok=False)
    if k == "vector3":
        return _vector(ck, value, fld, f, 3, scalar_ok=False)
    if k == "int2":
        v = _vector(ck, value, fld, f, 2, scalar_ok=False)
        if any(isinstance(x, bool) or float(x) != int(x) for x in value):
            ck.fail(fld, f"expected two integers, got {json.dumps(value)[:40]}")
        return (int(v[0]), int(v[1]))
    if k == "bool":
        return ck.boolean(value, fld)
    if k == "choice":
        if value not in f.choices:
            ck.fail(fld, f"expected one of {', '.join(json.dumps(c) for c in f.choices)}, got {json.dumps(value)}")
        return value
    if k in ("string", "object_ref"):
        return ck.string(value, fld)
    if k == "image":
        rel = ck.string(value, fld)
        enc = spec.get(f"{f.name}_encoding", "srgb")
        from .imageio import read_image

        try:
            img = read_image(ck.path(root, rel, fld), linear=(enc == "linear"))
        except ImageReadError as e:
            raise SceneError(ck.file, fld, f"cannot read {rel}: {e.reason}") from None
        img = img[..., :3] if img.shape[2] >= 3 else np.repeat(img[..., :1], 3, axis=2)
        if not np.all(np.isfinite(img)) or img.min() < 0 or img.max() > 1 + 1e-6:
            ck.fail(fld, f"{rel}: values must lie in [0, 1]")
        return np.clip(img.astype(np.float64), 0.0, 1.0)
    if k == "group":
        return parse_block(ck, value, fld, f.fields, root, alternatives=f.alternatives)
    raise AssertionError(k)


def number_field(ck: FieldChecker, f: Field, spec: dict, block: str):
    """The number of field ``f`` in the JSON block ``spec`` (its default where absent), checked against
    the field's range; a keyword of the field (``f.keywords``) is returned as given. ``block`` is the
    block's own path, for the error message."""
    value = spec.get(f.name, f.default)
    if isinstance(value, str) and value in f.keywords:
        return value
    return ck.number(value, f"{block}.{f.name}" if block else f.name, min_value=f.minimum,
                     min_exclusive=f.exclusive_min, max_value=f.maximum, max_exclusive=f.exclusive_max)


def parse_block(ck: FieldChecker, spec, fld: str, fields: tuple[Field, ...], root: Path | None = None,
                extra_keys: set[str] = frozenset(), alternatives: tuple[tuple[str, ...], ...] = ()) -> dict:
    """Validate a JSON block against ``fields``: unknown keys, missing required ones, every value,
    and that exactly one set of ``alternatives`` is given (whole).

    Returns the parsed values by field name, defaults filled in (fields whose default is ``None``
    and that are absent are left out); an image field also gives ``<name>_file``, its path.
    ``extra_keys`` are accepted and left to the caller (a material's "type" and "aim").
    """
    spec = {} if spec is None else ck.obj(spec, fld)
    req = {f.name for f in fields if f.required}
    opt = {f.name for f in fields if not f.required}
    ck.keys(spec, fld, req, opt | set(extra_keys))
    if alternatives:
        given = [alt for alt in alternatives if any(k in spec for k in alt)]
        names = " or ".join("+".join(f'"{k}"' for k in alt) for alt in alternatives)
        if len(given) != 1:
            ck.fail(fld, f"give exactly one of {names}")
        for k in given[0]:
            if k not in spec:
                ck.fail(f"{fld}.{k}" if fld else k, f"missing (it goes with {', '.join(given[0])})")
    out: dict = {}
    for f in fields:
        sub = f"{fld}.{f.name}" if fld else f.name
        if f.name in spec:
            out[f.name] = parse_value(ck, f, spec[f.name], sub, root, spec)
            if f.kind == "image":
                out[f"{f.name}_file"] = spec[f.name]
        elif f.default is not None and not f.required:
            out[f.name] = parse_value(ck, f, f.default, sub, root, spec)
    return out


def to_json(f: Field, value):
    """A parsed value back to its JSON form (what an exporter writes)."""
    if f.kind in ("rgb", "pair", "vector2"):
        return [float(x) for x in np.asarray(value, dtype=np.float64).reshape(-1)]
    if f.kind == "number":
        return float(value)
    if f.kind == "int":
        return int(value)
    return value


def check_consistent(schemas) -> dict[str, Field]:
    """Fields by name across ``schemas``; the add-on keeps one property per name, so a name must mean
    the same kind and unit in every schema that has it. Raises ValueError otherwise."""
    seen: dict[str, Field] = {}
    for s in schemas:
        for f in s.fields:
            if f.name in seen and (seen[f.name].kind, seen[f.name].unit) != (f.kind, f.unit):
                raise ValueError(f"field {f.name!r} has kind/unit {(f.kind, f.unit)} in {s.name!r} but "
                                 f"{(seen[f.name].kind, seen[f.name].unit)} elsewhere")
            seen.setdefault(f.name, f)
    return seen


def fail_in(ck: FieldChecker, fld: str) -> Callable[[str, str], None]:
    """A ``fail(field, message)`` for a schema's ``check`` that names fields inside block ``fld``."""
    def fail(name: str, msg: str):
        ck.fail(f"{fld}.{name}" if name else fld, msg)
    return fail
