"""Scenes whose images have closed forms (../shared/reference/hud-optical-metrics.md), for the optical
analysis: a plane mirror, a concave spherical mirror on its axis behind a beam splitter, the same mirror
met off its axis, and a glass plate, flat or wedged, that shows a panel and its ghost. World axes: x right,
y forward, z up; the eye sits at the origin and looks along +y. Every PGU is an emitting panel."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from presets._build import SceneBuilder, frame_matrix, rectangle
from tests.support.scenes import mirror_cap

EYE = {"position": [0.0, 0.0, 0.0], "gaze": [0.0, 1.0, 0.0], "up": [0.0, 0.0, 1.0], "pupil_diameter_mm": 4.0,
       "resolution": [60, 40], "fov_deg": [12.0, 8.0]}
PANEL = {"type": "absorber"}
LIT = {"luminance": 1000.0}


def _eye(gaze=(0.0, 1.0, 0.0), fov=(12.0, 8.0)) -> dict:
    return EYE | {"gaze": list(gaze), "fov_deg": list(fov)}


def plane_mirror(folder: Path, eye_to_mirror: float = 400.0, mirror_to_panel: float = 600.0,
                 panel_mm=(60.0, 30.0), target: dict | None = None) -> Path:
    """A plane mirror folding the view up by 90 degrees onto a panel: VID = eye_to_mirror + mirror_to_panel."""
    sb = SceneBuilder(Path(folder), "plane-mirror", "a plane mirror and a panel above it")
    m = np.array([0.0, eye_to_mirror, 0.0])
    sb.add("mirror", rectangle(400.0, 400.0)[:2], {"type": "mirror", "reflectance": 1.0},
           frame_matrix(m, [1, 0, 0], [0, -1, 1]))
    sb.add("panel", rectangle(*panel_mm)[:2], PANEL, frame_matrix(m + [0, 0, mirror_to_panel], [1, 0, 0], [0, 0, -1]),
           emission=LIT)
    return sb.write(eye=_eye(), target=target or {})


def sphere_on_axis(folder: Path, radius: float = 1000.0, eye_to_mirror: float = 400.0, panel_distance: float = 350.0,
                   panel_mm=(10.0, 6.0)) -> Path:
    """A concave spherical mirror met at normal incidence: the eye looks through a 45-degree beam splitter
    at the mirror's vertex, and the splitter folds the returning light down onto a panel
    ``panel_distance`` from the mirror along the axis. Virtual image s_i = s_o f / (f - s_o) behind the
    mirror, f = R / 2, lateral magnification s_i / s_o."""
    sb = SceneBuilder(Path(folder), "sphere-on-axis", "a concave mirror on its axis behind a beam splitter")
    splitter_y = eye_to_mirror / 2
    sb.add("splitter", rectangle(120.0, 120.0)[:2], {"type": "coating", "reflectance": 0.5, "transmittance": 0.5},
           frame_matrix([0.0, splitter_y, 0.0], [1, 0, 0], [0, -1, 1]))
    vertex = np.array([0.0, eye_to_mirror, 0.0])
    sb.add("mirror", mirror_cap(radius, 60.0, 24), {"type": "mirror", "reflectance": 1.0},
           frame_matrix(vertex, [1, 0, 0], [0, -1, 0]), smooth=True, surfaces=[{"type": "sphere", "radius_mm": radius}])
    drop = panel_distance - (eye_to_mirror - splitter_y)
    sb.add("panel", rectangle(*panel_mm)[:2], PANEL, frame_matrix([0.0, splitter_y, -drop], [1, 0, 0], [0, 0, 1]),
           emission=LIT)
    return sb.write(eye=_eye(fov=(4.0, 3.0)), target={"eyebox_mm": [4.0, 4.0], "eye_grid": [1, 1]})


def sphere_off_axis(folder: Path, radius: float = 1000.0, incidence_deg: float = 15.0, eye_to_mirror: float = 600.0,
                    panel_distance: float = 300.0, exact: bool = True, cells: int = 24) -> Path:
    """A concave spherical mirror met at ``incidence_deg`` in the vertical plane, reflecting the view up
    and back onto a small panel ``panel_distance`` away along the reflected chief ray (Coddington:
    f_t = (R/2) cos(theta), f_s = (R/2) / cos(theta))."""
    sb = SceneBuilder(Path(folder), "sphere-off-axis", "a concave mirror met off its axis")
    th = math.radians(incidence_deg)
    vertex = np.array([0.0, eye_to_mirror, 0.0])
    axis = np.array([0.0, -math.cos(th), math.sin(th)])
    sb.add("mirror", mirror_cap(radius, 60.0, cells), {"type": "mirror", "reflectance": 1.0},
           frame_matrix(vertex, [1, 0, 0], axis), smooth=True,
           surfaces=[{"type": "sphere", "radius_mm": radius}] if exact else None)
    r = np.array([0.0, -math.cos(2 * th), math.sin(2 * th)])
    sb.add("panel", rectangle(10.0, 6.0)[:2], PANEL, frame_matrix(vertex + panel_distance * r, [1, 0, 0], -r),
           emission=LIT)
    return sb.write(eye=_eye(fov=(4.0, 3.0)), target={"eyebox_mm": [4.0, 4.0], "eye_grid": [1, 1]})


def plate(folder: Path, thickness: float = 4.76, ior: float = 1.52, incidence_deg: float = 65.0,
          eye_to_plate: float = 800.0, vid: float = 2500.0, wedge_mrad: float = 0.0, panel_mm=(40.0, 20.0),
          target: dict | None = None) -> Path:
    """A glass plate (a windshield block) met at ``incidence_deg`` reflecting a panel into the eye: the
    primary image (its inner surface) and the ghost (its outer surface), the panel at ``vid`` from the
    eye along the reflected chief ray; a wedge thickens the glass toward its top."""
    sb = SceneBuilder(Path(folder), "plate", "a glass plate showing a panel and its ghost")
    th = math.radians(incidence_deg)
    normal = np.array([0.0, -math.cos(th), math.sin(th)])  # the inner surface's, toward the eye
    hit = np.array([0.0, eye_to_plate, 0.0])
    frame = np.array(frame_matrix(hit, [1, 0, 0], normal))  # the glass's +y runs up along it
    sb.data["objects"].append({"name": "plate", "material": {"type": "dielectric", "ior": ior},
                               "transform": {"matrix": frame.tolist()},
                               "windshield": {"size_mm": [600.0, 600.0], "thickness_mm": thickness,
                                              "wedge_mrad": wedge_mrad}})
    r = np.array([0.0, 1.0, 0.0]) - 2 * (np.array([0.0, 1.0, 0.0]) @ normal) * normal  # reflected chief ray
    sb.add("panel", rectangle(*panel_mm)[:2], PANEL, frame_matrix(hit + (vid - eye_to_plate) * r, [1, 0, 0], -r),
           emission=LIT)
    return sb.write(eye=_eye(fov=(3.0, 3.0)), target=target or {"eyebox_mm": [4.0, 4.0], "eye_grid": [1, 1]})


def plate_offset(thickness: float, ior: float, incidence_deg: float) -> float:
    """The ghost's parallel offset d = 2 t tan(theta') cos(theta), mm."""
    th = math.radians(incidence_deg)
    tp = math.asin(math.sin(th) / ior)
    return 2 * thickness * math.tan(tp) * math.cos(th)


def wedge_deviation(wedge_mrad: float, ior: float, incidence_deg: float) -> float:
    """The ghost's deviation by a wedge, 2 n delta cos(theta') / cos(theta), rad."""
    th = math.radians(incidence_deg)
    tp = math.asin(math.sin(th) / ior)
    return 2 * ior * wedge_mrad * 1e-3 * math.cos(tp) / math.cos(th)


def hud_direct_grid(folder: Path, eye: dict | None = None, **kw) -> Path:
    """hud-direct (``kw``: presets.hud_direct.write's, a windshield) showing the optical analysis's 5 x 3
    field grid in lines one LCD pixel wide (presets.slide.grid_array), the eye's block updated by ``eye``
    (a narrow view, an accommodation): the scenes where a render is held to the analysis."""
    from presets import hud_direct
    from presets.slide import grid_array
    from tests.support.scenes import edit_json
    from tracer.core.imageio import write_png

    f = hud_direct.write(folder, grid_slide=True, **kw)
    a = (255 * grid_array(240, 80, thickness=1)).astype(np.uint8)
    write_png(f / "textures/slide.png", np.repeat(a[:, :, None], 3, axis=2))
    if eye:
        edit_json(f, lambda d: d["eye"].update(eye))
    return f
