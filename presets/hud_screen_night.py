"""hud-screen-night: the rear-projection HUD at night (the paper's Figs. 9 and 10): symbols of 10^4
cd/m^2 against Blender's "night" panorama calibrated to a minimum of 34 cd/m^2 (the paper's). The
paper's finding: the symbols are "completely distinguishable", but "a visible bright spot in the field
of view caused by a rear projection effect ... seriously worsens the conditions for observing the real
environment"; at 1600 cd/m^2 (Fig. 10, found by lowering the LED luminance: hud-trace sweep) the spot
fades while the symbols stay legible."""

from __future__ import annotations

from pathlib import Path

from . import hud_screen
from .hud_screen_day import HUD_SCREEN_SYMBOLS_CD_M2
from .studies import make_study

NAME = "hud-screen-night"
SUMMARY = "hud-screen against a night panorama (minimum 34 cd/m^2), symbols 10^4 cd/m^2 (paper Figs. 9-10)"
#: The night panorama: Blender's "night" (a field at dusk), its minimum the paper's 34 cd/m^2, turned by
#: 90 deg, toward the darker horizon (panorama, calibration, rotation_deg).
NIGHT = ("night", {"mode": "min", "value": 34.0}, 90.0)


def write(folder, pupil_mm: float = hud_screen.PUPIL_MM) -> Path:
    hud_screen.write(folder, pupil_mm)
    return make_study(folder, 1.0e4 / HUD_SCREEN_SYMBOLS_CD_M2, *NIGHT, NAME, SUMMARY)
