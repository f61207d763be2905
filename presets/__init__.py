"""Presets: Python code that writes scene folders, found by name.

Each preset module has ``NAME``, ``SUMMARY`` (one line) and ``write(folder) -> Path``. The Blender
add-on builds its "Add HUD preset" menu from the same registry.
"""

from . import (
               analytic_disk,
               analytic_furnace,
               analytic_mirror,
               hud_direct,
               hud_direct_condenser,
               hud_direct_env,
               hud_screen,
               hud_screen_day,
               hud_screen_ideal,
               hud_screen_night,
)

PRESETS = {m.NAME: m for m in (hud_direct, hud_screen, hud_screen_ideal, hud_direct_condenser, hud_screen_day,
                               hud_screen_night, hud_direct_env, analytic_mirror, analytic_disk, analytic_furnace)}
