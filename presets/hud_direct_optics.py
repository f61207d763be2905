"""hud-direct's windshields for the optical analysis (``hud-trace optics``, docs/user/optics.md):

- ``hud-direct-wedge``: the flat windshield made a wedge, the glass thicker toward its top by
  WEDGE_MRAD, the angle that fuses the ghost with the primary image at the design eye point. Found
  with ``hud-trace sweep hud-direct-wedge --optics --set "objects[windshield].windshield.wedge_mrad=..."``
  on ``optics.design_eye.ghost_separation_centre_arcmin`` (docs/results/optics.md), against the
  first-order estimate t sin(theta) cos^2(theta) / (n^2 cos^2(theta') VID) of
  ../shared/reference/hud-optical-metrics.md.
- ``hud-direct-curved``: the windshield curved as cars' are, concave toward the driver with radii
  CURVED_RADII_MM across and up its inner surface (a biconic, even thickness). Its curvature is a
  weak mirror of its own, astigmatic at 63 deg: the LCD moves to where the mirror and the windshield's
  mean power image it at the VID (hud_direct.design), and what remains is what the analysis reports:
  astigmatism, a changed distortion, and images that the two eyes see differently. The LCD shows the
  analysis's 5 x 3 field grid, so that the render shows the distortion it reports.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

from . import hud_direct

#: hud-direct-wedge's wedge, mrad (docs/results/optics.md: the sweep's zero of the ghost separation).
WEDGE_MRAD = 0.267
#: hud-direct-curved's inner-surface radii [across (x), up the glass (y)], mm.
CURVED_RADII_MM = (5000.0, 20000.0)


def first_order_wedge_mrad(thickness_mm: float = hud_direct.GLASS_MM, ior: float = 1.52,
                           incidence_deg: float | None = None, vid_mm: float = hud_direct.VID) -> float:
    """The reference's first-order wedge that fuses a flat plate's ghost: delta = t sin(theta)
    cos^2(theta) / (n^2 cos^2(theta') VID), mrad."""
    th = math.radians(hud_direct.design()["incidence_windshield_deg"] if incidence_deg is None else incidence_deg)
    tp = math.asin(math.sin(th) / ior)
    return 1e3 * thickness_mm * math.sin(th) * math.cos(th) ** 2 / (ior ** 2 * math.cos(tp) ** 2 * vid_mm)


@dataclass(frozen=True)
class Variant:
    """A preset: hud-direct with a parametric windshield."""

    NAME: str
    SUMMARY: str
    windshield: dict
    grid_slide: bool = False

    def write(self, folder) -> Path:
        return hud_direct.write(folder, name=self.NAME, summary=self.SUMMARY, windshield=self.windshield,
                                grid_slide=self.grid_slide)


VARIANTS = (
    Variant("hud-direct-wedge", f"hud-direct with a {WEDGE_MRAD:g} mrad wedge windshield: the ghost fused with the "
                                "image", {"wedge_mrad": WEDGE_MRAD}),
    Variant("hud-direct-curved", f"hud-direct behind a curved windshield (radii {CURVED_RADII_MM[0]:g} and "
                                 f"{CURVED_RADII_MM[1]:g} mm), showing a grid",
            {"radius_x_mm": CURVED_RADII_MM[0], "radius_y_mm": CURVED_RADII_MM[1]}, grid_slide=True),
)
