"""The render engine "HUD Tracer": thin; the work is in :func:`render_final`.

F12: export the scene to a temporary scene folder, load it with the tracer (the same validation as
the command line), run the chosen method with progress (update_progress, update_stats) and cancel
(test_break, checked each ray batch), then write Combined and a luminance pass Y into the Render
Result and report the tracer's warnings.
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import bpy
import numpy as np

from ..tracer.errors import SceneError
from ..tracer.integrators import INTEGRATORS, Budget
from ..tracer.scene import load_scene
from ..tracer.units import Y_WEIGHTS
from .export import export_scene

#: Extra passes written beside Combined: name -> (channels, channel ids, Blender pass type).
PASSES = {"Y": (1, "X", "VALUE")}

#: Figures of the last final render (read by hud-render for its report.json).
LAST_RENDER: dict = {}


def render_final(engine, depsgraph) -> dict:
    """Render the depsgraph's scene into ``engine``'s result. Returns figures for the caller:
    method, rays, paths, seconds, efficiency, partial, warnings, luminance (mean, max)."""
    scene = depsgraph.scene
    s = scene.hud
    budget = Budget(rays=s.rays) if s.budget == "RAYS" else Budget(seconds=s.seconds)
    with tempfile.TemporaryDirectory(prefix="hud-blender-") as tmp:
        try:
            folder = export_scene(depsgraph, Path(tmp) / "scene")
            tracer_scene = load_scene(folder)
        except (SceneError, ValueError) as e:
            engine.report({"ERROR"}, f"HUD Tracer: {e}")
            LAST_RENDER.clear()
            LAST_RENDER["error"] = str(e)
            return dict(LAST_RENDER)
        integrator = INTEGRATORS[s.method](tracer_scene, s.seed)

        def progress(fraction, message):
            engine.update_progress(fraction)
            engine.update_stats("HUD Tracer", message)

        result = integrator.render(budget, progress, engine.test_break)
    image = result.film.rgb().astype(np.float32)
    write_result(engine, image)
    for w in result.warnings:
        engine.report({"WARNING"}, f"HUD Tracer: {w}")
    y = image @ Y_WEIGHTS.astype(np.float32)
    LAST_RENDER.clear()
    LAST_RENDER.update({"method": result.method, "rays": result.rays, "paths": result.paths, "seconds": result.seconds,
            "efficiency": result.efficiency, "partial": result.partial, "warnings": list(result.warnings),
            "batches": result.batches, "seed": s.seed, "scene_hash": tracer_scene.scene_hash,
            "luminance": {"mean": float(y.mean()), "max": float(y.max())}})
    return dict(LAST_RENDER)


def write_result(engine, image: np.ndarray):
    """Apparent luminance (H, W, 3) cd/m^2 -> Combined (RGBA, alpha 1) and the Y pass; rows go
    bottom-up (Blender's row 0 is the bottom row), contiguous float32, one foreach_set per pass."""
    h, w = image.shape[:2]
    for name, (channels, chan_id, _) in PASSES.items():
        engine.add_pass(name, channels, chan_id)
    rr = engine.begin_result(0, 0, w, h)
    layer = rr.layers[0]
    flipped = image[::-1]
    rgba = np.concatenate([flipped, np.ones((h, w, 1), np.float32)], axis=2)
    layer.passes["Combined"].rect.foreach_set(np.ascontiguousarray(rgba, dtype=np.float32).ravel())
    y = np.ascontiguousarray(flipped @ Y_WEIGHTS.astype(np.float32), dtype=np.float32)
    layer.passes["Y"].rect.foreach_set(y.ravel())
    engine.end_result(rr)


class HudRenderEngine(bpy.types.RenderEngine):
    bl_idname = "HUD_TRACER"
    bl_label = "HUD Tracer"
    bl_use_preview = False
    bl_use_shading_nodes_custom = False

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)  # required since Blender 4.4

    def render(self, depsgraph):
        render_final(self, depsgraph)

    def update_render_passes(self, scene=None, renderlayer=None):
        self.register_pass(scene, renderlayer, "Combined", 4, "RGBA", "COLOR")
        for name, (channels, chan_id, kind) in PASSES.items():
            self.register_pass(scene, renderlayer, name, channels, chan_id, kind)

register, unregister = bpy.utils.register_classes_factory((HudRenderEngine,))
