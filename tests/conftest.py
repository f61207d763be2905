"""Shared helpers: scene folders written by presets or by hand, and renders held in memory."""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from tracer.integrators import INTEGRATORS, Budget  # noqa: E402
from tracer.scene import load_scene  # noqa: E402
from tracer.units import Y_WEIGHTS  # noqa: E402


#: Sidak-corrected two-sided z bound for alpha = 0.01 over m comparisons.
def z_bound(m: int, alpha: float = 0.01) -> float:
    from statistics import NormalDist

    a = 1 - (1 - alpha) ** (1 / m)
    return NormalDist().inv_cdf(1 - a / 2)


def render(scene_dir, method: str, rays: int, seed: int = 1, batch_size: int | None = None, edit=None):
    """Render in memory: (Y (H, W), variance of Y (H, W), RenderResult)."""
    scene = load_scene(scene_dir)
    if edit is not None:
        edit(scene)
    kw = {"batch_size": batch_size} if batch_size else {}
    integ = INTEGRATORS[method](scene, seed, **kw)
    res = integ.render(Budget(rays=rays))
    rgb = res.film.rgb()
    return rgb @ Y_WEIGHTS, res.film.variance_y(), res


def edit_json(folder: Path, fn):
    p = Path(folder) / "scene.json"
    data = json.loads(p.read_text())
    fn(data)
    p.write_text(json.dumps(data))


@pytest.fixture
def preset(tmp_path):
    from presets import PRESETS

    def make(name, **kw):
        return PRESETS[name].write(tmp_path / name, **kw)

    return make


__all__ = ["z_bound", "render", "edit_json", "math", "np"]
