"""Layer 4, the scene format: the one seam between Blender (or a preset) and the tracer. The add-on
exports it, presets write it, the tracer reads it. Its blocks and fields are :mod:`.format` (with
:mod:`.methods` for the methods' options); docs/user/scene-format.md is generated from them."""

from .format import ANALYSER, LEGACY_EMITTER, MESH_SUFFIXES, POLARISATION_MODES, SCENE_FILE
from .load import load_scene
from .model import Aim, EyeSpec, Material, Scene, SceneObject, Surface

__all__ = ["ANALYSER", "LEGACY_EMITTER", "MESH_SUFFIXES", "POLARISATION_MODES", "SCENE_FILE", "Aim", "EyeSpec",
           "Material", "Scene", "SceneObject", "Surface", "load_scene"]
