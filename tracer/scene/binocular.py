"""The two eyes of a binocular pair: the scene's eye moved by half the interpupillary distance
(``target.ipd_mm``, 65 mm by default) to either side across the vehicle's forward direction (the
target block's ``forward`` and ``up``; absent: the eye's gaze made horizontal, and the world's z), as
the optical analysis places its pairs (tracer.analysis.optics). Renders use it for ``--eye left``,
``right`` and ``both``, so that users see what each eye sees (vertical and horizontal disparity,
a ghost or a distortion one eye sees more of)."""

from __future__ import annotations

import dataclasses

import numpy as np

from ..core.errors import SceneError
from .model import EyeSpec, Scene

#: The eye a render sees through: the scene's own (the design eye point), or one of a pair's.
SIDES = ("centre", "left", "right")


def vehicle_axes(scene: Scene) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The vehicle's axes (unit (3,) world vectors: forward, right, up) that the optical analysis reads
    angles in and its pairs of eyes lie along: ``target.up`` (the world's z), and ``target.forward`` or
    else the eye's gaze, made horizontal. Raises :class:`~tracer.core.errors.SceneError` naming
    ``target.forward`` where it is absent and the gaze is vertical."""
    t = scene.target
    up = np.asarray(t.get("up", (0.0, 0.0, 1.0)), dtype=np.float64)
    up = up / np.linalg.norm(up)
    forward = np.asarray(t["forward"] if t.get("forward") is not None else scene.eye.gaze, dtype=np.float64)
    forward = forward - (forward @ up) * up
    if np.linalg.norm(forward) < 1e-6:
        raise SceneError(scene.file, "target.forward", "the eye looks straight up or down, so its gaze gives no "
                                                      "forward direction: give the vehicle's forward")
    forward = forward / np.linalg.norm(forward)
    return forward, np.cross(forward, up), up


def right_axis(scene: Scene) -> np.ndarray:
    """The vehicle's right (unit (3,) world vector): :func:`vehicle_axes`'s."""
    return vehicle_axes(scene)[1]


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
