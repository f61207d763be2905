"""The "environment" block of scene.json: the environment it describes, validated field by field
against :data:`tracer.scene.format.ENVIRONMENTS` and :data:`tracer.scene.format.SUN`."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from ..core.errors import ImageReadError, SceneError
from ..core.imageio import read_image
from ..core.schema import number_field
from ..core.units import Y_WEIGHTS
from ..core.validate import MAX_ABS, MAX_LUMINANCE, MIN_LUMINANCE, FieldChecker
from ..sources.environment import (
    CALIBRATION_MODES,
    Environment,
    HdriEnvironment,
    NoEnvironment,
    UniformEnvironment,
    panorama_rgb,
)
from ..sources.sun import EnvironmentWithSun, Sun
from .format import ENVIRONMENTS, SUN


def _check_luminous(ck, rgb: np.ndarray, fld: str):
    """Refuse a colour whose luminance is not positive (black, or so dark that it is 0 in floating
    point): it is normalised to unit luminance (tracer.core.units.normalize_color)."""
    if not float(rgb @ Y_WEIGHTS) > 0.0:
        ck.fail(fld, "must have a positive luminance (0.2126 R + 0.7152 G + 0.0722 B): it is black, or so dark that "
                     "its luminance is 0 in floating point")


def _colour(ck: FieldChecker, schema, spec: dict, block: str) -> np.ndarray:
    f = schema.field("color")
    rgb = ck.rgb(spec.get("color", f.default), f"{block}.color", max_value=f.maximum)
    _check_luminous(ck, rgb, f"{block}.color")
    return rgb


def _sun_from_spec(ck: FieldChecker, spec) -> Sun:
    """The :class:`Sun` of an environment's "sun" block, validated field by field."""
    block = "environment.sun"
    ck.obj(spec, block)
    ck.keys(spec, block, *SUN.keys)
    direction = ck.unit_vector(spec["direction"], f"{block}.direction")
    e = number_field(ck, SUN.field("illuminance_lux"), spec, block)
    diameter = number_field(ck, SUN.field("angular_diameter_deg"), spec, block)
    sun = Sun(direction, e, diameter, _colour(ck, SUN, spec, block))
    if not sun.luminance_cd_m2 <= MAX_LUMINANCE:
        ck.fail(block, f"illuminance_lux {e:g} over a disk of {diameter:g} deg gives it a luminance of "
                       f"{sun.luminance_cd_m2:.3g} cd/m^2 (E / (pi sin^2(diameter / 2))), above {MAX_LUMINANCE:g}: "
                       "give a larger angular_diameter_deg or a smaller illuminance")
    if 0 < sun.luminance_cd_m2 < MIN_LUMINANCE:
        ck.fail(f"{block}.illuminance_lux", f"{e:.3g} lx gives the sun's disk a luminance of "
                                            f"{sun.luminance_cd_m2:.3g} cd/m^2, below {MIN_LUMINANCE:g} (give 0 for "
                                            "no sun)")
    return sun


def environment_from_spec(spec: dict, scene_dir: Path, file: str = "scene.json",
                          allow_external: bool = False) -> Environment:
    """The environment described by the "environment" block of scene.json (its fields:
    :data:`tracer.scene.format.ENVIRONMENTS` by ``type``, each with an optional ``sun``,
    :data:`tracer.scene.format.SUN`). The image file is relative to ``scene_dir`` and read with
    :func:`tracer.core.imageio.read_image` (float files as stored, integer files sRGB-decoded; 1
    channel: grey; 2: grey and alpha; 3: RGB; 4: RGBA; alpha is dropped).

    Raises
    ------
    SceneError
        With field ``environment.<field>`` for an unknown type, an unknown, missing, negative or
        non-numeric field, a black colour (``environment.sun.<field>`` for those of the sun;
        ``environment.sun`` for a disk brighter than 1e12 cd/m^2); with field ``environment.file`` for
        an image that is missing, unreadable, with more than 4 channels, with negative or non-finite
        pixels, black with calibration "mean" or "max", or with a black pixel with calibration "min".
    """
    ck = FieldChecker(file, allow_external)
    ck.obj(spec, "environment")
    if "type" not in spec:
        ck.fail("environment.type", "missing required field")
    kind = spec["type"]
    if not isinstance(kind, str) or kind not in ENVIRONMENTS:
        ck.fail("environment.type", f"unknown type {json.dumps(kind)[:40]} (known: {', '.join(ENVIRONMENTS)})")
    required, optional = ENVIRONMENTS[kind].keys
    ck.keys(spec, "environment", required | {"type"}, optional)
    sun = _sun_from_spec(ck, spec["sun"]) if "sun" in spec else None
    base = _base_from_spec(ck, kind, spec, scene_dir, file)
    return base if sun is None else EnvironmentWithSun(base, sun)


def _base_from_spec(ck: FieldChecker, kind: str, spec: dict, scene_dir: Path, file: str) -> Environment:
    """The environment of a block whose fields are known to be those of ``kind``, without its sun."""
    schema = ENVIRONMENTS[kind]
    if kind == "none":
        return NoEnvironment()

    if kind == "uniform":
        L = number_field(ck, schema.field("luminance"), spec, "environment")
        if 0 < L < MIN_LUMINANCE:
            ck.fail("environment.luminance", f"{L:.3g} cd/m^2 is below {MIN_LUMINANCE:g} (give 0 for no light)")
        return UniformEnvironment(L, _colour(ck, schema, spec, "environment"))

    image_file = ck.string(spec["file"], "environment.file")
    calibration = schema.field("calibration")
    cal = ck.obj(spec["calibration"], "environment.calibration")
    ck.keys(cal, "environment.calibration", {f.name for f in calibration.fields}, set())
    mode = cal["mode"]
    if not isinstance(mode, str) or mode not in CALIBRATION_MODES:
        ck.fail("environment.calibration.mode", f"unknown mode {json.dumps(mode)[:40]} (known: "
                                                f"{', '.join(CALIBRATION_MODES)})")
    value_field = next(f for f in calibration.fields if f.name == "value")
    value = ck.number(cal["value"], "environment.calibration.value", min_value=value_field.minimum,
                      min_exclusive=value_field.exclusive_min,
                      max_value=MAX_ABS if mode == "scale" else value_field.maximum)
    rotation = number_field(ck, schema.field("rotation_deg"), spec, "environment")

    try:
        pixels = read_image(ck.path(scene_dir, image_file, "environment.file"))
    except ImageReadError as exc:
        raise SceneError(file, "environment.file", f"cannot read {image_file!r}: {exc.reason}") from exc
    try:
        env = HdriEnvironment(panorama_rgb(pixels), mode, value, rotation, source=image_file)
    except ValueError as exc:
        raise SceneError(file, "environment.file", f"{image_file!r}: {exc}") from exc
    if not env.max_luminance <= MAX_LUMINANCE:
        ck.fail("environment.calibration.value", f"makes the panorama's brightest pixel {env.max_luminance!r} "
                                                 f"cd/m^2, above {MAX_LUMINANCE:g}")
    if 0 < env.max_luminance < MIN_LUMINANCE:
        ck.fail("environment.calibration.value", f"makes the panorama's brightest pixel {env.max_luminance:.3g} "
                                                 f"cd/m^2, below {MIN_LUMINANCE:g}")
    return env
