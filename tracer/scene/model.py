"""The loaded scene: plain data, validated by :mod:`tracer.scene.load` (lengths in mm, luminance in
cd/m^2, angles in degrees)."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..core.validate import FieldChecker
from ..optics.materials import MATERIALS
from ..optics.shapes import Shape
from ..sources.environment import Environment
from ..sources.lights import Emission
from .format import SCENE_FILE
from .methods import METHOD_OPTIONS


@dataclass
class Aim:
    """The paper's directed split (sec. 2): with probability ``share`` a direction is drawn
    toward ``target`` ("eye" or the name of an object), otherwise from the surface's own law.

    ``mode`` "toward" aims at the target; "away" draws directions as if they came from it: the
    target is then a virtual image behind the surface (an optical system's pupil imaged back).
    """

    target: str
    share: float
    mode: str = "toward"


@dataclass
class Material:
    """An optical material with validated parameters (RGB values as float64 arrays (3,))."""

    type: str
    params: dict
    aim: Aim | None = None
    #: Guidance of eye paths (backward tracing): a share of the directions drawn toward the aperture
    #: through which the surface's light arrives ("light_aim").
    light_aim: Aim | None = None


@dataclass
class Surface:
    """An exact surface of an object (:data:`tracer.scene.format.SURFACE`): its shape on a frame, and the
    faces of the object's mesh that lie on it.

    type : the shape's name. shape : :class:`tracer.optics.shapes.Shape` (sag in the frame's units).
    to_local : (4, 4) world mm -> the shape's frame (the inverse of the object's transform times the
    frame; any affine map: the sag is taken in the frame's coordinates and normals follow by the inverse
    transpose). faces : (k,) indices into the object's faces. gap_mm : (k,) the largest distance
    between each of those faces and the shape (its corners' residuals and its facet's sagitta), mm.
    params : the parsed fields, for the report.
    """

    type: str
    shape: Shape
    to_local: np.ndarray
    faces: np.ndarray
    gap_mm: np.ndarray
    params: dict = field(default_factory=dict)


@dataclass
class SceneObject:
    """One object: a triangle mesh in world millimetres, its material and, if it emits, its emission.

    Attributes
    ----------
    index : position in scene.json's object list; it is also the object's ``slot`` in a render world.
    vertices : (v, 3) float64, mm, world space.
    faces : (f, 3) int64.
    normals : (v, 3) float64 unit vertex normals when ``smooth`` else None.
    uv : (v, 2) float64 texture coordinates or None.
    local_x : (3,) the object's local x axis in the world (anisotropic lobes follow it).
    local_y : (3,) its local y axis, made perpendicular to local_x (polariser and retarder axes are
    angles from local_x toward local_y).
    """

    name: str
    index: int
    vertices: np.ndarray
    faces: np.ndarray
    material: Material
    smooth: bool = False
    normals: np.ndarray | None = None
    uv: np.ndarray | None = None
    local_x: np.ndarray = field(default_factory=lambda: np.array([1.0, 0.0, 0.0]))
    emission: Emission | None = None
    local_y: np.ndarray = field(default_factory=lambda: np.array([0.0, 1.0, 0.0]))
    #: Exact surfaces of the object (:class:`Surface`); hits on their faces are refined onto them.
    surfaces: list[Surface] = field(default_factory=list)

    def axis(self, angle_deg: float) -> np.ndarray:
        """(3,) unit vector at ``angle_deg`` from the local x axis toward the local y axis (the axis of a
        polariser, a retarder film or a polarised emitter on this object)."""
        a = np.radians(angle_deg)
        return np.cos(a) * self.local_x + np.sin(a) * self.local_y

    @property
    def slot(self) -> int:
        return self.index

    @property
    def triangles(self) -> np.ndarray:
        """(f, 3, 3) float64 triangle corners, mm."""
        return self.vertices[self.faces]

    @property
    def area_mm2(self) -> float:
        t = self.triangles
        return float(0.5 * np.linalg.norm(np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]), axis=1).sum())


@dataclass
class EyeSpec:
    """The observer: a thin-lens eye (see :mod:`tracer.transport.eye`). Lengths in mm, angles in degrees."""

    position: np.ndarray
    gaze: np.ndarray
    up: np.ndarray
    pupil_diameter_mm: float
    focal_length_mm: float
    accommodation_distance_mm: float
    resolution: tuple[int, int]
    fov_deg: tuple[float, float]
    #: How the adaptation luminance follows from the image the eye sees: "log_average" (Ward 1994's
    #: log-average, the default) or "mean" (the arithmetic mean; the paper's "average luminance").
    adaptation: str = "log_average"
    #: The pupil follows the image's adaptation luminance (Watson & Yellott 2012; "auto" with
    #: adaptation_luminance_cd_m2 "image"): a pilot render finds it (tracer.products.render.run_render).
    pupil_from_image: bool = False
    observer_age: float = 30.0
    #: The analyser in front of the eye (:data:`ANALYSER`'s parsed fields), or None.
    analyser: dict | None = None


@dataclass
class Scene:
    """A loaded, validated scene."""

    root: Path
    name: str
    description: str
    eye: EyeSpec
    environment: Environment
    objects: list[SceneObject]
    #: Validated options of each method named in scene.json (methods not named use their defaults).
    methods: dict[str, dict]
    scene_hash: str
    raw: dict
    file: str = SCENE_FILE
    #: Whether the scene's files may lie outside its folder (load_scene's ``allow_external``): worker
    #: processes load the folder again with the same rule.
    allow_external: bool = False
    #: :data:`POLARISATION_MODES`: "auto" (Stokes vectors where the scene polarises) or "off".
    polarisation: str = "auto"
    #: The target image of the optical analysis (tracer.scene.format.TARGET's parsed fields, defaults
    #: filled in; absent optional fields left out).
    target: dict = field(default_factory=dict)

    def object(self, name: str) -> SceneObject:
        for obj in self.objects:
            if obj.name == name:
                return obj
        raise KeyError(name)

    @property
    def traced_objects(self) -> list[SceneObject]:
        """Objects that take part in ray intersection (virtual apertures do not)."""
        return [o for o in self.objects if MATERIALS[o.material.type].traced]

    def method_options(self, name: str) -> dict:
        """The validated options of method ``name`` (its defaults when scene.json names none)."""
        if name not in self.methods:
            self.methods[name] = METHOD_OPTIONS[name].parse(FieldChecker(self.file), None, f"methods.{name}", self)
        return self.methods[name]
