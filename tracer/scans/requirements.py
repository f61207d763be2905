"""What a sweep reads off each run's report: its figures (every number of the report's HUD figures,
luminance, noise and cost: sweep.csv's columns) and its requirements, ``"KEY OP VALUE"`` with KEY a
dotted path into the report (``hud.contrast_ratio``), OP one of ``>= <= > <``, VALUE a number. A run
whose report lacks KEY, or holds no number there, fails the requirement, and sweep.json says why.
"""

from __future__ import annotations

import difflib

from ..analysis.hud import HUD_KEYS, SPOT_KEYS
from ..core.jsonpath import Requirement
from ..core.jsonpath import parse_requirement as parse_text
from ..products.report import REPORT_SECTIONS
from .fields import SweepArgumentError

#: The parts of a report whose numeric leaves are a run's figures (sweep.csv's columns), in order.
FIGURES = ("hud", "optics", "luminance", "adaptation_luminance", "noise", "rays", "seconds", "efficiency")


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
def check_report_key(argument: str, steps, optics_only: bool = False) -> None:
    """A report key's first name must be a section of every report (tracer.products.report.REPORT_SECTIONS), so
    that a mistyped key is refused before the runs rather than found missing in each; below ``optics``,
    ``design_eye`` and ``eyebox`` must name a metric of the optical analysis
    (tracer.analysis.optics.REQUIREMENT_KEYS). ``optics_only`` (a sweep of the optical analysis alone):
    the key must lie in ``optics``. (What lies below a section depends on the scene and the method: a
    run whose report lacks it fails the requirement.) Raises :class:`SweepArgumentError`."""
    from ..analysis.optics import OpticsError, check_metric

    name = steps[0][1]
    if optics_only and name != "optics":
        raise SweepArgumentError(argument, "a sweep of the optical analysis (--optics) reads optics.* only "
                                           "(optics.design_eye.ghost_separation_arcmin)")
    if name not in REPORT_SECTIONS:
        near = difflib.get_close_matches(name, REPORT_SECTIONS, n=1)
        hint = f"did you mean {near[0]!r}? " if near else ""
        raise SweepArgumentError(argument, f"{name!r} is not a section of a run's report.json ({hint}the sections "
                                           f"are: {', '.join(REPORT_SECTIONS)})")
    names = [arg for _, arg in steps[1:]]
    if name == "hud" and names:
        for known, key in ((HUD_KEYS, names[0]), (SPOT_KEYS, names[1] if names[0] == "spot" and len(names) > 1
                                                  else None)):
            if key is not None and key not in known:
                near = difflib.get_close_matches(key, known, n=1)
                hint = f" (did you mean {near[0]!r}?)" if near else ""
                raise SweepArgumentError(argument, f"the HUD figures have no {key!r}{hint}; they are: "
                                                   f"{', '.join(known)}")
    if name == "optics" and names and names[0] in ("design_eye", "eyebox"):
        try:
            check_metric(names, name)
        except OpticsError as e:
            raise SweepArgumentError(argument, str(e)) from None


def parse_requirement(text: str, optics_only: bool = False) -> Requirement:
    """``"KEY OP VALUE"`` (spaces optional) as a :class:`Requirement` on a run's report
    (:func:`check_report_key`). Raises :class:`SweepArgumentError`."""
    argument = f"--require {text}"
    try:
        req = parse_text(text)
    except ValueError as e:
        raise SweepArgumentError(argument, str(e).replace("(hud.contrast_ratio)", "into the report "
                                                          "(hud.contrast_ratio)")) from None
    check_report_key(argument, req.steps, optics_only)
    return req
