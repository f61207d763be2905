"""Blender's units and the tracer's: lengths in mm, angles in degrees.

The tracer's scene format is in millimetres; a Blender unit is ``scale_length`` metres (Scene > Units).
Values the add-on stores for the tracer keep the tracer's units (a .blend keeps meaning the same
whatever its unit settings), and each has a twin that Blender shows in its own unit system (a length
in the scene's length unit, an angle in its rotation unit), which the panels draw: reading the twin
converts the stored value, setting it converts back.
"""

from __future__ import annotations

import math

import bpy
from bpy.props import FloatProperty, FloatVectorProperty

#: Metres to millimetres.
M_TO_MM = 1000.0
#: Name of the twin that Blender shows in its own units.
SHOWN = "{}_shown"


def unit_mm(scene) -> float:
    """Millimetres per Blender unit of ``scene``."""
    return M_TO_MM * scene.unit_settings.scale_length


def _mm_per_unit() -> float:
    scene = bpy.context.scene
    return unit_mm(scene) if scene is not None else M_TO_MM


def declared_default(owner, name: str):
    """The default that ``owner``'s property ``name`` declares (a tuple for an array)."""
    prop = owner.bl_rna.properties[name]
    return tuple(prop.default_array) if prop.is_array else prop.default


def starting_value(owner, stored: str):
    """The value ``owner``'s property ``stored`` starts from: the owner's own ``starting_value(stored)``
    where it has one and gives one (an object's optical role: a coating's Reflectance is 0.25, where the
    property that every role shares declares the mirror's 0.9), else the property's declared default."""
    own = getattr(owner, "starting_value", None)
    value = own(stored) if own is not None else None
    return declared_default(owner, stored) if value is None else value


def _twin(stored: str, size: int, to_shown, from_shown, **kw):
    """A property whose value is ``to_shown(stored value)`` and which stores ``from_shown(value)``.

    Its declared default is NaN, and a NaN set on it (or on one of its components) puts the stored
    value's starting value there (:func:`starting_value`): Blender's Reset to Default Value sets a
    property's declared default, which a twin cannot know (a length's depends on the scene's unit), and a
    default of 0 had set a pupil of 0.01 mm and an eye of 0.1 mm focal length."""
    if size:
        def get(self):
            return tuple(to_shown(v) for v in getattr(self, stored))

        def set_(self, value):
            start = starting_value(self, stored) if any(math.isnan(v) for v in value) else None
            setattr(self, stored, tuple(start[i] if math.isnan(v) else from_shown(v) for i, v in enumerate(value)))

        return FloatVectorProperty(size=size, get=get, set=set_, default=(math.nan,) * size, **kw)

    def get1(self):
        return to_shown(getattr(self, stored))

    def set1(self, value):
        setattr(self, stored, starting_value(self, stored) if math.isnan(value) else from_shown(value))

    return FloatProperty(get=get1, set=set1, default=math.nan, **kw)


def length_twin(stored: str, name: str, description: str, size: int = 0, nonnegative: bool = False):
    """The twin of a length stored in mm, shown in the scene's length unit (the stored property keeps
    its own bounds, in mm, and clamps to them)."""
    kw = {"name": name, "description": description, "unit": "LENGTH",
          "subtype": "TRANSLATION" if size else "DISTANCE"}
    if nonnegative:
        kw["min"] = 0.0
    return _twin(stored, size, lambda v: v / _mm_per_unit(), lambda v: v * _mm_per_unit(), **kw)


def angle_twin(stored: str, name: str, description: str, size: int = 0):
    """The twin of an angle stored in degrees, shown in the scene's rotation unit."""
    kw = {"name": name, "description": description, "unit": "ROTATION", "subtype": "EULER" if size else "ANGLE"}
    return _twin(stored, size, math.radians, math.degrees, **kw)
