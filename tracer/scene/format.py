"""The scene format block by block: every field of scene.json with its kind, default, unit, range and
meaning, as :class:`~tracer.core.schema.Schema` objects.

The loader (:mod:`tracer.scene.load`, :mod:`tracer.scene.environment`) takes each block's keys,
defaults and ranges from here; the materials' fields are their classes' schemas
(:data:`tracer.optics.materials.MATERIALS`), the emission block is :data:`tracer.sources.lights.EMISSION`
and the methods' options are :data:`tracer.scene.methods.METHOD_OPTIONS`. docs/user/scene-format.md is
generated from all of them (``python tools/scene_format.py``), and a test fails when it is stale.
"""

from __future__ import annotations

from ..core.schema import Field, Schema
from ..core.validate import (
    MAX_COORD_MM,
    MAX_DISTANCE_MM,
    MAX_FOCAL_MM,
    MAX_LUMINANCE,
    MAX_PUPIL_MM,
    MAX_SCALE,
    MIN_DISTANCE_MM,
    MIN_PUPIL_MM,
    MIN_SCALE,
)
from ..optics.shapes import SHAPES
from ..sources.environment import CALIBRATION_MODES
from ..sources.sun import SUN_ANGULAR_DIAMETER_DEG, SUN_ILLUMINANCE_LX, SUN_MAX_ANGULAR_DIAMETER_DEG
from .windshield import WINDSHIELD

FORMAT = "hud-scene"
VERSION = 1
SCENE_FILE = "scene.json"
#: The mesh formats scene.json may name (trimesh reads them; it also guesses at others, and reads a
#: point cloud or a text file of numbers as a mesh of no faces or of garbage).
MESH_SUFFIXES = (".obj", ".ply", ".stl", ".off", ".glb", ".gltf")
#: The legacy material type that stands for an absorber with an emission block.
LEGACY_EMITTER = "emitter"
#: How the adaptation luminance follows from an image (``eye.adaptation``).
ADAPTATION_MODES = ("log_average", "mean")
#: ``polarisation`` at the top of scene.json: "auto" carries Stokes vectors where an element of the
#: scene polarises (tracer.optics.polar); "off" uses the unpolarised Fresnel average at dielectrics
#: (what an RGB renderer does) and refuses elements that only mean something with polarisation.
POLARISATION_MODES = ("auto", "off")
#: Largest number of retina pixels along either side.
MAX_RESOLUTION = 16384
#: Field angles lie in (0, MAX_FOV_DEG) degrees.
MAX_FOV_DEG = 170.0

#: The eye's optional analyser, ``eye.analyser``: polarised sunglasses (a linear polariser before the eye).
ANALYSER = Field(
    "analyser", "group", None, label="Analyser (polarised sunglasses)",
    description="A linear polariser in front of the eye, as polarised sunglasses are",
    fields=(Field("axis_deg", "number", 90.0, unit="deg", minimum=-360.0, maximum=360.0, label="Axis",
                  description="Transmission axis, degrees from the eye's right toward its up (sunglasses: 90)"),
            Field("transmittance_along", "number", 1.0, unit="1", minimum=0.0, maximum=1.0, label="Transmittance along",
                  description="Transmittance for light polarised along the axis, 0..1"),
            Field("transmittance_across", "number", 0.0, unit="1", minimum=0.0, maximum=1.0,
                  label="Transmittance across", description="Transmittance for light polarised across the axis, 0..1")))

#: The observer: a thin-lens eye (tracer.transport.eye; paper eq. 2) with a finite pupil.
EYE = Schema("eye", "Eye", "The observer: a thin-lens eye with a finite pupil and a flat retina of square pixels", (
    Field("position", "vector3", unit="mm", minimum=-MAX_COORD_MM, maximum=MAX_COORD_MM,
          description="Centre of the pupil, world coordinates"),
    Field("gaze", "vector3", description="Direction of the optical axis (normalised on load)"),
    Field("up", "vector3", description="Up on the retina image (normalised on load; not parallel to gaze)"),
    Field("pupil_diameter_mm", "number", unit="mm", minimum=MIN_PUPIL_MM, maximum=MAX_PUPIL_MM, keywords=("auto",),
          description='Pupil diameter; "auto": Watson & Yellott\'s 2012 unified formula (doi:10.1167/12.10.12) for '
                      "adaptation_luminance_cd_m2 and observer_age"),
    Field("adaptation_luminance_cd_m2", "number", None, unit="cd/m^2", minimum=0.0, maximum=MAX_LUMINANCE,
          keywords=("image",),
          description='The luminance the eye is adapted to, for a pupil "auto"; "image": what the eye sees (a '
                      "pilot render, 5 % of the budget, finds it); absent: the environment's mean luminance"),
    Field("adaptation", "choice", "log_average", choices=ADAPTATION_MODES,
          description="How an image gives the adaptation luminance: its log-average (Ward 1994) or mean (the "
                      "paper's \"average luminance\"); the preview, the report and a pupil that follows the image "
                      "use it"),
    Field("observer_age", "number", 30.0, unit="years", minimum=1.0, maximum=120.0,
          description="Age in Watson & Yellott's formula"),
    Field("focal_length_mm", "number", 16.67, unit="mm", minimum=0.0, exclusive_min=True, maximum=MAX_FOCAL_MM,
          description="Distance from the thin lens to the retina"),
    Field("accommodation_distance_mm", "number", "infinity", unit="mm", minimum=MIN_DISTANCE_MM,
          maximum=MAX_DISTANCE_MM, keywords=("infinity",),
          description="Distance the eye is focused at, along the gaze"),
    Field("resolution", "int2", unit="px", minimum=1, maximum=MAX_RESOLUTION,
          description="Retina pixels [width, height]; the film must fit in half the machine's memory (about 800 "
                      "bytes per pixel and process)"),
    Field("fov_deg", "vector2", unit="deg", minimum=0.0, exclusive_min=True, maximum=MAX_FOV_DEG, exclusive_max=True,
          description="Full field of view [horizontal, vertical]; pixels are square, so the two should keep the "
                      "resolution's aspect"),
    ANALYSER))

#: The paper's directed split (sec. 2): ``aim`` of an emission or a scattering material, and
#: ``light_aim`` of a scattering material.
AIM = Schema("aim", "Aim", "A share of the directions drawn toward (or away from) a target aperture; the "
             "one-sample mixture keeps the estimate unbiased for every share", (
                 Field("target", "string", description='"eye" (the pupil) or the name of a planar object (a '
                                                       "window, a lens aperture, an aperture object)"),
                 Field("share", "number", 0.5, unit="1", minimum=0.0, maximum=1.0,
                       description="Share of the directions drawn toward the target, below 1"),
                 Field("mode", "choice", "toward", choices=("toward", "away"),
                       description='"away": the target is a virtual image behind the surface (a pupil imaged back '
                                   "through the optics): directions are drawn as if they came from it")))

#: A transform by its matrix.
TRANSFORM_MATRIX = Schema("transform (matrix)", "Transform", "An affine 4 x 4 world matrix, rows first", (
    Field("matrix", "matrix4", unit="mm", minimum=-MAX_COORD_MM, maximum=MAX_COORD_MM,
          description="Four rows of four numbers; the last row [0, 0, 0, 1]; translations in mm"),))
#: A transform by its parts: scale first, then the rotations about x, y and z, then the translation.
TRANSFORM_PARTS = Schema("transform (parts)", "Transform", "Scale, then rotate, then translate", (
    Field("translate", "vector3", [0.0, 0.0, 0.0], unit="mm", minimum=-MAX_COORD_MM, maximum=MAX_COORD_MM,
          description="Translation, world coordinates"),
    Field("rotate_deg", "vector3", [0.0, 0.0, 0.0], unit="deg", minimum=-1e6, maximum=1e6,
          description="Rotations about the world x, then y, then z axes (Blender's XYZ Euler: R = Rz Ry Rx)"),
    Field("scale", "vector3", [1.0, 1.0, 1.0], unit="1", minimum=MIN_SCALE, maximum=MAX_SCALE,
          description="A number or [sx, sy, sz] along the object's own axes, each within the range in magnitude "
                      "(a negative scale mirrors the mesh, and its faces are turned so that they keep facing out)")))

#: One object of ``objects``.
OBJECT = Schema("object", "Object", "A triangle mesh with a material, optionally emitting", (
    Field("name", "string", description='Unique in the scene; "eye" is reserved'),
    Field("mesh", "string", None, description="A mesh file inside the scene folder (" + ", ".join(MESH_SUFFIXES)
                                              + "), in mm; an LCD's mesh needs texture coordinates (an OBJ with vt "
                                              "lines). Give a mesh or a windshield"),
    WINDSHIELD,
    Field("material", "group", description='"type" and that material\'s fields (Materials below)'),
    Field("transform", "group", None, description="Object to world: a matrix or parts (below); absent: the "
                                                  "identity"),
    Field("smooth_normals", "bool", False,
          description="Interpolate vertex normals for shading (a curved mirror's facets hidden)"),
    Field("emission", "group", None, description="Makes the object a light (Emission below)"),
    Field("surfaces", "list", None,
          description="Exact surfaces of an optic (Surfaces below): hits on the faces that lie on one are moved onto "
                      "it and take its normal, so that the facets do not bend the rays (a windshield has its own)")))

#: One exact surface of an object (``objects[].surfaces[]``): a shape of tracer.optics.shapes on a frame
#: given in the object's own coordinates (before its transform).
SURFACE = Schema("surface", "Surface", "An analytic shape z = sag(x, y) on a frame of the object's own coordinates; "
                 "the faces whose three corners lie on it within tolerance_mm are its own", (
    Field("type", "choice", choices=tuple(SHAPES), description="The shape (below)"),
    Field("origin", "vector3", [0.0, 0.0, 0.0], unit="mm", minimum=-MAX_COORD_MM, maximum=MAX_COORD_MM,
          description="The shape's vertex, in the object's coordinates"),
    Field("axis", "vector3", [0.0, 0.0, 1.0],
          description="The shape's +z (the side its sag grows toward), in the object's coordinates"),
    Field("x_axis", "vector3", [1.0, 0.0, 0.0],
          description="The shape's +x (made perpendicular to axis; must not be parallel to it)"),
    Field("tolerance_mm", "number", 0.01, unit="mm", minimum=1e-6, maximum=10.0,
          description="How far a face's corners may lie from the shape for the face to be its own")))

#: The sun of an environment: a uniform disk added to it.
SUN = Schema("sun", "Sun", "A uniform disk of luminance E / (pi sin^2(diameter / 2)) added to the environment", (
    Field("direction", "vector3", description="Toward the sun, world axes (z up); normalised on load"),
    Field("illuminance_lux", "number", SUN_ILLUMINANCE_LX, unit="lx", minimum=0.0, maximum=MAX_LUMINANCE,
          description="Illuminance on a surface facing the sun; the disk's luminance must stay within 1e-9 to "
                      "1e12 cd/m^2"),
    Field("angular_diameter_deg", "number", SUN_ANGULAR_DIAMETER_DEG, unit="deg", minimum=0.0, exclusive_min=True,
          maximum=SUN_MAX_ANGULAR_DIAMETER_DEG, description="Angular diameter of the disk"),
    Field("color", "rgb", [1.0, 1.0, 1.0], unit="1", minimum=0.0,
          description="Linear Rec.709 colour, normalised to unit luminance")))

#: An HDRI panorama's calibration to cd/m^2.
CALIBRATION = Field(
    "calibration", "group", description="How the panorama's values become cd/m^2",
    fields=(Field("mode", "choice", choices=CALIBRATION_MODES,
                  description='"scale": multiply the values by value; "mean", "max", "min": scale so that the '
                              "solid-angle mean, the brightest or the darkest pixel's luminance is value ('min' "
                              "refuses a panorama with a black pixel)"),
            Field("value", "number", unit="cd/m^2", minimum=0.0, exclusive_min=True, maximum=MAX_LUMINANCE,
                  description="The factor (mode scale, dimensionless, at most 1e15) or the luminance")))

#: The environment block, one schema per ``type``.
ENVIRONMENTS = {
    "none": Schema("none", "No environment", "Black beyond the scene's objects", (
        Field("sun", "group", None, description="A sun (below)"),)),
    "uniform": Schema("uniform", "Uniform", "The same luminance from every direction", (
        Field("luminance", "number", unit="cd/m^2", minimum=0.0, maximum=MAX_LUMINANCE,
              description="0, or at least 1e-9"),
        Field("color", "rgb", [1.0, 1.0, 1.0], unit="1", minimum=0.0,
              description="Linear Rec.709 colour, normalised to unit luminance"),
        Field("sun", "group", None, description="A sun (below)"))),
    "hdri": Schema("hdri", "HDRI panorama", "An equirectangular panorama in Blender's orientation (the image's centre "
                   "column is +x, a quarter of its width from the left +y, its top row +z), turned about z by "
                   "rotation_deg", (
        Field("file", "string", description="The panorama inside the scene folder (EXR, HDR, PNG; read with "
                                            "OpenImageIO; 1 to 4 channels, alpha dropped)"),
        CALIBRATION,
        Field("rotation_deg", "number", 0.0, unit="deg", minimum=-1e6, maximum=1e6,
              description="Rotation about the world z axis"),
        Field("sun", "group", None, description="A sun (below)"))),
}

#: The target image of the optical analysis (tracer.analysis.optics): the virtual image as specified.
TARGET = Schema("target", "Target image", "The virtual image as specified, which the optical analysis (hud-trace "
                "optics) reports every metric against; every field is optional", (
    Field("distance_mm", "number", None, unit="mm", minimum=10.0, maximum=MAX_DISTANCE_MM,
          description="Target image distance (TID) from the design eye point; absent: the measured virtual image "
                      "distance of the PGU's centre"),
    Field("look_down_deg", "number", None, unit="deg", minimum=-90.0, maximum=90.0,
          description="The image centre below the horizontal through the design eye point; absent: measured"),
    Field("look_over_deg", "number", None, unit="deg", minimum=-90.0, maximum=90.0,
          description="The image centre to the right of the forward direction; absent: measured"),
    Field("fov_deg", "vector2", None, unit="deg", minimum=0.0, exclusive_min=True, maximum=MAX_FOV_DEG,
          description="Field of view [horizontal, vertical]; absent: measured (and no PGU usage)"),
    Field("eyebox_mm", "vector2", [130.0, 50.0], unit="mm", minimum=0.0, maximum=1000.0,
          description="Eyebox [width, height], centred on the design eye point (the eye's position), across the "
                      "forward direction"),
    Field("ipd_mm", "number", 65.0, unit="mm", minimum=0.0, exclusive_min=True, maximum=200.0,
          description="Interpupillary distance of the binocular pairs"),
    Field("forward", "vector3", None, description="The vehicle's forward direction; absent: the eye's gaze made "
                                                  "horizontal"),
    Field("up", "vector3", [0.0, 0.0, 1.0], description="The vehicle's up (the world's z)"),
    Field("field_grid", "int2", [5, 3], minimum=2, maximum=41,
          description="PGU field points [across, up] over its active area, edges included (across: the PGU "
                      "direction that the image shows horizontally)"),
    Field("eye_grid", "int2", [9, 5], minimum=1, maximum=41,
          description="Eye points [across, up] over the eyebox, edges included"),
    Field("pgu", "string", None, description="The object the image forms on; absent: the first LCD of the "
                                             "brightest specular chain from the eye, else the surface it ends on"),
    Field("requirements", "list", None,
          description='"KEY OP VALUE" against optics.json\'s summary (design_eye.ghost_separation_arcmin < 1), as '
                      "the sweep's --require; judged in optics.json")))

#: The top level of scene.json.
TOP = Schema("scene", "Scene", "The top level of scene.json", (
    Field("format", "string", description=f'"{FORMAT}"'),
    Field("version", "int", description=f"{VERSION} (an integer)"),
    Field("name", "string", None, description="Default: the folder's name"),
    Field("description", "string", None, description="Free text"),
    Field("eye", "group", description="The observer (Eye below)"),
    Field("objects", "list", description="The objects (Object below), in any order"),
    Field("environment", "group", None, description='What lies beyond the objects (Environment below); absent: '
                                                    '{"type": "none"}'),
    Field("methods", "group", None, description="Options of each light-transport method by its name (Methods "
                                                "below)"),
    Field("target", "group", None, description="The target image of the optical analysis (Target below)"),
    Field("polarisation", "choice", "auto", choices=POLARISATION_MODES,
          description='"auto": Stokes vectors wherever an element polarises (a dielectric, a metal, an s/p coating, '
                      'an LCD polariser, a polarised source, an analyser); "off": the unpolarised Fresnel average '
                      "of RGB renderers (a scene that needs polarisation is then refused)"),
    Field("backward", "group", None, description="The legacy place of methods.backward, read as it"),
    Field("forward", "group", None, description="The legacy place of methods.forward, read as it")))
