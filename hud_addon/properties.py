"""Property groups: Scene.hud (render settings), Object.hud (optical role), Camera.hud (eye),
World.hud (environment). One PointerProperty per datablock type; every physical quantity says its
unit in its name or description."""

import bpy
from bpy.props import (
    BoolProperty,
    EnumProperty,
    FloatProperty,
    FloatVectorProperty,
    IntProperty,
    PointerProperty,
)

from ..tracer.integrators import INTEGRATORS
from ..tracer.scene import MATERIAL_FIELDS


def _method_items(self, context):
    # Read from the tracer's registry: later methods appear here by themselves (forward first:
    # the paper's method of choice for HUDs and the default).
    names = sorted(INTEGRATORS, key=lambda n: (n != "forward", n))
    return [(name, name.capitalize(), INTEGRATORS[name].summary) for name in names]


ROLE_LABELS = {
    "mirror": "Mirror", "dielectric": "Dielectric (glass)", "coating": "Coated partial reflector",
    "absorber": "Absorber", "lambertian": "Lambertian reflector",
    "lambertian_transmitter": "Diffuse screen (Lambertian transmitter)", "diffuser": "Gaussian diffuser",
    "lcd": "LCD modulator", "emitter": "Emitter", "aperture": "Aperture (virtual, not traced)",
}
ROLE_ITEMS = [("none", "None", "Not exported to the tracer")] + [
    (role, ROLE_LABELS.get(role, role), f"Tracer material '{role}'") for role in MATERIAL_FIELDS]


class HudSceneSettings(bpy.types.PropertyGroup):
    method: EnumProperty(name="Method", items=_method_items, description="Light-transport method")
    budget: EnumProperty(name="Budget", items=[("SECONDS", "Seconds", "Wall-clock time"),
                                               ("RAYS", "Rays", "Traced ray segments")], default="SECONDS")
    seconds: FloatProperty(name="Seconds", default=10.0, min=0.01, description="Render time, s")
    rays: IntProperty(name="Rays", default=10_000_000, min=1, description="Ray segments to trace")
    seed: IntProperty(name="Seed", default=0, min=0)


class HudObjectSettings(bpy.types.PropertyGroup):
    role: EnumProperty(name="Optical role", items=ROLE_ITEMS, default="none")
    smooth_normals: BoolProperty(name="Smooth normals", default=False,
                                 description="Interpolate vertex normals (curved mirrors and lenses)")
    reflectance: FloatVectorProperty(name="Reflectance", subtype="COLOR", size=3, min=0, max=1,
                                     default=(0.9, 0.9, 0.9))
    transmittance: FloatVectorProperty(name="Transmittance", subtype="COLOR", size=3, min=0, max=1,
                                       default=(0.9, 0.9, 0.9))
    ior: FloatProperty(name="IOR", default=1.52, min=1.0, description="Refractive index inside the mesh")
    ior_outside: FloatProperty(name="IOR outside", default=1.0, min=1.0)
    sigma_deg: FloatVectorProperty(name="Lobe width, deg", size=2, default=(3.0, 3.0), min=0.001, max=60.0,
                                   description="Gaussian lobe widths along the object's local x and y, degrees")
    lcd_image: PointerProperty(name="Slide", type=bpy.types.Image, description="LCD transmittance image")
    lcd_encoding: EnumProperty(name="Encoding", items=[("srgb", "sRGB", ""), ("linear", "Linear", "")])
    contrast_ratio: FloatProperty(name="Contrast ratio", default=300.0, min=1.0)
    emission: EnumProperty(name="Emission", items=[("LUMINANCE", "Luminance", "cd/m^2"), ("FLUX", "Flux", "lm")])
    luminance: FloatProperty(name="Luminance, cd/m²", default=1000.0, min=0.0)
    flux: FloatProperty(name="Flux, lm", default=1.0, min=0.0)
    color: FloatVectorProperty(name="Color", subtype="COLOR", size=3, min=0, default=(1.0, 1.0, 1.0))
    two_sided: BoolProperty(name="Two-sided", default=False)
    aim: EnumProperty(name="Aim", items=[("NONE", "None", "No directed sampling"),
                                         ("EYE", "Eye pupil", "Aim at the eye pupil"),
                                         ("OBJECT", "Object", "Aim at a planar object")], default="NONE")
    aim_object: PointerProperty(name="Aim at", type=bpy.types.Object)
    aim_share: FloatProperty(name="Share", default=0.5, min=0.0, max=0.99)
    aim_mode: EnumProperty(name="Mode", items=[("toward", "Toward", "Directions toward the target"),
                                               ("away", "Away", "As if coming from a virtual target behind")])


class HudCameraSettings(bpy.types.PropertyGroup):
    pupil: EnumProperty(name="Pupil", items=[("FIXED", "Fixed", "A given diameter"),
                                             ("AUTO", "From adaptation", "Watson & Yellott 2012 from the "
                                              "adaptation luminance")], default="FIXED")
    pupil_diameter_mm: FloatProperty(name="Pupil, mm", default=4.0, min=0.01)
    adaptation_luminance: FloatProperty(
        name="Adaptation, cd/m²", default=0.0, min=0.0,
        description="Luminance the eye is adapted to, cd/m^2; 0: the environment's mean")
    observer_age: FloatProperty(name="Age, years", default=30.0, min=1.0, max=120.0)
    focal_length_mm: FloatProperty(name="Eye focal length, mm", default=16.67, min=0.1)
    accommodation_distance_mm: FloatProperty(name="Accommodation, mm", default=2500.0, min=0.0,
                                             description="Focus distance, mm; 0 means infinity")


class HudWorldSettings(bpy.types.PropertyGroup):
    kind: EnumProperty(name="Environment", items=[("none", "None", ""), ("uniform", "Uniform", ""),
                                                  ("hdri", "HDRI panorama", "")], default="none")
    luminance: FloatProperty(name="Luminance, cd/m²", default=100.0, min=0.0)
    color: FloatVectorProperty(name="Color", subtype="COLOR", size=3, min=0, default=(1.0, 1.0, 1.0))
    image: PointerProperty(name="Panorama", type=bpy.types.Image)
    calibration: EnumProperty(name="Calibration", items=[("scale", "Scale", "Multiply the image by a factor"),
                                                         ("mean", "Mean", "Mean luminance, cd/m^2"),
                                                         ("max", "Max", "Maximum luminance, cd/m^2")], default="mean")
    value: FloatProperty(name="Value", default=1000.0, min=1e-9)
    rotation_deg: FloatProperty(name="Rotation, deg", default=0.0)


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


