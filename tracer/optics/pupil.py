"""Pupil diameter from the adaptation luminance: Watson & Yellott's unified formula.

A. B. Watson and J. I. Yellott, "A unified formula for light-adapted pupil size", Journal of Vision
12(10):12 (2012), doi:10.1167/12.10.12:

    F = L a M  (L luminance cd/m^2, a field area deg^2, M = 1 both eyes or 0.1 one eye)
    D_SD = 7.75 - 5.75 x / (x + 2),  x = (F / 846)^0.41      (Stanley & Davies, mm)
    D = D_SD + (y - 28.58)(0.02132 - 0.009562 D_SD)          (age y in years)
"""

from __future__ import annotations

import math


def pupil_diameter_mm(luminance_cd_m2: float, field_deg: float = 60.0, age_years: float = 30.0,
                      both_eyes: bool = True) -> float:
    """Light-adapted pupil diameter (mm) for a circular adapting field of ``field_deg`` diameter."""
    if luminance_cd_m2 < 0 or not math.isfinite(luminance_cd_m2):
        raise ValueError("the adaptation luminance must be finite and >= 0 cd/m^2")
    area = math.pi * (field_deg / 2) ** 2
    x = (luminance_cd_m2 * area * (1.0 if both_eyes else 0.1) / 846.0) ** 0.41
    d_sd = 7.75 - 5.75 * x / (x + 2.0)
    return d_sd + (age_years - 28.58) * (0.02132 - 0.009562 * d_sd)
