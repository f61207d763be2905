"""The tracer's schemas (tracer/core/schema.py) turned into Blender properties, panel rows, scene.json blocks
and back: the one place where a field of a material, of the emission block or of a method's options
becomes something a user sets in Blender. A new material or method option appears here without any
change in the add-on.

A block of fields lives on a PropertyGroup under a name prefix ("" for materials, "emission_" for the
emission block, "<method>_" for a method's options). Per field ``f``: the property ``prefix + f.name``;
for a group: ``prefix + group + "_use"`` (whether it is given) and its fields under
``prefix + group + "_"``; for alternatives (exactly one set of fields given): an enum
``prefix + "by"`` whose items are the first field of each set.
"""

from __future__ import annotations

import math
from pathlib import Path

import bpy
import numpy as np
from bpy.props import (
    BoolProperty,
    EnumProperty,
    FloatProperty,
    FloatVectorProperty,
    IntProperty,
    PointerProperty,
    StringProperty,
)

from ..tracer.core.schema import REQUIRED, Field, to_json
from .units import SHOWN, angle_twin, length_twin, starting_value

#: Field kinds with one value (size 0) or two.
_SIZES = {"number": 0, "pair": 2, "vector2": 2}
#: A factor's twins (a reflectance or transmittance given per colour channel, in [0, 1]): one number for
#: its three channels (what a panel shows by default: a reflectance of 0.04 is a number, not a swatch),
#: and whether the channels are given apart. A colour (an emitter's) stays a swatch.
GREY = "{}_grey"
PER_CHANNEL = "{}_per_channel"


def _factor(f: Field) -> bool:
    """Whether ``f`` is a factor given per colour channel (an RGB field bounded by 1)."""
    return f.kind == "rgb" and f.maximum == 1.0


def grey_twin(stored: str, f: Field):
    """The number that sets R, G and B of the factor property ``stored`` at once (it reads their mean:
    the value itself while they are equal). Its declared default is NaN, which puts the stored value's
    starting value back (Reset to Default Value; hud_addon.units.starting_value): a default of 0 had made
    a mirror black."""
    def get(self):
        return float(sum(getattr(self, stored))) / 3.0

    def set_(self, value):
        setattr(self, stored, starting_value(self, stored) if math.isnan(value) else (value,) * 3)

    return FloatProperty(name=f.title, description=_tooltip(f) + " The same for R, G and B (the colour "
                         "button beside it gives them apart)", min=f.minimum or 0.0, max=f.maximum, precision=4,
                         get=get, set=set_, default=math.nan)


def twin(f: Field, name: str):
    """The property Blender shows for a field in mm or degrees (hud_addon/units.py), or None."""
    if f.kind in _SIZES and f.unit == "mm":
        return length_twin(name, f.title, _tooltip(f), _SIZES[f.kind], nonnegative=(f.minimum or 0) >= 0)
    if f.kind in _SIZES and f.unit == "deg":
        return angle_twin(name, f.title, _tooltip(f), _SIZES[f.kind])
    return None


def _tooltip(f: Field) -> str:
    unit = f" Unit: {f.unit}." if f.unit not in ("", "1") else ""
    return f"{f.description}.{unit}" if f.description else unit.strip()


def _default(f: Field):
    d = f.ui_default if f.default in (REQUIRED, None) else f.default
    return d


def starting_values(fields, prefix: str = "") -> dict[str, object]:
    """{property name: value} that a block's numbers and colours start from in a panel (the field's
    default, else the value a user interface starts from), its groups' fields included."""
    out: dict[str, object] = {}
    for f in fields:
        if f.kind == "group":
            out |= starting_values(f.fields, f"{prefix}{f.name}_")
        elif f.kind in ("rgb", "number") and (d := _default(f)) is not None:
            out[prefix + f.name] = tuple(float(x) for x in d) if isinstance(d, list | tuple) else \
                ((float(d),) * 3 if f.kind == "rgb" else float(d))
    return out


def prop(f: Field):
    """The Blender property of one field (kinds of tracer.core.schema)."""
    d = _default(f)
    common = {"name": f.title, "description": _tooltip(f)}
    lo = -1e30 if f.minimum is None else f.minimum
    hi = 1e30 if f.maximum is None else f.maximum
    if f.kind == "rgb":
        v = (float(d),) * 3 if not isinstance(d, list | tuple) else tuple(float(x) for x in d)
        return FloatVectorProperty(subtype="COLOR", size=3, min=lo, max=hi, default=v if d is not None else (0.9,) * 3,
                                   **common)
    if f.kind in ("pair", "vector2"):
        v = (0.0, 0.0) if d is None else ((float(d),) * 2 if not isinstance(d, list | tuple) else tuple(map(float, d)))
        return FloatVectorProperty(size=2, min=lo, max=hi, default=v, **common)
    if f.kind == "number":
        return FloatProperty(min=lo, max=hi, default=float(d if d is not None else max(lo, 0.0)), precision=4, **common)
    if f.kind == "int":
        return IntProperty(min=int(max(lo, -2**31)), max=int(min(hi, 2**31 - 1)), default=int(d or 0), **common)
    if f.kind == "bool":
        return BoolProperty(default=bool(d), **common)
    if f.kind == "choice":
        return EnumProperty(items=[(c, c.capitalize(), "") for c in f.choices], default=d or f.choices[0], **common)
    if f.kind == "image":
        return PointerProperty(type=bpy.types.Image, **common)
    if f.kind == "object_ref":
        return PointerProperty(type=bpy.types.Object, **common)
    if f.kind == "string":
        return StringProperty(default=d or "", **common)
    raise ValueError(f.kind)


def _alternative_enum(alternatives, fields, label: str):
    by_name = {f.name: f for f in fields}
    items = [(alt[0], " + ".join(by_name[k].title for k in alt), "") for alt in alternatives]
    return EnumProperty(name=label, items=items, description="Which of the alternative fields to give")


def annotations(fields: tuple[Field, ...], prefix: str = "", alternatives=(), seen: dict | None = None) -> dict:
    """The properties of a block (module docstring). ``seen`` shares properties by name across blocks
    (materials: one "reflectance" for every material that has one)."""
    out = {} if seen is None else seen
    for f in fields:
        if f.kind == "group":
            out[f"{prefix}{f.name}_use"] = BoolProperty(name=f.title, description=_tooltip(f))
            annotations(f.fields, f"{prefix}{f.name}_", f.alternatives, out)
        else:
            out.setdefault(prefix + f.name, prop(f))
            shown = twin(f, prefix + f.name)
            if shown is not None:
                out.setdefault(SHOWN.format(prefix + f.name), shown)
            if _factor(f):
                out.setdefault(GREY.format(prefix + f.name), grey_twin(prefix + f.name, f))
                out.setdefault(PER_CHANNEL.format(prefix + f.name), BoolProperty(
                    name="Per channel", description=f"Give {f.title}'s R, G and B apart (a tinted glass, a "
                                                    "coloured coating)"))
    if alternatives:
        by = _alternative_enum(alternatives, fields, "Given by")
        if f"{prefix}by" in out and out[f"{prefix}by"].keywords["items"] != by.keywords["items"]:
            # Blocks that share their properties by name (materials) share this enum too: two different
            # sets of alternatives under one prefix would silently export the wrong fields of one of them.
            raise ValueError(f"{prefix}by: two blocks under the prefix {prefix!r} have different alternatives "
                             f"({out[f'{prefix}by'].keywords['items']} and {by.keywords['items']})")
        out.setdefault(f"{prefix}by", by)
    return out


def _active(fields, prefix, alternatives, owner):
    """The fields of a block that are in use: all but the alternative sets not chosen."""
    if not alternatives:
        return list(fields)
    chosen = getattr(owner, f"{prefix}by")
    unused = {k for alt in alternatives if alt[0] != chosen for k in alt}
    return [f for f in fields if f.name not in unused]


def draw(layout, owner, fields, prefix: str = "", alternatives=()):
    """Panel rows of a block."""
    if alternatives:
        layout.prop(owner, f"{prefix}by")
    for f in _active(fields, prefix, alternatives, owner):
        if f.kind == "group":
            layout.prop(owner, f"{prefix}{f.name}_use")
            if getattr(owner, f"{prefix}{f.name}_use"):
                box = layout.box()
                draw(box, owner, f.fields, f"{prefix}{f.name}_", f.alternatives)
        elif f.kind == "image":
            layout.template_ID(owner, prefix + f.name, open="image.open")
        elif _encoding_field(f, fields):
            image = getattr(owner, prefix + f.name[: -len("_encoding")])
            layout.label(text=f"{f.title}: from the image's Color Space"
                              + (f" ({image.colorspace_settings.name})" if image is not None else ""))
        else:
            shown = SHOWN.format(prefix + f.name)
            unit = f" ({f.unit.replace('^2', '²')})" if f.unit not in ("", "1") else ""
            if shown in owner.bl_rna.properties:  # a length or angle, shown in the scene's own units
                layout.prop(owner, shown)
            elif _factor(f):  # one number, or R, G and B where the colour button is pressed
                row = layout.row(align=True)
                apart = getattr(owner, PER_CHANNEL.format(prefix + f.name))
                row.prop(owner, prefix + f.name if apart else GREY.format(prefix + f.name), text=f"{f.title}{unit}")
                row.prop(owner, PER_CHANNEL.format(prefix + f.name), text="", icon="COLOR")
            else:  # the unit beside the name (cd/m^2, lm, mrad ...), not only in the tooltip
                layout.prop(owner, prefix + f.name, text=f"{f.title}{unit}")


#: Blender colour spaces whose byte values the tracer reads as sRGB-encoded, and those it reads as they
#: are (linear transmittance). Float images are linear in Blender whatever their colour space.
SRGB_SPACES = frozenset({"sRGB"})
LINEAR_SPACES = frozenset({"Non-Color", "Linear Rec.709", "Linear", "Raw", "Linear CIE-XYZ E", "Linear CIE-XYZ D65"})


def _encoding_field(f: Field, fields) -> bool:
    """Whether ``f`` is the encoding of a sibling image field (tracer.core.schema's ``<name>_encoding``)."""
    return f.kind == "choice" and f.name.endswith("_encoding") and any(
        g.kind == "image" and f.name == f"{g.name}_encoding" for g in fields)


def image_encoding(image, title: str) -> str:
    """How the tracer decodes ``image``'s values, from Blender's own setting of it:
    a float image holds linear values; a byte image's Color Space says sRGB or linear. Raises
    ValueError naming the image for a colour space the tracer cannot read a transmittance from."""
    space = image.colorspace_settings.name
    if image.is_float or space in LINEAR_SPACES:
        return "linear"
    if space in SRGB_SPACES:
        return "srgb"
    raise ValueError(f"{title}: image {image.name!r} has the Color Space {space!r}; a slide's values are "
                     "transmittances: set it to sRGB (8-bit values sRGB-encoded) or Non-Color (linear)")


def export(owner, fields, prefix: str = "", alternatives=(), save_image=None) -> dict:
    """The scene.json block of a block's properties. ``save_image(image, field)`` writes an image into
    the scene folder and returns its relative path."""
    out: dict = {}
    for f in _active(fields, prefix, alternatives, owner):
        value = getattr(owner, prefix + f.name) if f.kind != "group" else None
        if f.kind == "group":
            if getattr(owner, f"{prefix}{f.name}_use"):
                try:
                    out[f.name] = export(owner, f.fields, f"{prefix}{f.name}_", f.alternatives, save_image)
                except ValueError as e:  # the group's title in front, as the panel nests it
                    raise ValueError(f"{f.title} > {e}") from None
        elif f.kind == "image":
            if value is None:
                raise ValueError(f"{f.title}: choose an image")
            out[f.name] = save_image(value, f)
        elif f.kind == "object_ref":
            if value is None:
                raise ValueError(f"{f.title}: choose an object")
            out[f.name] = value.name
        elif _encoding_field(f, fields):
            image = getattr(owner, prefix + f.name[: -len("_encoding")])
            if image is not None:
                out[f.name] = image_encoding(image, next(g.title for g in fields if f.name == f"{g.name}_encoding"))
        elif f.kind in ("rgb", "pair", "vector2"):
            out[f.name] = to_json(f, np.array(value))
        else:
            out[f.name] = to_json(f, value)
    return out


def apply(owner, fields, spec: dict, prefix: str = "", alternatives=(), root: Path | None = None, objects=None):
    """Set a block's properties from its scene.json form ``spec`` (what "Add HUD Preset" builds).
    Images are loaded from ``root`` and packed; object references are looked up in ``objects``.

    A field the block does not give takes its own default where it has one: materials share their
    properties by name, so the property may hold another material's default (hud-screen's screen, a
    Lambertian transmitter without a reflectance, kept the Lambertian reflector's, and its export was
    refused: reflectance + transmittance above 1)."""
    if alternatives:
        for alt in alternatives:
            if any(k in spec for k in alt):
                setattr(owner, f"{prefix}by", alt[0])
    for f in fields:
        if f.name in spec:
            value = spec[f.name]
        elif f.kind not in ("group", "image", "object_ref") and f.default not in (REQUIRED, None):
            value = f.default
        else:
            continue
        name = prefix + f.name
        if f.kind == "group":
            if value is None:  # an optional group given as null: not given
                continue
            setattr(owner, f"{name}_use", True)
            apply(owner, f.fields, value, f"{name}_", f.alternatives, root, objects)
        elif f.kind == "image":
            img = bpy.data.images.load(str(Path(root) / value), check_existing=False)
            img.pack()
            if not img.is_float and f"{f.name}_encoding" in {g.name for g in fields}:
                linear = spec.get(f"{f.name}_encoding", "srgb") == "linear"
                img.colorspace_settings.name = "Non-Color" if linear else "sRGB"
            setattr(owner, name, img)
        elif f.kind == "object_ref":
            setattr(owner, name, objects[value])
        elif f.kind == "rgb":
            rgb = (float(value),) * 3 if not isinstance(value, list) else tuple(map(float, value))
            setattr(owner, name, rgb)
            if _factor(f):
                setattr(owner, PER_CHANNEL.format(name), len(set(rgb)) > 1)
        elif f.kind == "pair":
            setattr(owner, name, (float(value),) * 2 if not isinstance(value, list) else tuple(map(float, value)))
        elif f.kind == "vector2":
            setattr(owner, name, tuple(map(float, value)))
        else:
            setattr(owner, name, value)
