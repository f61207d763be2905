"""hud-direct with polarised light: an LCD picture generation unit whose output polariser
sends s light to the windshield, the same seen through polarised sunglasses, and with a half-wave
film that turns it into p light, which the sunglasses pass.

hud-direct's own LEDs are unpolarised: its windshield already needs polarisation, since s and p light
cross the glass as separate channels (ghost ratio [(1-Rs)^2 Rs + (1-Rp)^2 Rp] / (Rs + Rp) = 0.576 at
67 deg, n = 1.52, not the (1 - R)^2 = 0.74 of the unpolarised average). Here:

- ``hud-direct-s``: the LCD's output polariser along its local x (the world x, perpendicular to the
  planes of incidence at the mirror and the windshield): s light, primary R_s = 0.262, ghost ratio
  (1 - R_s)^2 = 0.545;
- ``hud-direct-s-sunglasses``: the same through polarised sunglasses (an ideal analyser with its axis
  vertical, 90 deg, as sunglasses pass the p light that glare off horizontal surfaces lacks): the
  symbols' s light is blocked and the HUD vanishes;
- ``hud-direct-film-sunglasses``: a half-wave film 1 mm in front of the LCD with its fast axis at 45
  deg turns the s light into p light: the windshield reflects R_p = 0.021 (8 times less than s
  light), the ghost ratio is (1 - R_p)^2 = 0.958, and the sunglasses pass it.

Numbers: docs/results/polarisation.md.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from . import hud_direct

#: Polarised sunglasses: an ideal linear polariser with its transmission axis vertical.
SUNGLASSES = {"axis_deg": 90.0, "transmittance_along": 1.0, "transmittance_across": 0.0}


@dataclass(frozen=True)
class Variant:
    """A preset: hud-direct with an LCD output polariser, a half-wave film and an analyser."""

    NAME: str
    SUMMARY: str
    lcd_polariser_deg: float
    film_axis_deg: float | None = None
    analyser: dict | None = None

    def write(self, folder, pupil_mm: float = hud_direct.PUPIL_MM, resolution=hud_direct.RESOLUTION) -> Path:
        return hud_direct.write(folder, pupil_mm, resolution, name=self.NAME, summary=self.SUMMARY,
                                lcd_polariser_deg=self.lcd_polariser_deg, film_axis_deg=self.film_axis_deg,
                                analyser=self.analyser)


S = Variant("hud-direct-s", "hud-direct with an LCD whose output polariser sends s light to the windshield", 0.0)
S_SUNGLASSES = Variant("hud-direct-s-sunglasses", "hud-direct-s seen through polarised sunglasses (axis vertical)",
                       0.0, analyser=SUNGLASSES)
FILM_SUNGLASSES = Variant("hud-direct-film-sunglasses",
                          "hud-direct-s with a half-wave film at 45 deg (p light), through polarised sunglasses",
                          0.0, film_axis_deg=45.0, analyser=SUNGLASSES)
VARIANTS = (S, S_SUNGLASSES, FILM_SUNGLASSES)
