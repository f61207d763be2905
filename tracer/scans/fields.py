"""The fields a sweep sets: dotted paths into scene.json (``eye.pupil_diameter_mm``,
``objects[led_?].emission.luminance``, ``eye.position[2]``), resolved against a scene, and the grid of
values each ``--set FIELD=START:STOP:N`` gives (tracer.scans.sweep).

A path's steps are keys, list indices and, after the top-level ``objects``, a glob over the objects'
names (:func:`fnmatch.fnmatchcase`; an integer in the brackets is the index, as the loader's messages
write it). Every block on the path must exist (a sweep never gives an object an emission it lacks),
except a method's options under ``methods``, whose defaults apply when they are absent; the last field
may be absent, and the loader judges whether its block takes it. Setting one of an emission's
alternatives (``luminance``) removes the other (``flux``).
"""

from __future__ import annotations

import json
import math
import re
from dataclasses import dataclass, replace
from fnmatch import fnmatchcase

import numpy as np

from ..core.jsonpath import parse_field, path_text
from ..optics.materials import MATERIALS
from ..scene.format import AIM, ANALYSER, CALIBRATION, ENVIRONMENTS, EYE, SUN, TRANSFORM_PARTS
from ..scene.methods import METHOD_OPTIONS
from ..sources.lights import EMISSION

#: Most runs a sweep may have: a grid of about 8 x 8 x 8. Each run writes its images (1.5 MB for
#: hud-direct), and every grid point's scene is loaded before the first ray (0.2 s each for hud-direct).
MAX_RUNS = 500


#: Relative distance to an integer within which a value of an integer field is that integer (geometric
#: values are rounded by the floating-point powers).
INTEGER_TOLERANCE = 1e-9


class SweepArgumentError(ValueError):
    """A sweep argument that cannot be run: ``argument`` names it (``--set FIELD=...``), ``message``
    says why."""

    def __init__(self, argument: str, message: str):
        self.argument, self.message = argument, message
        super().__init__(f"{argument}: {message}")


# -- paths into JSON ----------------------------------------------------------------------------------
#: Marks a block or field that the scene does not hold yet.
MISSING = object()


# -- fields and their grid ----------------------------------------------------------------------------
@dataclass(frozen=True)
class SweepField:
    """One ``--set FIELD=START:STOP:N`` (``given``): ``text`` the FIELD, ``steps`` its path, N values from
    ``start`` to ``stop`` (geometric if ``log``). ``targets`` (after :meth:`resolve`): each concrete
    path it sets, with the keys that setting it removes (an emission's other alternative);
    ``integer``: every target holds an integer, so the values are written as integers."""

    given: str
    text: str
    steps: tuple
    start: float
    stop: float
    n: int
    log: bool = False
    targets: tuple[tuple[tuple, tuple[str, ...]], ...] = ()
    integer: bool = False

    @property
    def argument(self) -> str:
        return f"--set {self.given}"

    @property
    def values(self) -> list[int | float]:
        """The N values, START first and STOP last."""
        if self.n == 1:
            v = [self.start]
        elif self.log:
            v = np.geomspace(self.start, self.stop, self.n)
        else:
            v = np.linspace(self.start, self.stop, self.n)
        out: list[int | float] = [float(x) for x in v]
        if self.integer:
            out = [int(round(x)) if abs(x - round(x)) <= INTEGER_TOLERANCE * max(1.0, abs(x)) else x for x in out]
        return out

    def resolve(self, raw: dict) -> SweepField:
        """This field with its targets in the scene ``raw`` (scene.json parsed); raises
        :class:`SweepArgumentError` for a path the scene does not have."""
        def bad(message):
            raise SweepArgumentError(self.argument, message)

        branches = [((), raw, None)]  # (path, node, the glob that chose the object)
        for depth, (kind, arg) in enumerate(self.steps):
            last = depth == len(self.steps) - 1
            nxt = []
            for path, node, glob in branches:
                where = _describe(raw, path, glob)
                if kind == "key":
                    if node is MISSING:
                        nxt.append(((*path, arg), MISSING, glob))
                    elif not isinstance(node, dict):
                        bad(f"{where} is {_what(node)}: it has no field {arg!r}")
                    elif arg in node:
                        nxt.append(((*path, arg), node[arg], glob))
                    elif last or _may_create((*path, arg)):
                        nxt.append(((*path, arg), MISSING, glob))
                    else:
                        fields = ", ".join(sorted(node)) or "none"
                        hint = f"; narrow the glob {glob!r}" if glob else ""
                        bad(f"{where} has no field {arg!r} (its fields: {fields}){hint}")
                elif kind == "index":
                    if not isinstance(node, list):
                        bad(f"{where} is {_what(node)}, not a list: [{arg}] addresses nothing")
                    if arg >= len(node):
                        bad(f"{where} has {len(node)} entries: [{arg}] is out of range")
                    nxt.append(((*path, arg), node[arg], glob))
                else:
                    if not isinstance(node, list):
                        bad(f"{where} is {_what(node)}, not a list of objects")
                    hits = [i for i, o in enumerate(node)
                            if isinstance(o, dict) and isinstance(o.get("name"), str) and fnmatchcase(o["name"], arg)]
                    if not hits:
                        names = [o.get("name") for o in node if isinstance(o, dict) and isinstance(o.get("name"), str)]
                        listed = ", ".join(names[:12]) + (f" and {len(names) - 12} more" if len(names) > 12 else "")
                        literal = [i for i, o in enumerate(node) if isinstance(o, dict) and o.get("name") == arg]
                        hint = (f"; names are globs (*, ? and [...] match), so address it by its index, "
                                f"objects[{literal[0]}]" if literal else "")
                        bad(f"no object's name matches {arg!r} (objects: {listed or 'none'}){hint}")
                    nxt += [((*path, i), node[i], arg) for i in hits]
            branches = nxt
        targets, integer = [], True
        for path, value, glob in branches:
            where = _describe(raw, path, glob)
            if isinstance(value, dict):
                bad(f"{where} is a block, not a value: name one of its fields ({', '.join(sorted(value)) or 'none'})")
            if isinstance(value, list):
                bad(f"{where} is a list of {len(value)} values: name one of them, as {path_text(path)}[0]")
            if isinstance(value, bool):
                bad(f"{where} is {json.dumps(value)}: only numbers can be swept")
            integer &= isinstance(value, int)
            targets.append((path, _replaced_alternatives(raw, path)))
        return replace(self, targets=tuple(targets), integer=integer)


def _may_create(path: tuple) -> bool:
    """A block that may be missing: ``methods`` and a method's options (their defaults apply)."""
    return path == ("methods",) or (len(path) == 2 and path[0] == "methods")


def _what(node) -> str:
    if isinstance(node, dict):
        return "a block"
    if isinstance(node, list):
        return f"a list of {len(node)}"
    return json.dumps(node)[:40]


def _describe(raw: dict, path: tuple, glob: str | None) -> str:
    """A path for a message, with the name of the object it goes through."""
    text = path_text(path) or "scene.json"
    if len(path) >= 2 and path[0] == "objects" and isinstance(path[1], int):
        name = raw["objects"][path[1]].get("name")
        if isinstance(name, str):
            text += f" (object {name!r}{f', matched by {glob!r}' if glob else ''})"
    return text


def _replaced_alternatives(raw: dict, path: tuple) -> tuple[str, ...]:
    """The keys that setting ``path`` removes from its block: the other alternatives of an emission
    (luminance or flux), in an ``emission`` block or a legacy ``emitter`` material."""
    if len(path) != 4 or path[0] != "objects" or path[2] not in ("emission", "material"):
        return ()
    block = raw["objects"][path[1]].get(path[2])
    if path[2] == "material" and not (isinstance(block, dict) and block.get("type") == "emitter"):
        return ()
    key = path[3]
    if not any(key in alt for alt in EMISSION.alternatives):
        return ()
    return tuple(k for alt in EMISSION.alternatives if key not in alt for k in alt)


def parse_set(text: str) -> SweepField:
    """``FIELD=START:STOP:N`` as a :class:`SweepField` (not yet resolved in a scene). Raises
    :class:`SweepArgumentError`."""
    argument = f"--set {text}"
    name, eq, spec = text.rpartition("=")
    if not eq:
        raise SweepArgumentError(argument, "expected FIELD=START:STOP:N")
    try:
        steps = parse_field(name)
    except ValueError as e:
        raise SweepArgumentError(argument, f"field {name!r}: {e}") from None
    parts = spec.split(":")
    if len(parts) != 3:
        raise SweepArgumentError(argument, f"expected START:STOP:N after '=', got {spec!r}")
    try:
        start, stop = float(parts[0]), float(parts[1])
    except ValueError:
        raise SweepArgumentError(argument, f"START and STOP must be numbers, got {parts[0]!r} and {parts[1]!r}") \
            from None
    if not (math.isfinite(start) and math.isfinite(stop)):
        raise SweepArgumentError(argument, "START and STOP must be finite")
    if not re.fullmatch(r"\s*[+-]?\d+\s*", parts[2]):
        raise SweepArgumentError(argument, f"N must be a whole number of values, got {parts[2]!r}")
    n = int(parts[2])
    if n < 1:
        raise SweepArgumentError(argument, f"N must be >= 1 (the number of values), got {n}")
    if n == 1 and start != stop:
        raise SweepArgumentError(argument, f"N = 1 gives one value: START and STOP must be equal, got {start:g} "
                                           f"and {stop:g}")
    if n > MAX_RUNS:
        raise SweepArgumentError(argument, f"{n} values, more than the {MAX_RUNS} runs a sweep may have")
    return SweepField(text, name, steps, start, stop, n)


def _flatten(fields) -> list:
    out = []
    for f in fields:
        out.append(f)
        out += _flatten(f.fields)
    return out


def field_unit(steps) -> str:
    """The unit of the scene.json field at path ``steps`` (:func:`parse_field`), from the scene format's
    schemas ("cd/m^2" for ``objects[led_?].emission.luminance``); "" where the path names no single
    kind of field."""
    keys = [v for kind, v in steps if kind == "key"]
    if not keys:
        return ""
    first, name = keys[0], keys[-1]
    if first == "eye":
        fields = [*EYE.fields, ANALYSER]
    elif first == "environment":
        fields = [f for e in ENVIRONMENTS.values() for f in e.fields] + [*SUN.fields, CALIBRATION]
    elif first == "methods" and len(keys) > 1 and keys[1] in METHOD_OPTIONS:
        fields = list(METHOD_OPTIONS[keys[1]].fields)
    elif first == "objects" and "emission" in keys:
        fields = list(EMISSION.fields) + list(AIM.fields)
    elif first == "objects" and "material" in keys:
        fields = [f for m in MATERIALS.values() for f in m.schema.fields] + list(AIM.fields)
    elif first == "objects" and "transform" in keys:
        fields = list(TRANSFORM_PARTS.fields)
    else:
        return ""
    units = {f.unit for f in _flatten(fields) if f.name == name}
    return units.pop() if len(units) == 1 else ""
