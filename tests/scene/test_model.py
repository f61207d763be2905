"""The scene model (tracer.scene.model): a scene object's axes follow its transform."""

import math

import numpy as np
import pytest

from tracer.scene import SceneObject


def test_scene_object_axes_follow_the_transform():
    o = SceneObject("x", 0, np.zeros((3, 3)), np.zeros((1, 3), np.int64), None, local_x=np.array([0.0, 1.0, 0.0]),
                    local_y=np.array([0.0, 0.0, 1.0]))
    assert o.axis(90.0) == pytest.approx([0.0, 0.0, 1.0], abs=1e-12)
    assert o.axis(45.0) == pytest.approx([0.0, math.sqrt(0.5), math.sqrt(0.5)])
