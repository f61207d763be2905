"""Layer 4, the scene format: the one seam between Blender (or a preset) and the tracer. The add-on
exports it, presets write it, the tracer reads it (docs/scene-format.md, generated from its schemas)."""

from .load import (
    ANALYSER,
    LEGACY_EMITTER,
    MESH_SUFFIXES,
    POLARISATION_MODES,
    SCENE_FILE,
    Aim,
    EyeSpec,
    Material,
    Scene,
    SceneObject,
    load_scene,
)

__all__ = ["ANALYSER", "LEGACY_EMITTER", "MESH_SUFFIXES", "POLARISATION_MODES", "SCENE_FILE", "Aim", "EyeSpec",
           "Material", "Scene", "SceneObject", "load_scene"]
