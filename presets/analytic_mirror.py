"""analytic-mirror: a Lambertian panel of luminance L seen through a flat mirror of reflectance R.

Closed form (brightness theorem): every pixel that sees the panel in the mirror reads L R.
The forward method aims the panel's emission at a virtual aperture: the mirror image of the eye pupil,
i.e. the entrance pupil of the one-mirror "optical system" (paper sec. 2, directed sampling).
"""

from pathlib import Path

import numpy as np

from ._build import SceneBuilder, disk, frame_matrix, rectangle

NAME = "analytic-mirror"
SUMMARY = "Lambertian panel (1000 cd/m^2) seen in a mirror of R = 0.85: covered pixels read 850 cd/m^2"
L = 1000.0  # cd/m^2
R = 0.85


def write(folder, pupil_mm: float = 4.0, resolution=(64, 48)) -> Path:
    sb = SceneBuilder(Path(folder), NAME, SUMMARY)
    # Mirror in the plane y = 300 tilted 45 deg: the eye at the origin looks along +y and sees down (-z).
    m_center = np.array([0.0, 300.0, 0.0])
    m_normal = np.array([0.0, -1.0, -1.0]) / np.sqrt(2)
    sb.add("mirror", rectangle(160, 160), {"type": "mirror", "reflectance": R},
           frame_matrix(m_center, [1, 0, 0], m_normal))
    # Panel below the mirror facing up (+z): seen by the eye through the mirror.
    p_center = np.array([0.0, 300.0, -300.0])
    # The mirror image of the pupil, where the panel's light must go to reach the eye.
    eye = np.zeros(3)
    image = eye - 2 * ((eye - m_center) @ m_normal) * m_normal
    image_normal = np.array([0.0, 0.0, -1.0])  # the mirrored gaze (+y) becomes -z
    sb.add("pupil_image", disk(pupil_mm / 2, 64), {"type": "aperture"},
           frame_matrix(image, [1, 0, 0], image_normal))
    sb.add("panel", rectangle(120, 120), {"type": "absorber"}, frame_matrix(p_center, [1, 0, 0], [0, 0, 1]),
           emission={"luminance": L, "aim": {"target": "pupil_image", "share": 0.9}})
    return sb.write(eye={"position": eye.tolist(), "gaze": [0, 1, 0], "up": [0, 0, 1],
                         "pupil_diameter_mm": pupil_mm, "focal_length_mm": 16.67,
                         "accommodation_distance_mm": 600.0,
                         "resolution": list(resolution), "fov_deg": [30.0, 22.5]})
