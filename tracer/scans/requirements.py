"""What a sweep reads off each run's report: its figures (every number of the report's HUD figures,
luminance, noise and cost: sweep.csv's columns) and its requirements, ``"KEY OP VALUE"`` with KEY a
dotted path into the report (``hud.contrast_ratio``), OP one of ``>= <= > <``, VALUE a number. A run
whose report lacks KEY, or holds no number there, fails the requirement, and sweep.json says why.
"""

from __future__ import annotations

import difflib
import json
import math
import operator
import re
from dataclasses import dataclass

from ..products.report import REPORT_SECTIONS
from .fields import SweepArgumentError, lookup, parse_field

#: Comparison operators of a requirement.
OPS = {">=": operator.ge, "<=": operator.le, ">": operator.gt, "<": operator.lt}


#: The parts of a report whose numeric leaves are a run's figures (sweep.csv's columns), in order.
FIGURES = ("hud", "luminance", "adaptation_luminance", "noise", "rays", "seconds", "efficiency")


def numeric_leaves(value, prefix: str) -> dict[str, int | float]:
    """Every number in ``value`` (nested blocks and lists) by its dotted key path; booleans, strings
    and nulls are left out."""
    out: dict[str, int | float] = {}
    if isinstance(value, bool) or value is None:
        return out
    if isinstance(value, (int, float)):
        out[prefix] = value
    elif isinstance(value, dict):
        for k, v in value.items():
            out |= numeric_leaves(v, f"{prefix}.{k}" if prefix else k)
    elif isinstance(value, list):
        for i, v in enumerate(value):
            out |= numeric_leaves(v, f"{prefix}[{i}]")
    return out


def run_figures(report: dict) -> dict[str, int | float]:
    """A run's figures (the columns of sweep.csv): every numeric leaf of the report's :data:`FIGURES`."""
    out: dict[str, int | float] = {}
    for key in FIGURES:
        out |= numeric_leaves(report.get(key), key)
    return out


# -- requirements -------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Requirement:
    """``KEY OP VALUE``: the figure at ``key`` (a dotted path into a run's report) compared with ``value``."""

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


def check_report_key(argument: str, steps) -> None:
    """A report key's first name must be a section of every report (tracer.products.report.REPORT_SECTIONS), so
    that a mistyped key is refused before the runs rather than found missing in each. (What lies below
    a section depends on the scene and the method: a run whose report lacks it fails the requirement.)
    Raises :class:`SweepArgumentError`."""
    name = steps[0][1]
    if name not in REPORT_SECTIONS:
        near = difflib.get_close_matches(name, REPORT_SECTIONS, n=1)
        hint = f"did you mean {near[0]!r}? " if near else ""
        raise SweepArgumentError(argument, f"{name!r} is not a section of a run's report.json ({hint}the sections "
                                           f"are: {', '.join(REPORT_SECTIONS)})")


_REQUIREMENT = re.compile(r"\s*(?P<key>[^\s<>=!]+)\s*(?P<op>>=|<=|==|=|!=|>|<)\s*(?P<value>[^\s<>=!]\S*)\s*")


def parse_requirement(text: str) -> Requirement:
    """``"KEY OP VALUE"`` (spaces optional) as a :class:`Requirement`. Raises :class:`SweepArgumentError`."""
    argument = f"--require {text}"
    m = _REQUIREMENT.fullmatch(text)
    if not m:
        raise SweepArgumentError(argument, "expected \"KEY OP VALUE\", KEY a dotted path into the report "
                                           "(hud.contrast_ratio), OP one of >= <= > <, VALUE a number")
    key, op, value = m["key"], m["op"], m["value"]
    if op not in OPS:
        raise SweepArgumentError(argument, f"OP {op!r}: must be one of {' '.join(OPS)}")
    try:
        steps = parse_field(key, globs=False)
    except ValueError as e:
        raise SweepArgumentError(argument, f"KEY {key!r}: {e}") from None
    check_report_key(argument, steps)
    try:
        v = float(value)
    except ValueError:
        raise SweepArgumentError(argument, f"VALUE must be a number, got {value!r}") from None
    if not math.isfinite(v):
        raise SweepArgumentError(argument, f"VALUE must be finite, got {value!r}")
    return Requirement(f"{key} {op} {value}", key, steps, op, v)
