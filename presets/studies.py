"""The paper's studies of a HUD against the real world (sec. 4.1, Figs. 8-10; sec. 4.2, Fig. 13), as one
function that turns a HUD preset into a study: a wider view than the HUD's own (so that the eye sees
the road and the sky around the symbols and adapts to them), a real HDR panorama behind the
windshield calibrated to cd/m^2, the LEDs set for the symbol luminance of the study, an eye whose
pupil follows the luminance it adapts to, and the hybrid method (the HUD channel and the environment
channel, each by the method its pilots choose).

The panoramas are Blender's own studio lights, found inside the bpy package (presets/hdri.py): no
image is committed. The paper's panoramas are not published, so each study keeps one of its figures:
the day panorama is scaled so that the directions the eye sees average the paper's adaptation
luminance (a whole panorama's mean is mostly its sun), the night panorama's minimum is the paper's
34 cd/m^2; docs/results/studies.md sets the other figures beside the paper's.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from . import hud_direct
from ._build import write_obj
from .hdri import copy_panorama, studio_hdri

try:  # inside the Blender extension, presets and tracer are subpackages of the extension package
    from ..tracer.core.imageio import read_image
    from ..tracer.core.units import luminance
    from ..tracer.scene import load_scene
    from ..tracer.sources.environment import HdriEnvironment
    from ..tracer.transport.eye import ThinLensEye
except ImportError:  # presets and tracer as top-level packages (command line, tests)
    from tracer.core.imageio import read_image
    from tracer.core.units import luminance
    from tracer.scene import load_scene
    from tracer.sources.environment import HdriEnvironment
    from tracer.transport.eye import ThinLensEye

#: The study's view: full field (deg) and retina, 30 pixels per degree (the HUD presets' own view is
#: 7 x 2.6 deg at 60 px/deg: the symbols alone).
VIEW_DEG = (24.0, 14.0)
RESOLUTION = (480, 280)


#: The dashboard: a black plane DASH_HEIGHT mm above the HUD's mirror (just below the windshield's lower
#: edge), DASH_SIZE mm, with an opening of DASH_OPENING mm where the mirror's light rises to the
#: windshield, over a black well (WELL, mm: x half-width, y from, y to, floor z) that holds the HUD's
#: optics. Without them the windshield's inner surface (and its outer one, from inside the glass) would
#: reflect the panorama's ground into the view everywhere but over the HUD (14 % at 67 deg); a car's
#: dark dashboard takes its place (black here: a grey one would show its opening in the reflection).
DASH_HEIGHT = 120.0
#: The dashboard's extent (x half-width; y from the driver's side to just past the windshield's lower edge,
#: so that the eye still sees the road beyond it at the HUD's look-down angle), mm.
DASH_HALF_X, DASH_Y = 800.0, (-900.0, 60.0)
DASH_OPENING = (240.0, 220.0)
WELL = (170.0, -430.0, 70.0, -80.0)


def _panel(name: str, corner: np.ndarray, a: np.ndarray, b: np.ndarray):
    """A flat quadrilateral corner, corner + a, corner + a + b, corner + b: (name, vertices, faces)."""
    v = np.array([corner, corner + a, corner + a + b, corner + b])
    return name, v, np.array([[0, 1, 2], [0, 2, 3]])


def dashboard() -> list[tuple[str, np.ndarray, np.ndarray, dict]]:
    """(name, vertices (v, 3) world mm, faces (f, 3), material) of the dashboard's four panels around its
    opening and of the well below it (:data:`DASH_HEIGHT`, :data:`WELL`); the hud-direct design's mirror
    and windshield point place the opening (hud-screen shares them)."""
    d = hud_direct.design()
    mirror, top = np.asarray(d["mirror"], float), np.asarray(d["w_point"], float)
    centre = mirror + (DASH_HEIGHT - mirror[2]) / (top[2] - mirror[2]) * (top - mirror)
    ow, oh = DASH_OPENING
    hx0, hx1, hy0, hy1 = centre[0] - ow / 2, centre[0] + ow / 2, centre[1] - oh / 2, centre[1] + oh / 2
    (y0, y1), x = DASH_Y, DASH_HALF_X
    black = {"type": "absorber"}
    out = []
    panels = [(-x, hx0, y0, y1), (hx1, x, y0, y1), (hx0, hx1, y0, hy0), (hx0, hx1, hy1, y1)]
    for k, (a0, a1, b0, b1) in enumerate(panels):
        out.append((*_panel(f"dashboard_{k}", np.array([a0, b0, DASH_HEIGHT]), np.array([a1 - a0, 0, 0]),
                            np.array([0, b1 - b0, 0])), black))
    hx, y0, y1, z0 = WELL
    ex, ey, ez = np.array([2 * hx, 0, 0]), np.array([0, y1 - y0, 0]), np.array([0, 0, DASH_HEIGHT - z0])
    c = np.array([-hx, y0, z0])
    for name, corner, a, b in (("well_floor", c, ex, ey), ("well_back", c, ex, ez), ("well_front", c + ey, ex, ez),
                               ("well_left", c, ey, ez), ("well_right", c + ex, ey, ez)):
        out.append((*_panel(name, corner, a, b), black))
    return out


def view_mean(folder: Path, panorama: Path, rotation_deg: float) -> float:
    """The mean of ``panorama``'s own values (luminance, before calibration) over the directions of the
    chief rays of the eye of the scene in ``folder``: what the eye sees of it through clear glass."""
    eye = ThinLensEye(load_scene(folder).eye)
    sx, sy = np.meshgrid(*eye.pixel_centers())  # perceived retina points: the direction (sx, sy, f) / |.|
    d = eye.to_world(np.stack([sx.ravel() / eye.focal, sy.ravel() / eye.focal, np.ones(sx.size)]))
    d = d / np.linalg.norm(d, axis=0)
    env = HdriEnvironment(np.clip(read_image(panorama), 0.0, None), "scale", 1.0, rotation_deg)
    return float(luminance(env.radiance(d).T).mean())


def make_study(folder: Path, symbol_scale: float, panorama: str, calibration: dict, rotation_deg: float,
               name: str, summary: str) -> Path:
    """Edit the HUD preset written in ``folder`` into a study: every emitter's luminance times
    ``symbol_scale``, the view widened to :data:`VIEW_DEG`, the panorama ``panorama`` (copied into the
    folder, calibrated as ``calibration``, turned by ``rotation_deg``) as the environment, the pupil
    following the image's mean luminance (Watson & Yellott 2012; the paper's eye "adapts to the average
    luminance"), the hybrid method's channels chosen by pilots. A ``calibration`` {"mode": "view",
    "value": L} scales the panorama so that what the eye sees of it averages L cd/m^2 (:func:`view_mean`)."""
    folder = Path(folder)
    texture = folder / "textures" / f"{panorama}.exr"
    copy_panorama(studio_hdri(panorama), texture)
    path = folder / "scene.json"
    data = json.loads(path.read_text())
    data["eye"] |= {"fov_deg": list(VIEW_DEG), "resolution": list(RESOLUTION)}
    path.write_text(json.dumps(data, indent=2) + "\n")
    if calibration["mode"] == "view":
        calibration = {"mode": "scale", "value": calibration["value"] / view_mean(folder, texture, rotation_deg)}
    data["name"], data["description"] = name, summary
    for o in data["objects"]:
        if "emission" in o:
            o["emission"]["luminance"] *= symbol_scale
    data["eye"] |= {"pupil_diameter_mm": "auto", "adaptation_luminance_cd_m2": "image", "adaptation": "mean",
                    "observer_age": 30}
    data["environment"] = {"type": "hdri", "file": f"textures/{panorama}.exr", "calibration": calibration,
                           "rotation_deg": rotation_deg}
    for name, vertices, faces, material in dashboard():
        write_obj(folder / "meshes" / f"{name}.obj", vertices, faces)
        data["objects"].append({"name": name, "mesh": f"meshes/{name}.obj", "material": material})
    data.setdefault("methods", {})["hybrid"] = {"hud_method": "auto", "environment_method": "auto"}
    path.write_text(json.dumps(data, indent=2) + "\n")
    return folder
