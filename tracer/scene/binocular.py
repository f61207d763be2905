"""The two eyes of a binocular pair: the scene's eye moved by half the interpupillary distance
(``target.ipd_mm``, 65 mm by default) to either side across the vehicle's forward direction (the
target block's ``forward`` and ``up``; absent: the eye's gaze made horizontal, and the world's z), as
the optical analysis places its pairs (tracer.analysis.optics). Renders use it for ``--eye left``,
``right`` and ``both``, so that users see what each eye sees (vertical and horizontal disparity,
a ghost or a distortion one eye sees more of)."""

from __future__ import annotations

import dataclasses

import numpy as np

from .model import EyeSpec, Scene

#: The eye a render sees through: the scene's own (the design eye point), or one of a pair's.
SIDES = ("centre", "left", "right")


def right_axis(scene: Scene) -> np.ndarray:
    """The vehicle's right (unit (3,) world vector): forward x up."""
    t = scene.target
    up = np.asarray(t.get("up", (0.0, 0.0, 1.0)), dtype=np.float64)
    up = up / np.linalg.norm(up)
    forward = t.get("forward")
    if forward is None:
        gaze = np.asarray(scene.eye.gaze, dtype=np.float64)
        forward = gaze - (gaze @ up) * up
        if np.linalg.norm(forward) < 1e-6:
            raise ValueError("the eye looks straight up or down: give target.forward for its pair of eyes")
    right = np.cross(np.asarray(forward, dtype=np.float64), up)
    return right / np.linalg.norm(right)


def eye_for(scene: Scene, side: str) -> EyeSpec:
    """The scene's eye seen from ``side`` (:data:`SIDES`): moved by -IPD / 2 (left) or +IPD / 2 (right)
    along :func:`right_axis`, mm; the same gaze, pupil and focus."""
    if side not in SIDES:
        raise ValueError(f"eye side {side!r}: one of {', '.join(SIDES)}")
    if side == "centre":
        return scene.eye
    half = 0.5 * float(scene.target.get("ipd_mm", 65.0))
    shift = (-half if side == "left" else half) * right_axis(scene)
    return dataclasses.replace(scene.eye, position=np.asarray(scene.eye.position, dtype=np.float64) + shift)
