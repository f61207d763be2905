"""The options of every light-transport method: scene.json's ``"methods": {"<name>": {...}}``.

They belong to the scene format, so that loading a scene validates them without importing a method
(tracer.methods registers a class for every name here; a test holds the two together). The Blender
add-on draws its method options from the same fields.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from ..core.schema import Field, parse_block
from ..core.validate import FieldChecker

#: The methods a channel of the hybrid method may be given, in the order its pilots try them.
CANDIDATES = ("backward", "forward", "photon")

#: The option every tracing method has.
MAX_DEPTH = Field("max_depth", "int", 32, minimum=1, maximum=1000, label="Max depth",
                  description="Longest path in ray segments; paths cut there are counted and reported")

EXIT_PUPIL = Field(
    "exit_pupil", "group", None, label="Exit pupil",
    description="Eq. (3) strata: a disk in the pupil plane that receives a share of the samples",
    fields=(Field("object", "object_ref", None, label="Object",
                  description="An object whose outline, projected along the gaze, is the exit pupil"),
            Field("center_mm", "vector2", None, unit="mm", minimum=-1e4, maximum=1e4, label="Centre",
                  description="Centre of the exit pupil in eye coordinates (right, up), mm"),
            Field("radius_mm", "number", None, unit="mm", minimum=0.0, exclusive_min=True, maximum=1e4, label="Radius",
                  description="Radius of the exit pupil, mm"),
            Field("share", "number", unit="1", minimum=0.0, maximum=1.0, label="Share",
                  description="Share of the samples sent into the exit pupil, below 1", ui_default=0.5)),
    alternatives=(("object",), ("center_mm", "radius_mm")))

PILOT_SHARE = Field("pilot_share", "number", 0.1, unit="1", minimum=0.01, maximum=0.5, label="Pilot share",
                    description="Share of the budget spent on the pilots that choose the methods (a time "
                                "budget whose share is under 2 s runs none: the rules choose)")


def _exit_pupil(ck: FieldChecker, opts: dict, fld: str, scene):
    """The exit pupil's share below 1, its object present; an object becomes the disk of its outline
    projected along the gaze onto the pupil plane (eye coordinates)."""
    ep = opts.get("exit_pupil")
    if ep is None:
        return
    f = f"{fld}.exit_pupil"
    if ep["share"] >= 1.0:
        ck.fail(f"{f}.share", "must be < 1: the rest of the pupil keeps samples (unbiasedness)")
    if "object" in ep:
        matches = [o for o in scene.objects if o.name == ep["object"]]
        if not matches:
            ck.fail(f"{f}.object", f"no object named {json.dumps(ep['object'])}")
        eye = scene.eye
        right = np.cross(eye.gaze, eye.up)
        right /= np.linalg.norm(right)
        upv = np.cross(right, eye.gaze)
        rel = matches[0].vertices - eye.position
        xy = np.stack([rel @ right, rel @ upv], axis=1)
        center = 0.5 * (xy.min(axis=0) + xy.max(axis=0))
        ep["center_mm"], ep["radius_mm"] = center, float(np.linalg.norm(xy - center, axis=1).max())


@dataclass(frozen=True)
class MethodOptions:
    """A method's block under ``methods``: its fields, and ``check(ck, options, field, scene)`` for what
    relates options to each other or to the scene (it may derive values)."""

    name: str
    fields: tuple[Field, ...]
    check: Callable[[FieldChecker, dict, str, object], None] | None = None

    def parse(self, ck: FieldChecker, block, fld: str, scene) -> dict:
        """The validated options of a JSON block (None: every default), errors naming ``fld``."""
        opts = parse_block(ck, block, fld, self.fields, scene.root)
        if self.check is not None:
            self.check(ck, opts, fld, scene)
        return opts


METHOD_OPTIONS: dict[str, MethodOptions] = {m.name: m for m in (
    MethodOptions("backward", (
        MAX_DEPTH,
        Field("next_event", "bool", True, label="Next-event estimation",
              description="Connect every non-specular vertex to the lights (off: the paper's plain method)"),
        Field("splits", "int", 3, minimum=0, maximum=8, label="Specular splits",
              description="At the first N glass surfaces or coatings of a camera path, follow both the "
                          "reflected and the transmitted branch with their weights instead of choosing one"),
        EXIT_PUPIL), _exit_pupil),
    MethodOptions("forward", (MAX_DEPTH,)),
    MethodOptions("photon", (
        MAX_DEPTH,
        Field("next_event", "bool", True, label="Next-event estimation",
              description="Connect visibility points to the lights they see directly (off: photons carry "
                          "the direct light too)"),
        Field("splits", "int", 3, minimum=0, maximum=8, label="Specular splits",
              description="At the first N glass surfaces or coatings of an eye path, follow both branches"),
        Field("radius_mm", "number", 0.0, unit="mm", minimum=0.0, maximum=1e4, label="Initial radius",
              description="Gather radius of the first batch, mm; 0: automatic (1.5 pixel footprints on the "
                          "surface in view)"),
        Field("alpha", "number", 2.0 / 3.0, unit="1", minimum=0.0, exclusive_min=True, maximum=1.0,
              label="Radius reduction",
              description="Knaus-Zwicker alpha: the radius^2 shrinks as batches^(alpha - 1); 1 keeps it"))),
    MethodOptions("hybrid", (
        Field("hud_method", "choice", "auto", choices=("auto",) + CANDIDATES, label="HUD channel",
              description="Method of the channel of light from the scene's emitters (auto: chosen by pilots, "
                          "or by rules on a budget too short for them)"),
        Field("environment_method", "choice", "auto", choices=("auto", "backward"), label="Environment channel",
              description="Method of the channel of light from the environment (auto: chosen by pilots, or by "
                          "rules on a budget too short for them)"),
        PILOT_SHARE)),
    MethodOptions("auto", (PILOT_SHARE,)),
)}


def parse_methods(ck: FieldChecker, raw: dict, scene) -> dict[str, dict]:
    """The "methods" block (and the top-level "forward" and "backward" blocks of earlier files), each
    validated by its method's options."""
    blocks = dict(ck.obj(raw["methods"], "methods")) if "methods" in raw else {}
    fields = {name: f"methods.{name}" for name in blocks}
    for legacy in ("forward", "backward"):
        if legacy in raw:
            if legacy in blocks:
                ck.fail(legacy, f'give the options once, under "methods.{legacy}"')
            blocks[legacy], fields[legacy] = raw[legacy], legacy
    out = {}
    for name, block in blocks.items():
        if name not in METHOD_OPTIONS:
            ck.fail(fields[name], f"unknown method (known: {', '.join(METHOD_OPTIONS)})")
        out[name] = METHOD_OPTIONS[name].parse(ck, block, fields[name], scene)
    return out
