"""hud-direct-env: the direct HUD in daylight (the paper's Fig. 13): hud-direct's symbols set to 10^4
cd/m^2 in the centre of the field, against the day panorama of hud-screen-day (Blender's "city",
mean 2140 cd/m^2). The paper merged a forward-traced HUD channel with a photon-mapped environment
channel; here the hybrid method's pilots choose each channel's method."""

from __future__ import annotations

from pathlib import Path

from . import hud_direct
from .hud_screen_day import DAY
from .studies import make_study

NAME = "hud-direct-env"
SUMMARY = "hud-direct against the day panorama, symbols 10^4 cd/m^2 (paper Fig. 13)"
#: hud-direct's symbols read 8,324 cd/m^2 (its brightness-theorem prediction with polarisation,
#: docs/results/polarisation.md): to 10^4.
SYMBOL_SCALE = 1.0e4 / 8324.0


def write(folder, pupil_mm: float = hud_direct.PUPIL_MM) -> Path:
    hud_direct.write(folder, pupil_mm)
    return make_study(folder, SYMBOL_SCALE, *DAY, NAME, SUMMARY)
