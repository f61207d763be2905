"""Units and colour conventions used everywhere in the tracer.

- Lengths in millimetres (mm); areas in mm^2 unless a name says otherwise.
- Luminance in cd/m^2, luminous flux in lm, illuminance in lx.
- Colour: linear Rec.709 RGB. A luminance value L and a colour c are combined as L * c / Y(c),
  so that Y = 0.2126 R + 0.7152 G + 0.0722 B of the result equals L (ITU-R BT.709-6).
"""

from __future__ import annotations

import numpy as np

#: Rec.709 luminance weights: Y = 0.2126 R + 0.7152 G + 0.0722 B (ITU-R BT.709-6, item 3.3).
Y_WEIGHTS = np.array([0.2126, 0.7152, 0.0722])

#: Square millimetres to square metres.
MM2_TO_M2 = 1e-6


def luminance(rgb: np.ndarray) -> np.ndarray:
    """Y of linear Rec.709 RGB; ``rgb`` has shape (..., 3), the result shape (...). Summed term by
    term (not with BLAS), so the result does not depend on memory alignment."""
    c = np.asarray(rgb, dtype=np.float64)
    return c[..., 0] * Y_WEIGHTS[0] + c[..., 1] * Y_WEIGHTS[1] + c[..., 2] * Y_WEIGHTS[2]


def luminance3(planes: np.ndarray) -> np.ndarray:
    """Y of linear Rec.709 RGB given as (3, n) planes (or a (3,) vector); (n,), summed term by term."""
    return planes[0] * Y_WEIGHTS[0] + planes[1] * Y_WEIGHTS[1] + planes[2] * Y_WEIGHTS[2]


def normalize_color(rgb) -> np.ndarray:
    """Scale an RGB colour so that its luminance Y is 1 (a chromaticity carrier).

    Raises ``ValueError`` for a colour with a negative component or zero luminance.
    """
    c = np.asarray(rgb, dtype=np.float64).reshape(3)
    if np.any(c < 0) or not np.all(np.isfinite(c)):
        raise ValueError("colour components must be finite and >= 0")
    y = float(c @ Y_WEIGHTS)
    if y <= 0:
        raise ValueError("colour must have a positive luminance")
    return c / y


def lambertian_flux_lm(luminance_cd_m2: float, area_mm2: float) -> float:
    """Flux (lm) of a one-sided Lambertian emitter: Phi = pi L A."""
    return float(np.pi * luminance_cd_m2 * area_mm2 * MM2_TO_M2)


def lambertian_luminance_cd_m2(flux_lm: float, area_mm2: float) -> float:
    """Luminance (cd/m^2) of a one-sided Lambertian emitter of flux ``flux_lm`` and area ``area_mm2``."""
    return float(flux_lm / (np.pi * area_mm2 * MM2_TO_M2))
