"""analytic-disk: a Lambertian disk emitter over a Lambertian plane.

Closed form: the illuminance at the foot of the disk's axis is E = pi L sin^2(alpha), with
sin(alpha) = r / sqrt(r^2 + h^2) (Lambert's disk source; e.g. Ryer, Light Measurement Handbook). The
eye looks at the foot; the plane (albedo rho) there reads rho E / pi = rho L sin^2(alpha) cd/m^2.
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


def write(folder, resolution=(15, 15)) -> Path:
    sb = SceneBuilder(Path(folder), NAME, SUMMARY)
    sb.add("floor", rectangle(4000, 4000), {"type": "lambertian", "reflectance": RHO,
                                            "aim": {"target": "eye", "share": 0.5}})
    sb.add("disk", disk(RADIUS, 256), {"type": "absorber"}, frame_matrix([0, 0, HEIGHT], [1, 0, 0], [0, 0, -1]),
           emission={"luminance": L})
    # The eye looks at the foot (origin) from 50 deg elevation, 400 mm away, beside the disk.
    el = math.radians(50)
    pos = np.array([0.0, -400 * math.cos(el), 400 * math.sin(el)])
    gaze = -pos / np.linalg.norm(pos)
    return sb.write(eye={"position": pos.tolist(), "gaze": gaze.tolist(), "up": [0, 0, 1],
                         "pupil_diameter_mm": 4.0, "focal_length_mm": 16.67,
                         "accommodation_distance_mm": 400.0,
                         "resolution": list(resolution), "fov_deg": [0.3, 0.3]})
