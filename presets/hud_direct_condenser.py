"""hud-direct-condenser: hud-direct with real lighting optics, a plano-convex glass condenser between the
LEDs and the raster scatterer (paper sec. 4.2: "the lighting optics provides uniform illumination of
the entire LCD surface").

The condenser (f = 40 mm, n = 1.52, 32 mm across, convex face toward the scatterer) sits 20 mm in front
of hud-direct's design LED point F2 and forms there a virtual image of the LEDs, so that the concave
mirror still images them onto the eyebox: the LEDs sit u = f c / (f + c) = 13.3 mm from the
condenser's object-side principal plane (3.5 mm in front of F2), on a grid shrunk by the
magnification c / u = 1.5, and aim at the condenser's central 24 mm. Every straight line
from the scatterer to an LED crosses the condenser: next-event estimation from the scatterer is
blocked by glass, as in real products, which is what makes this scene hard for a path tracer (the
issue measured about 10 hours to 1 % noise with Mitsuba 3). See :mod:`presets.hud_direct` for the rest of the design.
"""

from __future__ import annotations

from pathlib import Path

from . import hud_direct

NAME = "hud-direct-condenser"
SUMMARY = "hud-direct with a glass condenser between the LEDs and the scatterer (no straight line joins them)"


def write(folder, pupil_mm: float = hud_direct.PUPIL_MM, resolution=hud_direct.RESOLUTION) -> Path:
    return hud_direct.write(folder, pupil_mm, resolution, condenser=True, name=NAME, summary=SUMMARY)
