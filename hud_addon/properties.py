"""Property groups: Scene.hud (render settings and every method's options), Object.hud (optical role,
the material's fields, emission), Camera.hud (eye), World.hud (environment). One PointerProperty per
datablock type. The fields of materials, of the emission block and of the methods' options come from
the tracer's schemas (hud_addon/schema_ui.py), so a new material or option needs no change here."""

import bpy
from bpy.props import (
    BoolProperty,
    EnumProperty,
    FloatProperty,
    FloatVectorProperty,
    IntProperty,
    PointerProperty,
)

from ..tracer.integrators import DEFAULT_METHOD, INTEGRATORS
from ..tracer.lights import EMISSION
from ..tracer.optics.materials import MATERIALS
from ..tracer.schema import check_consistent
from .schema_ui import annotations


def _method_items(self, context):
    # Read from the tracer's registry: later methods appear here by themselves (the tracer's default
    # first, so that it is the property's default).
    names = sorted(INTEGRATORS, key=lambda n: (n != DEFAULT_METHOD, n))
    return [(name, name.capitalize(), INTEGRATORS[name].summary) for name in names]


ROLE_ITEMS = [("none", "None", "Not exported to the tracer")] + [
    (name, cls.schema.label, cls.schema.description) for name, cls in MATERIALS.items()]


def _aim(prefix: str, name: str = "Aim",
         description: str = "Directed sampling for the forward method (paper sec. 2)") -> dict:
    """The paper's directed split (sec. 2) of a scattering material or of an emission; with prefix
    "light_", the guidance of eye paths toward the aperture through which a surface's light arrives."""
    return {
        f"{prefix}aim": EnumProperty(name=name, items=[("NONE", "None", "No directed sampling"),
                                                       ("EYE", "Eye pupil", "Aim at the eye pupil"),
                                                       ("OBJECT", "Object", "Aim at a planar object")],
                                     default="NONE", description=description),
        f"{prefix}aim_object": PointerProperty(name="Aim at", type=bpy.types.Object,
                                               description="A planar object: an aperture, a window, the LCD"),
        f"{prefix}aim_share": FloatProperty(name="Share", default=0.5, min=0.0, max=0.99,
                                            description="Share of the samples drawn toward the target, below 1"),
        f"{prefix}aim_mode": EnumProperty(name="Mode", items=[("toward", "Toward", "Directions toward the target"),
                                                              ("away", "Away",
                                                               "As if coming from a virtual target behind")],
                                          description="Toward the target, or away from its virtual image behind"),
    }


def _scene_annotations() -> dict:
    ann = {
        "method": EnumProperty(name="Method", items=_method_items, description="Light-transport method"),
        "budget": EnumProperty(name="Budget", items=[("SECONDS", "Seconds", "Wall-clock time"),
                                                     ("RAYS", "Rays", "Traced ray segments")], default="SECONDS",
                               description="Stop after a time or a number of traced ray segments"),
        "seconds": FloatProperty(name="Seconds", default=10.0, min=0.01, description="Render time, s"),
        "rays": IntProperty(name="Rays", default=10_000_000, min=1, description="Ray segments to trace"),
        "seed": IntProperty(name="Seed", default=0, min=0, description="Seed of the random streams"),
    }
    for name, cls in INTEGRATORS.items():
        annotations(cls.options, f"{name}_", seen=ann)
    return ann


def _object_annotations() -> dict:
    check_consistent([cls.schema for cls in MATERIALS.values()])
    ann = {
        "role": EnumProperty(name="Optical role", items=ROLE_ITEMS, default="none",
                             description="The tracer material of this object"),
        "smooth_normals": BoolProperty(name="Smooth normals", default=False,
                                       description="Interpolate vertex normals (curved mirrors and lenses)"),
        "emits": BoolProperty(name="Emits light", default=False,
                              description="The object is also a Lambertian light source (any material can emit)"),
    }
    for cls in MATERIALS.values():
        annotations(cls.schema.fields, "", cls.schema.alternatives, ann)
    ann |= _aim("")
    ann |= _aim("light_", "Light aim", "Guidance of eye paths (backward method) toward the aperture through which "
                                       "this surface's light arrives, e.g. a condenser's face")
    annotations(EMISSION.fields, "emission_", EMISSION.alternatives, ann)
    ann |= _aim("emission_")
    return ann


HudSceneSettings = type("HudSceneSettings", (bpy.types.PropertyGroup,), {"__annotations__": _scene_annotations()})
HudObjectSettings = type("HudObjectSettings", (bpy.types.PropertyGroup,), {"__annotations__": _object_annotations()})


class HudCameraSettings(bpy.types.PropertyGroup):
    pupil: EnumProperty(name="Pupil", items=[("FIXED", "Fixed", "A given diameter"),
                                             ("AUTO", "From adaptation", "Watson & Yellott 2012 from the "
                                              "adaptation luminance")], default="FIXED",
                        description="A fixed pupil or one that follows the adaptation luminance")
    pupil_diameter_mm: FloatProperty(name="Pupil, mm", default=4.0, min=0.01, description="Pupil diameter, mm")
    adaptation_luminance: FloatProperty(
        name="Adaptation, cd/m²", default=0.0, min=0.0,
        description="Luminance the eye is adapted to, cd/m^2; 0: the environment's mean")
    observer_age: FloatProperty(name="Age, years", default=30.0, min=1.0, max=120.0,
                                description="Observer's age (Watson & Yellott's age term), years")
    focal_length_mm: FloatProperty(name="Eye focal length, mm", default=16.67, min=0.1,
                                   description="Focal length of the thin-lens eye, mm (16.67: Emsley's reduced eye)")
    accommodation_distance_mm: FloatProperty(name="Accommodation, mm", default=2500.0, min=0.0,
                                             description="Focus distance, mm; 0 means infinity")


class HudWorldSettings(bpy.types.PropertyGroup):
    kind: EnumProperty(name="Environment", items=[("none", "None", "Black"), ("uniform", "Uniform", "One luminance"),
                                                  ("hdri", "HDRI panorama", "An equirectangular panorama")],
                       default="none", description="What rays that leave the scene see")
    luminance: FloatProperty(name="Luminance, cd/m²", default=100.0, min=0.0, description="Uniform luminance, cd/m^2")
    color: FloatVectorProperty(name="Color", subtype="COLOR", size=3, min=0, default=(1.0, 1.0, 1.0),
                               description="Linear Rec.709 colour, scaled to the luminance")
    image: PointerProperty(name="Panorama", type=bpy.types.Image, description="Equirectangular HDR panorama")
    calibration: EnumProperty(name="Calibration", items=[("scale", "Scale", "Multiply the image by a factor"),
                                                         ("mean", "Mean", "Mean luminance, cd/m^2"),
                                                         ("max", "Max", "Maximum luminance, cd/m^2")], default="mean",
                              description="How the panorama's values become cd/m^2")
    value: FloatProperty(name="Value", default=1000.0, min=1e-9, description="The factor, or the target cd/m^2")
    rotation_deg: FloatProperty(name="Rotation, deg", default=0.0, description="Turn about +z, degrees")


CLASSES = (HudSceneSettings, HudObjectSettings, HudCameraSettings, HudWorldSettings)
POINTERS = ((bpy.types.Scene, HudSceneSettings), (bpy.types.Object, HudObjectSettings),
            (bpy.types.Camera, HudCameraSettings), (bpy.types.World, HudWorldSettings))


def register():
    for cls in CLASSES:
        bpy.utils.register_class(cls)
    for owner, cls in POINTERS:
        owner.hud = PointerProperty(type=cls)


def unregister():
    for owner, _ in POINTERS:
        del owner.hud
    for cls in reversed(CLASSES):
        bpy.utils.unregister_class(cls)
