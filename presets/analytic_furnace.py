"""analytic-furnace: the eye inside a closed Lambertian emitter sphere of luminance L0.

Closed form: every pixel shows L0, whatever the pupil, the focus or the field angle (paper eq. 2-3 with
the exact pupil extent of tracer.transport.eye). Both methods apply: backward rays hit the sphere, forward
particles leave it (aimed at the pupil).
"""

from pathlib import Path

from ._build import SceneBuilder, sphere

NAME = "analytic-furnace"
SUMMARY = "eye inside a uniform emitter sphere of 100 cd/m^2: every pixel must read 100 cd/m^2"
L0 = 100.0  # cd/m^2


def write(folder, pupil_mm: float = 4.0, accommodation_mm: float = 500.0, fov_deg=(60.0, 40.0),
          resolution=(48, 32)) -> Path:
    sb = SceneBuilder(Path(folder), NAME, SUMMARY)
    sb.add("surround", sphere(1000.0, subdivisions=4, inward=True), {"type": "absorber"},
           emission={"luminance": L0, "aim": {"target": "eye", "share": 0.95}})
    return sb.write(eye={"position": [0, 0, 0], "gaze": [0, 1, 0], "up": [0, 0, 1],
                         "pupil_diameter_mm": pupil_mm, "focal_length_mm": 16.67,
                         "accommodation_distance_mm": accommodation_mm,
                         "resolution": list(resolution), "fov_deg": list(fov_deg)})
