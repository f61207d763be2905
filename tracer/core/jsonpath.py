"""Dotted paths into JSON documents (``objects[led_?].emission.luminance``, ``hud.contrast_ratio``) and
requirements on the numbers they lead to (``"KEY OP VALUE"``): the sweep's --set and --require
(tracer.scans) and the target image's requirements (tracer.analysis.optics) read them alike."""

from __future__ import annotations

import json
import math
import operator
import re
from dataclasses import dataclass

_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")


def parse_field(text: str, globs: bool = True) -> tuple[tuple[str, object], ...]:
    """The steps of a dotted path: ("key", name), ("index", i) or, after a top-level ``objects`` when
    ``globs``, ("glob", pattern). Raises ValueError saying what is malformed."""
    steps: list[tuple[str, object]] = []
    i, n = 0, len(text)
    if not text:
        raise ValueError("empty path")
    while True:
        m = _NAME.match(text, i)
        if not m:
            raise ValueError(f"expected a field name at character {i + 1}")
        steps.append(("key", m.group()))
        i = m.end()
        while i < n and text[i] == "[":
            depth, j = 0, i
            while j < n:
                depth += {"[": 1, "]": -1}.get(text[j], 0)
                if depth == 0:
                    break
                j += 1
            if j >= n:
                raise ValueError(f"the '[' at character {i + 1} is not closed")
            sel = text[i + 1:j]
            if re.fullmatch(r"\d+", sel):
                steps.append(("index", int(sel)))
            elif globs and steps == [("key", "objects")] and sel:
                steps.append(("glob", sel))
            else:
                where = "an object's name (a glob) or an index" if globs and steps == [("key", "objects")] else \
                    "an index (only objects[...] takes a name)"
                raise ValueError(f"[{sel}] at character {i + 1}: expected {where}")
            i = j + 1
        if i == n:
            return tuple(steps)
        if text[i] != ".":
            raise ValueError(f"unexpected {text[i]!r} at character {i + 1}")
        i += 1


def path_text(path: tuple) -> str:
    """A concrete path as the loader's messages write it: ``objects[10].emission.luminance``."""
    out = ""
    for step in path:
        out += f"[{step}]" if isinstance(step, int) else (f".{step}" if out else step)
    return out


def lookup(data, steps) -> tuple[object, str | None]:
    """(value, None) at ``steps`` (from :func:`parse_field` without globs) in ``data``, or (None, why)."""
    node, done = data, ()
    for kind, arg in steps:
        here = path_text(done) or "the report"
        if kind == "key":
            if not isinstance(node, dict):
                return None, f"{here} is not a block"
            if arg not in node:
                return None, f"{here} has no field {arg!r}"
        else:
            if not isinstance(node, list) or not 0 <= arg < len(node):
                return None, f"{here} has no element [{arg}]"
        node, done = node[arg], (*done, arg)
    return node, None


#: Comparison operators of a requirement.
OPS = {">=": operator.ge, "<=": operator.le, ">": operator.gt, "<": operator.lt}


@dataclass(frozen=True)
class Requirement:
    """``KEY OP VALUE``: the number at ``key`` (a dotted path into a document) compared with ``value``."""

    text: str
    key: str
    steps: tuple
    op: str
    value: float

    def judge(self, report: dict) -> dict:
        """{"requirement", "value" (the figure, or None), "met", and "why" where it is not met}."""
        v, why = lookup(report, self.steps)
        if why is None and (isinstance(v, bool) or not isinstance(v, (int, float))):
            why = f"{self.key} is {json.dumps(v)[:40]}, not a number"
        if why is not None:
            return {"requirement": self.text, "value": None, "met": False, "why": why}
        met = bool(OPS[self.op](v, self.value))
        out = {"requirement": self.text, "value": v, "met": met}
        if not met:
            out["why"] = f"{self.key} is {v:.6g}"
        return out


_REQUIREMENT = re.compile(r"\s*(?P<key>[^\s<>=!]+)\s*(?P<op>>=|<=|==|=|!=|>|<)\s*(?P<value>[^\s<>=!]\S*)\s*")


def parse_requirement(text: str) -> Requirement:
    """``"KEY OP VALUE"`` (spaces optional) as a :class:`Requirement`. Raises ValueError saying what is
    malformed."""
    m = _REQUIREMENT.fullmatch(text) if isinstance(text, str) else None
    if not m:
        raise ValueError("expected \"KEY OP VALUE\", KEY a dotted path (hud.contrast_ratio), OP one of >= <= > <, "
                         "VALUE a number")
    key, op, value = m["key"], m["op"], m["value"]
    if op not in OPS:
        raise ValueError(f"OP {op!r}: must be one of {' '.join(OPS)}")
    try:
        steps = parse_field(key, globs=False)
    except ValueError as e:
        raise ValueError(f"KEY {key!r}: {e}") from None
    try:
        v = float(value)
    except ValueError:
        raise ValueError(f"VALUE must be a number, got {value!r}") from None
    if not math.isfinite(v):
        raise ValueError(f"VALUE must be finite, got {value!r}")
    return Requirement(f"{key} {op} {value}", key, steps, op, v)

