"""The studio panoramas that ship inside the bpy package (presets/hdri.py): found without importing bpy, or
inside Blender itself, a clear message where they are missing, and their statistics."""

from __future__ import annotations

import ast
import importlib.util
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from tests.support.paths import ROOT
from tracer.core.imageio import write_exr
from tracer.core.units import luminance
from tracer.scene.environment import environment_from_spec
from tracer.sources.environment import (
    row_solid_angle_fractions,
)

_NO_BPY = importlib.util.find_spec("bpy") is None
_needs_bpy = pytest.mark.skipif(_NO_BPY, reason="the studio panoramas ship inside the bpy package "
                                                "(pip install bpy==4.5.15)")


@_needs_bpy
def test_studio_hdri_finds_every_panorama_without_importing_bpy():
    """Each of the eight panoramas is found inside the installed bpy package, in a child process that
    never imports bpy (importing it takes seconds), and loads as an environment."""
    from presets.hdri import STUDIO_HDRIS

    code = ("import sys; from presets.hdri import STUDIO_HDRIS, studio_hdri; "
            "print([str(studio_hdri(n)) for n in STUDIO_HDRIS]); print('bpy' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True,
                         cwd=ROOT).stdout.splitlines()
    paths = [Path(p) for p in ast.literal_eval(out[0])]
    assert out[1] == "False"
    package = Path(importlib.util.find_spec("bpy").origin).parent
    for name, path in zip(STUDIO_HDRIS, paths, strict=True):
        assert path.name == f"{name}.exr" and path.is_file() and path.is_relative_to(package)
    env = environment_from_spec({"type": "hdri", "file": str(paths[0]), "calibration": {"mode": "mean", "value": 2e3}},
                                Path("."), allow_external=True)
    assert env.mean_luminance == pytest.approx(2000.0)


def test_studio_hdri_says_where_the_panorama_comes_from(monkeypatch):
    """Without bpy: one ValueError naming the panorama, the bpy package, its pip line and the way out (a
    file); an unknown name lists the eight."""
    import presets.hdri as hdri

    monkeypatch.setattr(hdri.importlib.util, "find_spec", lambda name: None)
    with pytest.raises(ValueError) as info:
        hdri.studio_hdri("forest")
    message = str(info.value)
    for words in ("'forest'", "bpy", "pip install bpy==4.5.15", "file"):
        assert words in message, message
    with pytest.raises(ValueError, match="city, courtyard, forest, interior, night, studio, sunrise, sunset"):
        hdri.studio_hdri("beach")


def test_studio_hdri_inside_blender(tmp_path, monkeypatch):
    """Inside Blender itself bpy is <version>/scripts/modules/bpy and the panoramas are in
    <version>/datafiles/studiolights/world: found there too."""
    import types

    import presets.hdri as hdri

    package = tmp_path / "4.5" / "scripts" / "modules" / "bpy"
    package.mkdir(parents=True)
    (package / "__init__.py").write_text("")
    world = tmp_path / "4.5" / "datafiles" / "studiolights" / "world"
    world.mkdir(parents=True)
    (world / "night.exr").write_bytes(b"exr")
    monkeypatch.setattr(hdri.importlib.util, "find_spec",
                        lambda name: types.SimpleNamespace(origin=str(package / "__init__.py")))
    assert hdri.studio_hdri("night") == world / "night.exr"
    with pytest.raises(ValueError, match="pip install"):
        hdri.studio_hdri("city")


def test_panorama_stats_against_a_panorama_of_known_figures(tmp_path):
    """An 8 x 16 panorama whose row i (0 at the top) has luminance i + 1, one pixel of the top row black:
    min 0, max 8, the mean over the rows' exact solid angles, and percentiles by solid angle: the top row
    (3.8 % of the sphere) holds the 1st percentile's value 1 (the black pixel covers only 0.24 %), the
    bottom row (the same 3.8 %) the 99th's value 8."""
    from presets.hdri import panorama_stats

    rows = np.arange(1.0, 9.0)
    image = np.repeat(np.repeat(rows[:, None], 16, axis=1)[..., None], 3, axis=2)
    image[0, 3] = 0.0
    write_exr(tmp_path / "rows.exr", {c: image[..., i] for i, c in enumerate("RGB")})
    st = panorama_stats(tmp_path / "rows.exr")
    f = row_solid_angle_fractions(8)
    assert (st["min"], st["max"], st["black_pixels"], st["negative_values"]) == (0.0, 8.0, 1, 0)
    assert (st["width"], st["height"]) == (16, 8)
    assert st["mean"] == pytest.approx(f @ rows - f[0] / 16 * 1.0, rel=1e-12)
    assert f[0] / 16 < 0.01 < f[0] and f[-1] > 0.01
    assert st["p01"] == 1.0 and st["p99"] == 8.0


@_needs_bpy
@pytest.mark.parametrize("name", ["city", "night"])
def test_panorama_stats_of_a_studio_panorama_agree_with_the_environment(name, tmp_path):
    """The panorama copied into a scene folder (copy_panorama: night.exr has 250 slightly negative colour
    components from its lossy compression, city.exr none) loads as an environment whose min, mean and max
    (scale 1) are the copy's figures; the percentiles cut the sphere's solid angle at 1 % and 99 % (the
    pixels below p01 cover less than 1 % of it, those at or below it at least 1 %)."""
    from presets.hdri import copy_panorama, panorama_stats, studio_hdri
    from tracer.core.imageio import read_image

    raw = panorama_stats(studio_hdri(name))
    negative = copy_panorama(studio_hdri(name), tmp_path / "textures" / "sky.exr")
    assert negative == raw["negative_values"] and (negative > 0) == (name == "night")
    st = panorama_stats(tmp_path / "textures" / "sky.exr")
    assert st["negative_values"] == 0 and st["mean"] == pytest.approx(raw["mean"], rel=1e-6)
    env = environment_from_spec({"type": "hdri", "file": "textures/sky.exr", "calibration": {"mode": "scale",
                                                                                             "value": 1}}, tmp_path)
    assert st["mean"] == pytest.approx(env.mean_luminance, rel=1e-12)
    assert st["min"] == pytest.approx(env.min_luminance, rel=1e-12)
    assert st["max"] == pytest.approx(env.max_luminance, rel=1e-12)
    y = luminance(read_image(tmp_path / "textures" / "sky.exr")[..., :3])
    omega = np.broadcast_to(row_solid_angle_fractions(y.shape[0])[:, None] / y.shape[1], y.shape)
    for q, value in ((0.01, st["p01"]), (0.99, st["p99"])):
        assert omega[y < value].sum() < q <= omega[y <= value].sum()
    assert st["min"] < st["p01"] < st["mean"] and st["p99"] < st["max"]
