"""hud-screen-ideal-lcd: hud-screen with an LCD of absolute contrast (black cells transmit 1e-9 of a clear
cell): the paper's Fig. 7a, beside hud-screen's real 300:1 LCD (Fig. 7b), so that the rear-projection
spot, which the black cells' leak carries, can be told from the symbols."""

from __future__ import annotations

from pathlib import Path

from . import hud_screen

NAME = "hud-screen-ideal-lcd"
SUMMARY = "hud-screen with an LCD of absolute contrast (paper Fig. 7a): no black leak, no rear-projection spot"
CONTRAST = 1e9


def write(folder, pupil_mm: float = hud_screen.PUPIL_MM, resolution=hud_screen.RESOLUTION) -> Path:
    return hud_screen.write(folder, pupil_mm, resolution, contrast=CONTRAST, name=NAME, summary=SUMMARY)
