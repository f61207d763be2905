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
               hud_direct_optics,
               hud_direct_polarised,
               hud_screen,
               hud_screen_day,
               hud_screen_ideal,
               hud_screen_night,
)

PRESETS = {m.NAME: m for m in (hud_direct, hud_screen, hud_screen_ideal, hud_direct_condenser, hud_screen_day,
                               hud_screen_night, hud_direct_env, *hud_direct_polarised.VARIANTS,
                               *hud_direct_optics.VARIANTS, analytic_mirror, analytic_disk, analytic_furnace)}
#: The studies of a HUD against a panorama (presets/studies.py): the hybrid method's scenes. The
#: single-method benchmarks (speed against accuracy, Mitsuba, fingerprints) leave them out: forward
#: tracing and Mitsuba's converter do not render their environment channel as the hybrid does.
STUDIES = tuple(m.NAME for m in (hud_screen_day, hud_screen_night, hud_direct_env))
#: hud-direct's polarised variants (presets/hud_direct_polarised.py), which
#: tests/presets/test_hud_direct_polarised.py checks; the speed-against-accuracy and Mitsuba benchmarks
#: leave them out (Mitsuba's RGB variants cannot render polariser or analyser, and they are hud-direct
#: for speed).
POLARISED = tuple(v.NAME for v in hud_direct_polarised.VARIANTS)
#: hud-direct's windshields for the optical analysis (presets/hud_direct_optics.py): hud-direct for speed,
#: and made from parameters (no mesh file for Mitsuba's converter).
WINDSHIELDS = tuple(v.NAME for v in hud_direct_optics.VARIANTS)
#: Every preset but the studies, the polarised variants and the windshields.
SINGLE_METHOD = tuple(n for n in PRESETS if n not in STUDIES + POLARISED + WINDSHIELDS)
