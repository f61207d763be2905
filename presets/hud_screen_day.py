"""hud-screen-day: the rear-projection HUD in daylight (the paper's Fig. 8): symbols of 1600 cd/m^2
against Blender's "city" panorama, a street under a bright sky, scaled so that what the eye sees of it
averages 2140 cd/m^2 (the paper's adaptation luminance for this case; its panorama spans 292 to
21013 cd/m^2). The paper's
finding: "in the case of a very bright object in the field of view, the level of LED luminance is not
enough for a good visualization of useful information"."""

from __future__ import annotations

from pathlib import Path

from . import hud_screen
from .studies import make_study

NAME = "hud-screen-day"
SUMMARY = "hud-screen against a day panorama (2140 cd/m^2 in view), symbols 1600 cd/m^2 (paper Fig. 8)"
#: hud-screen's symbols as an eye in the studies' view sees them, cd/m^2 (hud-screen-night at scale 1,
#: 120 s hybrid render, docs/results/studies.md; with the windshield's s and p light apart, 10 % below the 10^4 cd/m^2
#: the preset was designed for with the unpolarised Fresnel average).
HUD_SCREEN_SYMBOLS_CD_M2 = 9019.0
#: Symbol luminance of the study over hud-screen's.
SYMBOL_SCALE = 1600.0 / HUD_SCREEN_SYMBOLS_CD_M2
#: The day panorama: Blender's "city", scaled so that the view averages the paper's adaptation
#: luminance, turned by 0 deg (panorama, calibration, rotation_deg).
DAY = ("city", {"mode": "view", "value": 2140.0}, 0.0)


def write(folder, pupil_mm: float = hud_screen.PUPIL_MM) -> Path:
    hud_screen.write(folder, pupil_mm)
    return make_study(folder, SYMBOL_SCALE, *DAY, NAME, SUMMARY)
