"""The environment block of scene.json (tracer.scene.environment.environment_from_spec): none, uniform,
HDRI panoramas with their calibrations and the sun, and every bad value named by its field."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import OpenImageIO as oiio
import pytest

from tests.support.environment import radiance_rows
from tracer.core.errors import SceneError
from tracer.core.imageio import write_exr
from tracer.scene.environment import environment_from_spec
from tracer.sources.environment import (
    HdriEnvironment,
    NoEnvironment,
    UniformEnvironment,
)
from tracer.sources.sun import EnvironmentWithSun

# --- environment_from_spec ------------------------------------------------------------------


@pytest.fixture
def scene_dir(tmp_path):
    """A scene folder with panoramas good and bad."""
    textures = tmp_path / "textures"
    textures.mkdir()
    rng = np.random.default_rng(14)
    rgb = rng.random((8, 16, 3))
    write_exr(textures / "sky.exr", {"R": rgb[..., 0], "G": rgb[..., 1], "B": rgb[..., 2]})
    write_exr(textures / "black.exr", {c: np.zeros((4, 8)) for c in "RGB"})
    one_black = np.ones((4, 8))
    one_black[1, 3] = 0.0
    write_exr(textures / "one_black.exr", {c: one_black for c in "RGB"})
    write_exr(textures / "negative.exr", {c: np.full((4, 8), -1.0) for c in "RGB"})
    write_exr(textures / "five.exr", {c: np.ones((4, 8)) for c in ["R", "G", "B", "Y", "Y_var"]})
    write_exr(textures / "rgba.exr", {"R": np.ones((4, 8)), "G": np.ones((4, 8)),
                                      "B": np.ones((4, 8)), "A": np.full((4, 8), 0.5)})
    grey = oiio.ImageOutput.create("png")
    assert grey.open(str(textures / "grey.png"), oiio.ImageSpec(8, 4, 1, oiio.UINT8))
    assert grey.write_image(np.full((4, 8, 1), 128, np.uint8)) and grey.close()
    (textures / "corrupt.exr").write_bytes(b"not an EXR file at all")
    return tmp_path


def test_spec_none_and_uniform(scene_dir):
    assert isinstance(environment_from_spec({"type": "none"}, scene_dir), NoEnvironment)
    env = environment_from_spec({"type": "uniform", "luminance": 10}, scene_dir)
    assert isinstance(env, UniformEnvironment) and env.mean_luminance == 10.0
    env = environment_from_spec(_uniform(luminance=5.0, color=[0, 1, 0]), scene_dir)
    np.testing.assert_allclose(radiance_rows(env, np.array([[0, 0, 1.0]])), [[0, 5.0 / 0.7152, 0]])


def test_spec_hdri(scene_dir):
    spec = {
        "type": "hdri",
        "file": "textures/sky.exr",
        "calibration": {"mode": "mean", "value": 800},
        "rotation_deg": 45,
    }
    env = environment_from_spec(spec, scene_dir)
    assert isinstance(env, HdriEnvironment)
    assert env.mean_luminance == pytest.approx(800.0, rel=1e-9)
    assert env.rotation_deg == 45.0 and env.source == "textures/sky.exr"
    assert env.calibration == "mean" and env.value == 800.0 and env.scale_factor > 0


def test_spec_sun(scene_dir):
    env = environment_from_spec({"type": "none", "sun": {"direction": [0, 0, 2]}}, scene_dir)
    assert isinstance(env, EnvironmentWithSun) and isinstance(env.base, NoEnvironment)
    sun = env.sun
    np.testing.assert_array_equal(sun.direction, [0.0, 0.0, 1.0])
    assert (sun.illuminance_lux, sun.angular_diameter_deg) == (100_000.0, 0.53)
    np.testing.assert_allclose(sun.color, 1.0)
    assert env.max_luminance == pytest.approx(1.488e9, rel=1e-3) and env.sun_share == 1.0
    spec = {"type": "uniform", "luminance": 50,
            "sun": {"direction": [1, 0, 1], "illuminance_lux": 60_000, "angular_diameter_deg": 2.0,
                    "color": [1.0, 0.9, 0.8]}}
    env = environment_from_spec(spec, scene_dir)
    assert env.base.mean_luminance == 50.0 and env.sun.illuminance_lux == 60_000.0
    assert env.sun.angular_diameter_deg == 2.0
    np.testing.assert_allclose(env.sun.direction, [math.sqrt(0.5), 0.0, math.sqrt(0.5)])
    np.testing.assert_allclose(env.sun.color / env.sun.color[0], [1.0, 0.9, 0.8])
    env = environment_from_spec(_hdri(calibration={"mode": "mean", "value": 800},
                                      sun={"direction": [0, 1, 0.2]}), scene_dir)
    assert isinstance(env.base, HdriEnvironment) and env.base.mean_luminance == pytest.approx(800.0)
    assert env.mean_luminance == pytest.approx(800.0 + env.sun.power / (4 * math.pi))


def test_spec_hdri_grey_png_is_decoded_and_grey(scene_dir):
    env = environment_from_spec(_hdri(file="textures/grey.png", rotation_deg=10), scene_dir)
    np.testing.assert_allclose(radiance_rows(env, np.array([[1.0, 0, 0]])), [[0.2158605] * 3], rtol=1e-6)


def test_spec_hdri_drops_alpha(scene_dir):
    env = environment_from_spec(_hdri(file="textures/rgba.exr"), scene_dir)
    np.testing.assert_array_equal(radiance_rows(env, np.array([[0, 0, 1.0]])), [[1.0, 1.0, 1.0]])


def _hdri(**fields):
    calibration = {"mode": "scale", "value": 1}
    return {"type": "hdri", "file": "textures/sky.exr", "calibration": calibration, **fields}


def _uniform(**fields):
    return {"type": "uniform", "luminance": 1.0, **fields}


def _sun(**fields):
    return {"type": "none", "sun": {"direction": [0, 0, 1], **fields}}


@pytest.mark.parametrize(
    ("spec", "field"),
    [
        ("none", "environment"),
        ({}, "environment.type"),
        ({"type": "sky"}, "environment.type"),
        ({"type": 3}, "environment.type"),
        ({"type": ["hdri"]}, "environment.type"),
        ({"type": "none", "luminance": 1}, "environment.luminance"),
        ({"type": "uniform"}, "environment.luminance"),
        (_uniform(luminance=-1), "environment.luminance"),
        (_uniform(luminance="10"), "environment.luminance"),
        (_uniform(luminance=True), "environment.luminance"),
        (_uniform(luminance=float("nan")), "environment.luminance"),
        (_uniform(luminance=None), "environment.luminance"),
        # positive but below 1e-9 cd/m^2: a black image and no warning before (2026-12-04)
        (_uniform(luminance=1e-300), "environment.luminance"),
        (_uniform(luminance=1e-10), "environment.luminance"),
        (_uniform(color=[1, 1]), "environment.color"),
        (_uniform(color="white"), "environment.color"),
        (_uniform(color=[1, -1, 1]), "environment.color[1]"),
        (_uniform(color=[1, 1, "1"]), "environment.color[2]"),
        (_uniform(color=[0, 0, 0]), "environment.color"),
        (_uniform(colour=[1, 1, 1]), "environment.colour"),
        ({"type": "hdri", "calibration": {"mode": "scale", "value": 1}}, "environment.file"),
        (_hdri(file=3), "environment.file"),
        (_hdri(file=""), "environment.file"),
        (_hdri(file="textures/missing.exr"), "environment.file"),
        (_hdri(file="textures/corrupt.exr"), "environment.file"),
        (_hdri(file="textures/five.exr"), "environment.file"),
        (_hdri(file="textures/negative.exr"), "environment.file"),
        (_hdri(file="textures/black.exr", calibration={"mode": "mean", "value": 1}),
         "environment.file"),
        (_hdri(file="textures/one_black.exr", calibration={"mode": "min", "value": 1}),
         "environment.file"),
        ({"type": "hdri", "file": "textures/sky.exr"}, "environment.calibration"),
        (_hdri(calibration="mean"), "environment.calibration"),
        (_hdri(calibration={"value": 1}), "environment.calibration.mode"),
        (_hdri(calibration={"mode": "median", "value": 1}), "environment.calibration.mode"),
        (_hdri(calibration={"mode": "mean"}), "environment.calibration.value"),
        (_hdri(calibration={"mode": "mean", "value": 0}), "environment.calibration.value"),
        (_hdri(calibration={"mode": "max", "value": -5}), "environment.calibration.value"),
        (_hdri(calibration={"mode": "min", "value": 0}), "environment.calibration.value"),
        (_hdri(calibration={"mode": "min", "value": 2e12}), "environment.calibration.value"),
        (_hdri(calibration={"mode": "max", "value": "5"}), "environment.calibration.value"),
        (_hdri(calibration={"mode": "scale", "value": 1e-12}), "environment.calibration.value"),
        (_hdri(calibration={"mode": "max", "value": 1e-10}), "environment.calibration.value"),
        (_hdri(calibration={"mode": "max", "value": 5, "unit": "nit"}),
         "environment.calibration.unit"),
        (_hdri(rotation_deg="90"), "environment.rotation_deg"),
        (_hdri(rotation_deg=float("inf")), "environment.rotation_deg"),
        (_hdri(rotation=90), "environment.rotation"),
        ({"type": "none", "sun": "up"}, "environment.sun"),
        ({"type": "none", "sun": {}}, "environment.sun.direction"),
        (_sun(direction=[0, 0, 0]), "environment.sun.direction"),
        (_sun(direction=[0, 1]), "environment.sun.direction"),
        (_sun(direction=[0, 1, "1"]), "environment.sun.direction[2]"),
        (_sun(direction=[0, 1, float("nan")]), "environment.sun.direction[2]"),
        (_sun(illuminance_lux=-1), "environment.sun.illuminance_lux"),
        (_sun(illuminance_lux="100 klx"), "environment.sun.illuminance_lux"),
        (_sun(illuminance_lux=2e12), "environment.sun.illuminance_lux"),
        (_sun(illuminance_lux=1e-300), "environment.sun.illuminance_lux"),
        (_sun(angular_diameter_deg=0), "environment.sun.angular_diameter_deg"),
        (_sun(angular_diameter_deg=-0.5), "environment.sun.angular_diameter_deg"),
        (_sun(angular_diameter_deg=20.01), "environment.sun.angular_diameter_deg"),
        (_sun(illuminance_lux=1e6, angular_diameter_deg=1e-4), "environment.sun"),
        (_sun(color=[0, 0, 0]), "environment.sun.color"),
        (_sun(color=[1, -1, 1]), "environment.sun.color[1]"),
        (_sun(elevation_deg=30), "environment.sun.elevation_deg"),
        (_uniform(sun={"direction": [0, 0, 1], "illuminance": 1}), "environment.sun.illuminance"),
        (_hdri(sun={"illuminance_lux": 1}), "environment.sun.direction"),
    ],
)
def test_spec_errors_name_the_field(scene_dir, spec, field):
    with pytest.raises(SceneError) as info:
        environment_from_spec(spec, scene_dir, file="scenes/demo/scene.json")
    assert info.value.field == field
    assert info.value.file == "scenes/demo/scene.json"


def test_unknown_names_are_shown_as_json_not_as_python():
    """A list where a name belongs was echoed as Python's repr (['none'])."""
    for spec, shown in (({"type": ["none"]}, 'unknown type ["none"] (known: none, uniform, hdri)'),
                        (_hdri(calibration={"mode": ["mean"], "value": 1}), 'unknown mode ["mean"] (known: scale')):
        with pytest.raises(SceneError) as info:
            environment_from_spec(spec, Path("."))
        assert shown in info.value.message
    assert info.value.message


def test_spec_hdri_min(scene_dir):
    env = environment_from_spec(_hdri(calibration={"mode": "min", "value": 25}), scene_dir)
    assert env.calibration == "min" and env.min_luminance == pytest.approx(25.0, rel=1e-12)
    with pytest.raises(SceneError) as info:
        environment_from_spec(_hdri(file="textures/one_black.exr", calibration={"mode": "min", "value": 1}),
                              scene_dir)
    assert "textures/one_black.exr" in info.value.message and "black" in info.value.message


def test_spec_unreadable_image_reports_the_reason(scene_dir):
    with pytest.raises(SceneError) as info:
        environment_from_spec(_hdri(file="textures/missing.exr"), scene_dir)
    assert "textures/missing.exr" in info.value.message
    assert info.value.file == "scene.json"
