"""analytic-disk: a Lambertian disk emitter over a Lambertian plane.

Closed form: the illuminance at the foot of the disk's axis is E = pi L sin^2(alpha), with
sin(alpha) = r / sqrt(r^2 + h^2) (Lambert's disk source; e.g. Ryer, Light Measurement Handbook). The
eye looks at the foot; the plane (albedo rho) there reads rho E / pi = rho L sin^2(alpha) cd/m^2.
The disk is a polygon of SEGMENTS sides, which has 1e-4 less area than the circle, and the eye sees a
patch 2 mm wide around the foot: :func:`polygon_illuminance_lx` gives the exact illuminance of the
polygon at any floor point (Lambert's contour formula), for tests that resolve 1e-4.
"""

import math
from pathlib import Path

import numpy as np

from ._build import SceneBuilder, disk, frame_matrix, rectangle

NAME = "analytic-disk"
SUMMARY = "disk emitter over a Lambertian plane: the foot reads rho L sin^2(alpha) (E = pi L sin^2 alpha)"
L = 1000.0    # cd/m^2
RADIUS = 50.0  # mm
HEIGHT = 100.0  # mm
RHO = 0.5


def expected_luminance() -> float:
    """Apparent luminance (cd/m^2) of the plane at the foot of the disk."""
    return RHO * L * RADIUS**2 / (RADIUS**2 + HEIGHT**2)


def expected_illuminance_lx() -> float:
    return math.pi * L * RADIUS**2 / (RADIUS**2 + HEIGHT**2)


SEGMENTS = 256


def polygon_illuminance_lx(points: np.ndarray) -> np.ndarray:
    """Illuminance (lx) of the floor (normal +z) at ``points`` (k, 3) mm from the disk as built, a regular
    polygon of SEGMENTS sides: E = (L / 2) |sum over edges of theta_i (R_i x R_i+1 / |R_i x R_i+1|) . z|,
    R the vectors to consecutive corners, theta_i the angle between them (Lambert's formula for a
    polygonal source; Howell, A Catalog of Radiation Heat Transfer Configuration Factors, B-2)."""
    ang = np.linspace(0, 2 * np.pi, SEGMENTS, endpoint=False)
    corners = np.stack([RADIUS * np.cos(ang), RADIUS * np.sin(ang), np.full(SEGMENTS, HEIGHT)], 1)
    r = corners[None, :, :] - np.asarray(points, dtype=np.float64)[:, None, :]  # (k, N, 3)
    r1 = np.roll(r, -1, axis=1)
    c = np.cross(r, r1)
    cos = (r * r1).sum(-1) / (np.linalg.norm(r, axis=-1) * np.linalg.norm(r1, axis=-1))
    theta = np.arccos(np.clip(cos, -1, 1))
    return L * 0.5 * np.abs((theta * c[..., 2] / np.linalg.norm(c, axis=-1)).sum(1))


def write(folder, resolution=(15, 15)) -> Path:
    sb = SceneBuilder(Path(folder), NAME, SUMMARY)
    sb.add("floor", rectangle(4000, 4000), {"type": "lambertian", "reflectance": RHO,
                                            "aim": {"target": "eye", "share": 0.5}})
    sb.add("disk", disk(RADIUS, SEGMENTS), {"type": "absorber"}, frame_matrix([0, 0, HEIGHT], [1, 0, 0], [0, 0, -1]),
           emission={"luminance": L})
    # The eye looks at the foot (origin) from 50 deg elevation, 400 mm away, beside the disk.
    el = math.radians(50)
    pos = np.array([0.0, -400 * math.cos(el), 400 * math.sin(el)])
    gaze = -pos / np.linalg.norm(pos)
    return sb.write(eye={"position": pos.tolist(), "gaze": gaze.tolist(), "up": [0, 0, 1],
                         "pupil_diameter_mm": 4.0, "focal_length_mm": 16.67,
                         "accommodation_distance_mm": 400.0,
                         "resolution": list(resolution), "fov_deg": [0.3, 0.3]})
