"""Property groups: Scene.hud (render settings, the polarisation mode and every method's options),
Object.hud (optical role, the material's fields, emission), Camera.hud (eye, with its analyser),
World.hud (environment), Light.hud (a Sun light's illuminance: the environment's sun). One
PointerProperty per datablock type. The fields of materials, of the emission block, of the eye's
analyser and of the methods' options come from the tracer's schemas (hud_addon/schema_ui.py), so a
new material or option needs no change here."""

import dataclasses

import bpy
import numpy as np
from bpy.props import (
    BoolProperty,
    EnumProperty,
    FloatProperty,
    FloatVectorProperty,
    IntProperty,
    IntVectorProperty,
    PointerProperty,
    StringProperty,
)

from ..tracer.core.schema import check_consistent
from ..tracer.methods import DEFAULT_METHOD, INTEGRATORS
from ..tracer.optics.materials import MATERIALS
from ..tracer.scene import ANALYSER, POLARISATION_MODES
from ..tracer.scene.methods import METHOD_OPTIONS
from ..tracer.sources.lights import EMISSION
from ..tracer.sources.sun import SUN_ILLUMINANCE_LX
from .schema_ui import annotations, starting_values
from .units import angle_twin, declared_default, length_twin


def _method_items(self, context):
    # Read from the tracer's registry: later methods appear here by themselves (the tracer's default
    # first, so that it is the property's default).
    names = sorted(INTEGRATORS, key=lambda n: (n != DEFAULT_METHOD, n))
    return [(name, name.capitalize(), INTEGRATORS[name].summary) for name in names]


#: Tooltips of the scene's polarisation modes (tracer.scene.POLARISATION_MODES).
POLARISATION_TIPS = {
    "auto": "Polarisation is carried (Stokes vectors) wherever an element of the scene polarises: Fresnel "
            "reflection and refraction at glass, LCD output polarisers, retarder films, coatings given for s and p "
            "light, metal mirrors, polarised emission and the eye's analyser",
    "off": "Unpolarised light throughout: the unpolarised Fresnel average at glass (what RGB renderers do); a "
           "scene with an element that needs polarisation (analyser, LCD polariser, retarder, s/p coating, metal "
           "mirror, polarised emission) is refused",
}


def _polarisation_items() -> list[tuple[str, str, str]]:
    return [(m, m.capitalize(), POLARISATION_TIPS.get(m, f"The tracer's polarisation mode {m!r}"))
            for m in POLARISATION_MODES]


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
        "scheduler": StringProperty(name="Dask Scheduler", default="",
                                    description="Address of a Dask scheduler (tcp://host:8786) to render on its "
                                                "cluster; empty: this machine's processes (Performance > Threads)"),
        "polarisation": EnumProperty(name="Polarisation", items=_polarisation_items(), default="auto",
                                     description="Whether light carries its polarisation (scene.json "
                                                 "\"polarisation\"): Auto where the scene polarises, Off for "
                                                 "the unpolarised average"),
        # The eyebox sweep (HUD Readouts panel): lengths stored in mm, shown in the scene's units.
        "eyebox_half_width_mm": FloatProperty(name="Half width", default=60.0, min=0.0, max=1000.0,
                                              description="Eye offsets to the left and right of the camera, mm"),
        "eyebox_half_width_mm_shown": length_twin("eyebox_half_width_mm", "Half width",
                                                  "Eye offsets scanned to the left and right of the camera",
                                                  nonnegative=True),
        "eyebox_half_height_mm": FloatProperty(name="Half height", default=30.0, min=0.0, max=1000.0,
                                               description="Eye offsets below and above the camera, mm"),
        "eyebox_half_height_mm_shown": length_twin("eyebox_half_height_mm", "Half height",
                                                   "Eye offsets scanned below and above the camera", nonnegative=True),
        "eyebox_step_mm": FloatProperty(name="Step", default=5.0, min=0.01, max=1000.0,
                                        description="Step of the grid of eye offsets, mm"),
        "eyebox_step_mm_shown": length_twin("eyebox_step_mm", "Step", "Step of the grid of eye offsets",
                                            nonnegative=True),
        "eyebox_threshold": FloatProperty(name="Threshold", default=0.5, min=0.01, max=1.0, subtype="FACTOR",
                                          description="Share of its luminance at the design eye that every point "
                                                      "of the display must keep inside the eyebox"),
        "eyebox_field": EnumProperty(name="Display field", items=[
            ("AUTO", "From the scene", "The angular extent of what the camera sees of the LCD, or of a lit screen"),
            ("GIVEN", "Given", "A field of view centred on the camera's axis")], default="AUTO",
            description="The display field whose centre and corners are checked"),
        "eyebox_field_deg": FloatVectorProperty(name="Field", size=2, default=(6.0, 2.0), min=0.01, max=179.0,
                                                description="Full width and height of the display field, degrees"),
        "eyebox_field_deg_shown": angle_twin("eyebox_field_deg", "Field",
                                             "Full width and height of the display field", size=2),
        "eyebox_photons": IntProperty(name="Photons", default=1_000_000, min=0, max=100_000_000,
                                      description="Particles of the photon map that lights a screen seen through "
                                                  "optics (a rear-projection HUD: about 5 s per million), used only "
                                                  "where a screen is lit through a lens or mirror; 0 leaves that "
                                                  "light out"),
        "eyebox_folder": StringProperty(name="Folder", default="//eyebox/", subtype="DIR_PATH",
                                        description="Where eyebox.csv, eyebox.png and eyebox.json are written "
                                                    "(// is the .blend's folder)"),
        # The optical analysis (HUD Optics panel; scene.json "target"): lengths stored in mm.
        "optics_eyebox_mm": FloatVectorProperty(name="Eyebox", size=2, default=(130.0, 50.0), min=0.0, max=1000.0,
                                                description="Eyebox width and height, centred on the camera, mm"),
        "optics_eyebox_mm_shown": length_twin("optics_eyebox_mm", "Eyebox",
                                              "Width and height of the eyebox, centred on the camera (the design eye "
                                              "point), across the vehicle's forward direction", size=2),
        "optics_ipd_mm": FloatProperty(name="IPD", default=65.0, min=1.0, max=200.0,
                                       description="Interpupillary distance of the binocular pairs, mm"),
        "optics_ipd_mm_shown": length_twin("optics_ipd_mm", "IPD", "Interpupillary distance of the binocular pairs "
                                           "(65 mm typical, 50 to 75 mm across drivers)", nonnegative=True),
        "optics_field_grid": IntVectorProperty(name="Field grid", size=2, default=(5, 3), min=2, max=41,
                                               description="PGU field points across and up its active area, edges "
                                                           "included"),
        "optics_eye_grid": IntVectorProperty(name="Eye grid", size=2, default=(9, 5), min=1, max=41,
                                             description="Eye points across and up the eyebox, edges included"),
        "optics_folder": StringProperty(name="Folder", default="//optics/", subtype="DIR_PATH",
                                        description="Where optics.json, optics.csv and the pictures are written "
                                                    "(// is the .blend's folder)"),
        "optics_target": StringProperty(name="Target", default="",
                                        description="The rest of the scene's target block (scene.json \"target\": "
                                                    "distance, look-down and look-over angles, field of view, PGU, "
                                                    "requirements) as a preset gave it, JSON"),
    }
    for name, options in METHOD_OPTIONS.items():
        annotations(options.fields, f"{name}_", seen=ann)
    return ann


def _per_role_descriptions() -> dict[str, str]:
    """For a material field that several roles share under one property (Reflectance: a mirror's specular
    reflectance, a Lambertian surface's albedo) but describe differently, one tooltip that gives each
    role's meaning ("Mirror: specular reflectance, 0..1. Lambertian: diffuse albedo, 0..1.")."""
    meanings: dict[str, dict[str, list[str]]] = {}
    for cls in MATERIALS.values():
        for f in cls.schema.fields:
            if f.description:
                meanings.setdefault(f.name, {}).setdefault(f.description.rstrip("."), []).append(cls.schema.label)
    return {name: ". ".join(f"{', '.join(roles)}: {text[0].lower()}{text[1:]}" for text, roles in by_text.items())
            for name, by_text in meanings.items() if len(by_text) > 1}  # the tooltip adds the last full stop


#: The values each role's numbers and colours start from in the panel, by role.
ROLE_STARTS = {name: starting_values(cls.schema.fields) for name, cls in MATERIALS.items()}


def _role_changed(self, context):
    """Give the role just chosen its own starting values where the object still holds those of the role
    before it (or the properties' defaults): roles share their properties by name (one Reflectance for
    all), and a coating and a diffuse screen refused the mirror's 0.9 and 0.9 (R + T above 1)."""
    if self.role not in ROLE_STARTS:  # none: the values wait for the next role
        return
    before = ROLE_STARTS.get(self.started_role, {})
    for name, value in ROLE_STARTS[self.role].items():
        was = before[name] if name in before else declared_default(self, name)
        if np.allclose(getattr(self, name), was, rtol=1e-6, atol=1e-7):  # stored as float32
            setattr(self, name, value)
    self.started_role = self.role


def _object_annotations() -> dict:
    check_consistent([cls.schema for cls in MATERIALS.values()])
    ann = {
        "role": EnumProperty(name="Optical role", items=ROLE_ITEMS, default="none", update=_role_changed,
                             description="The tracer material of this object. Choosing one gives its fields "
                                         "the role's own starting values where they still hold the role "
                                         "before's (a script sets the role first, then the values)"),
        "started_role": StringProperty(name="Started role", default="", options={"HIDDEN"},
                                       description="The role whose starting values the fields were given last"),
        "smooth_normals": BoolProperty(name="Smooth normals", default=False,
                                       description="Interpolate vertex normals (curved mirrors and lenses)"),
        "emits": BoolProperty(name="Emits light", default=False,
                              description="The object is also a Lambertian light source (any material can emit)"),
        "surfaces": StringProperty(name="Exact surfaces", default="",
                                   description="The exact surfaces of the object's optic (scene.json \"surfaces\", "
                                               "in the object's own coordinates, mm) as a preset gave them, JSON: "
                                               "hits on the faces that lie on one take its shape and normal"),
    }
    described = _per_role_descriptions()
    for cls in MATERIALS.values():
        fields = tuple(dataclasses.replace(f, description=described.get(f.name, f.description))
                       for f in cls.schema.fields)
        annotations(fields, "", cls.schema.alternatives, ann)
    ann |= _aim("")
    ann |= _aim("light_", "Light aim", "Guidance of eye paths (backward method) toward the aperture through which "
                                       "this surface's light arrives, e.g. a condenser's face")
    annotations(EMISSION.fields, "emission_", EMISSION.alternatives, ann)
    ann |= _aim("emission_")
    return ann


def _role_starting_value(self, name: str):
    """The value the object's property ``name`` starts from under its role (ROLE_STARTS), or None (the
    property's declared default): what Reset to Default Value puts back (hud_addon.units.starting_value)."""
    return ROLE_STARTS.get(self.role, {}).get(name)


HudSceneSettings = type("HudSceneSettings", (bpy.types.PropertyGroup,), {"__annotations__": _scene_annotations()})
HudObjectSettings = type("HudObjectSettings", (bpy.types.PropertyGroup,),
                         {"__annotations__": _object_annotations(), "starting_value": _role_starting_value})


class HudCameraSettings(bpy.types.PropertyGroup):
    pupil: EnumProperty(name="Pupil", items=[("FIXED", "Fixed", "A given diameter"),
                                             ("AUTO", "From adaptation", "Watson & Yellott 2012 from the "
                                              "adaptation luminance"),
                                             ("IMAGE", "Follows the image", "Watson & Yellott 2012 from the "
                                              "luminance the eye adapts to in what it sees (a pilot render "
                                              "finds it)")], default="FIXED",
                        description="A fixed pupil, one for a given adaptation luminance, or one that follows the "
                                    "image")
    adaptation: EnumProperty(name="Adaptation", items=[
        ("log_average", "Log-average", "Ward 1994: the log-average luminance of what the eye sees"),
        ("mean", "Mean", "The mean luminance of what the eye sees (the paper's \"average luminance\")")],
        default="log_average", description="How the image gives the luminance the eye adapts to (the preview, the "
                                           "report and a pupil that follows the image use it)")
    pupil_diameter_mm: FloatProperty(name="Pupil diameter", default=4.0, min=0.01, max=20.0,
                                     description="Diameter of the eye's entrance pupil, mm")
    pupil_diameter_mm_shown: length_twin("pupil_diameter_mm", "Pupil diameter",
                                         "Diameter of the eye's entrance pupil (2 mm in bright daylight, 8 mm at "
                                         "night)", nonnegative=True)
    adaptation_luminance: FloatProperty(
        name="Adaptation luminance", default=0.0, min=0.0,
        description="Luminance the eye is adapted to, cd/m^2; 0: the environment's mean")
    observer_age: FloatProperty(name="Observer age", default=30.0, min=1.0, max=120.0,
                                description="Observer's age in years (Watson & Yellott's age term)")
    focal_length_mm: FloatProperty(name="Eye focal length", default=16.67, min=0.1, max=1000.0,
                                   description="Focal length of the thin-lens eye, mm (16.67: Emsley's reduced eye)")
    focal_length_mm_shown: length_twin("focal_length_mm", "Eye focal length",
                                       "Focal length of the thin-lens eye (16.67 mm: Emsley's reduced eye); it sets "
                                       "the retina's scale, not the field of view (that is the camera's lens)",
                                       nonnegative=True)
    accommodation_distance_mm: FloatProperty(name="Accommodation", default=2500.0, min=0.0,
                                             description="Focus distance, mm; 0 means infinity")
    accommodation_distance_mm_shown: length_twin("accommodation_distance_mm", "Accommodation",
                                                 "Distance the eye focuses at (a HUD's virtual image: 2 to 15 m); "
                                                 "0 means infinity", nonnegative=True)


# The eye's analyser (polarised sunglasses, scene.json eye.analyser) from its schema group: analyser_use
# and analyser_<field> (hud_addon/schema_ui.py's group convention).
HudCameraSettings.__annotations__.update(annotations((ANALYSER,)))


class HudWorldSettings(bpy.types.PropertyGroup):
    kind: EnumProperty(name="Environment", items=[("none", "None", "Black"), ("uniform", "Uniform", "One luminance"),
                                                  ("hdri", "HDRI panorama", "An equirectangular panorama")],
                       default="none", description="What rays that leave the scene see")
    luminance: FloatProperty(name="Luminance", default=100.0, min=0.0,
                             description="Uniform luminance of the environment, cd/m^2")
    color: FloatVectorProperty(name="Color", subtype="COLOR", size=3, min=0, default=(1.0, 1.0, 1.0),
                               description="Linear Rec.709 colour, scaled to the luminance")
    image: PointerProperty(name="Panorama", type=bpy.types.Image, description="Equirectangular HDR panorama")
    calibration: EnumProperty(name="Calibration", items=[("scale", "Scale", "Multiply the image by a factor"),
                                                         ("mean", "Mean", "Mean luminance, cd/m^2"),
                                                         ("max", "Max", "Maximum luminance, cd/m^2"),
                                                         ("min", "Min", "Minimum luminance, cd/m^2 (a panorama "
                                                                        "without black pixels)")], default="mean",
                              description="How the panorama's values become cd/m^2")
    value: FloatProperty(name="Value", default=1000.0, min=1e-9,
                         description="The factor (Scale), or the target luminance in cd/m^2 (Mean, Max, Min)")
    rotation_deg: FloatProperty(name="Rotation", default=0.0, description="Turn of the panorama about +z, degrees")
    rotation_deg_shown: angle_twin("rotation_deg", "Rotation", "Turn of the panorama about +z")


class HudLightSettings(bpy.types.PropertyGroup):
    """A Sun light is the environment's sun (its direction, Angle and Color are Blender's own)."""

    illuminance_lux: FloatProperty(name="Illuminance", default=SUN_ILLUMINANCE_LX, min=0.0, soft_max=150_000.0,
                                   description="Illuminance of the sun on a surface facing it, lx (about 100,000 lx "
                                               "at a clear noon); the sun is a disk of the light's Angle whose "
                                               "luminance gives this illuminance. Used for Sun lights only")


CLASSES = (HudSceneSettings, HudObjectSettings, HudCameraSettings, HudWorldSettings, HudLightSettings)
POINTERS = ((bpy.types.Scene, HudSceneSettings), (bpy.types.Object, HudObjectSettings),
            (bpy.types.Camera, HudCameraSettings), (bpy.types.World, HudWorldSettings),
            (bpy.types.Light, HudLightSettings))


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
