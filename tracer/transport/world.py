"""The render world: everything a method needs of a scene, built once.

A :class:`World` holds the eye, the Embree scene, one material instance per material type, the light
table, the environment and the aim targets. Every method, the brightness-theorem analysis and the
benchmarks take a world instead of reaching into an integrator; worker processes build their own from
the scene folder. :meth:`World.with_eye` gives a world seen from another eye (the eyebox scan) that
shares everything else.
"""

from __future__ import annotations

import copy

import numpy as np

from ..core.units import luminance3
from ..core.vec import take
from ..optics.aimed import Aimed
from ..optics.bsdf import Interaction
from ..optics.materials import make_materials
from ..optics.polar import Transport
from ..scene import EyeSpec, Scene
from ..sources.environment import NoEnvironment
from ..sources.lights import LightTable
from .accel import Accelerator
from .apertures import DiskTarget, MeshTarget
from .eye import ThinLensEye


class World:
    """A scene made ready for tracing.

    Attributes
    ----------
    scene : the loaded scene. eye : ThinLensEye. accel : Accelerator or None (nothing to trace).
    materials : list of material instances (one per type present). face_material : (F,) int8 index
    into ``materials`` of every global face. lights : LightTable. environment : the scene's environment.
    """

    def __init__(self, scene: Scene, eye: ThinLensEye | None = None, exact_surfaces: bool = True):
        self.scene = scene
        self.eye = eye if eye is not None else ThinLensEye(scene.eye)
        self.environment = scene.environment
        traced = scene.traced_objects
        #: Whether hits on the objects' exact surfaces are refined onto them (false: the meshes alone, to
        #: measure what the facets cost).
        self.exact_surfaces = exact_surfaces
        self.accel = Accelerator(traced, exact_surfaces) if traced else None
        self.materials = make_materials(traced)
        slot_material = np.full(len(scene.objects), -1, np.int8)
        for i, m in enumerate(self.materials):
            for o in m.objects:
                slot_material[o.slot] = i
        self.slot_material = slot_material
        self.lights = LightTable(traced)
        if self.accel is not None:
            self.face_material = slot_material[self.accel.face_slot]
            #: The shading group of every face: its material, or -1 where the material absorbs everything;
            #: with -1 appended, so that np.take with face -1 (a miss) gives -1.
            absorbing = np.array([m.flags == 0 for m in self.materials] + [True])
            group = np.where(absorbing[self.face_material], -1, self.face_material).astype(np.int8)
            self.face_group = np.append(group, np.int8(-1))
            self.lights.link_faces(self.accel.faces, self.accel.first_face)
        self._targets: dict[str, DiskTarget | MeshTarget] = {}
        #: Stokes-vector transport (tracer.optics.polar.Transport) where the scene needs it, else None.
        self.polar = self._polar()
        #: Ray segments of a world without geometry (they all escape at once; counted as traced).
        self.rays_without_geometry = 0

    @property
    def key(self) -> tuple:
        """What everything traced in this world depends on, for results kept by it
        (tracer.core.kept.KeptResults): the scene's hash, the eye's spec and whether hits are refined onto
        exact surfaces."""
        return self.scene.scene_hash, repr(self.eye.spec), self.exact_surfaces

    @property
    def dark(self) -> bool:
        """Whether the world holds no light source at all: no emitter, a black environment (its image is
        black whatever is traced)."""
        return len(self.lights) == 0 and self.environment.is_black

    def _polarising_elements(self) -> list[str]:
        """What makes this world need Stokes vectors: objects whose material polarises
        (tracer.optics.bsdf.BSDF.polarising), polarised emitters, the eye's analyser; none with the
        scene's ``polarisation`` "off"."""
        scene = self.scene
        if scene.polarisation == "off":
            return []
        elements = [o.name for m in self.materials if m.polarising for o in m.objects]
        elements += [f"{o.name} (polarised emission)" for o in scene.objects
                     if o.emission is not None and o.emission.polarisation is not None]
        if self.eye.spec.analyser is not None:
            elements.append("eye (analyser)")
        return elements

    def _polar(self):
        """The polarised transport of this world, or None where nothing needs it."""
        return Transport(self) if self._polarising_elements() else None

    def polarisation_report(self) -> dict:
        """The report's account of polarisation: the scene's mode, whether paths carry Stokes vectors, and
        the elements that make them needed."""
        return {"mode": self.scene.polarisation, "stokes_vectors": self.polarised,
                "polarising_elements": self._polarising_elements()}

    @property
    def polarised(self) -> bool:
        """Whether paths carry Stokes vectors in this world."""
        return self.polar is not None

    def with_eye(self, spec: EyeSpec) -> World:
        """This world seen by another eye (same geometry, materials and lights)."""
        other = copy.copy(self)
        other.eye = ThinLensEye(spec)
        other._targets = {k: v for k, v in self._targets.items() if k != "eye"}
        other.polar = other._polar()
        return other

    def channel(self, lights: bool = True, environment: bool = True) -> World:
        """This world with only some of its sources: without its emitters (``lights`` false: every object
        is still traced, the emitting ones as their materials only) or without its environment (black).
        The hybrid method renders each channel of an image on such a world (tracer.methods.hybrid);
        the geometry, materials and aim targets are shared."""
        other = copy.copy(self)
        if not lights:
            other.lights = LightTable([])
            if self.accel is not None:
                other.lights.link_faces(self.accel.faces, self.accel.first_face)
        if not environment:
            other.environment = NoEnvironment()
        return other

    def target(self, name: str):
        """The aiming target "eye" (the pupil disk) or a named planar object (an aperture, the LCD)."""
        if name not in self._targets:
            if name == "eye":
                self._targets[name] = DiskTarget(self.eye.position, self.eye.gaze, self.eye.pupil_radius)
            else:
                self._targets[name] = MeshTarget(self.scene.object(name).triangles)
        return self._targets[name]

    def aimed_samplers(self, aim_of) -> dict[int, object]:
        """{id(material): its sampler}: the material, or its mixture with sampling toward targets
        (:class:`tracer.optics.aimed.Aimed`) where objects of it name one; ``aim_of(scene_object)``
        gives the object's Aim or None (the material's ``aim`` for particles, its ``light_aim`` for eye
        paths)."""
        slots = len(self.scene.objects)
        out = {}
        for m in self.materials:
            aims = {o.slot: (self.target(a.target), a.share, a.mode)
                    for o in m.objects if (a := aim_of(o)) is not None and a.share > 0}
            out[id(m)] = Aimed(m, aims, slots) if aims else m
        return out

    @property
    def rays_traced(self) -> int:
        """Ray segments handed to Embree so far (scene and aim-target queries)."""
        n = self.accel.rays_traced if self.accel is not None else self.rays_without_geometry
        return n + sum(t.rays_traced for t in self._targets.values() if isinstance(t, MeshTarget))

    def interaction(self, face: np.ndarray, p: np.ndarray, d: np.ndarray, ng: np.ndarray | None = None,
                    material=None) -> Interaction:
        """The interaction of rays arriving along ``d`` (3, n) at points ``p`` (3, n) of faces ``face``
        (all of one ``material``, when given: its objects say whether normals or UVs need interpolating)."""
        a = self.accel
        if ng is None:
            ng = take(a.normal32, face)
        if material is not None and not any(o.normals is not None or o.uv is not None for o in material.objects):
            ns, uv = ng, None
        else:
            ns, uv = a.shading(face, p, ng)
        if a.surfaces is not None:  # faces on an exact surface: its normal, for shading and sides alike
            exact = a.surfaces.normals(face, p, ng)
            if exact is not ng:
                ns = np.where(take(a.surfaces.face_surface, face) >= 0, exact, ns)
                ng = exact
        return Interaction(d, p, ng, ns, uv, a.face_slot[face], take(a.offset, face))

    @property
    def max_luminance(self) -> float:
        """The largest luminance of any light or of the environment, cd/m^2."""
        lum = float(luminance3(self.lights.radiance).max()) if len(self.lights) else 0.0
        return max(lum, self.environment.max_luminance)
