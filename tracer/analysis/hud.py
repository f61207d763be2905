"""The figures an HUD engineer reads off an image: symbol luminance, the background behind the symbols,
the rear-projection spot, and the contrast ratio (paper sec. 4.1: the spot "seriously worsens the
conditions for observing the real environment"; the LED luminance is chosen for "the minimum possible
contrast" of the spot and the "maximum contrast" of the symbols). Every command reports these: the
report's ``hud`` block, ``hud-trace readouts``, Blender's HUD Readouts, a sweep's ``hud.*`` keys.

Symbols and background are the pixels of :mod:`tracer.analysis.sections`, found from the eye's chief rays
on the HUD's light alone, so that every method is judged on one table:

- where the dominant chain crosses an LCD (``symbol_pixels_from`` "lcd_cells"), the symbols are the
  pixels whose chain crosses a clear cell, the background those whose chain and ghost chain cross black
  cells, both eroded by one analysis cell;
- where the eye sees the display only through a scattering screen lit through optics and the analysis has
  a photon map (``"lcd_cells_via_photons"``), the symbols are the pixels whose chief ray lands where the
  LCD's photons came through clear cells, the background where none did (:mod:`tracer.analysis.sections`);
- otherwise, where the eye sees the display only through a scattering screen (``"luminance_threshold"``:
  the LCD lies before the screen, out of the chains' reach), the symbols are the pixels of the display region
  above SYMBOL_SHARE of its 99th percentile (an LCD's clear and black cells differ by its contrast
  ratio) eroded by one pixel; among the rest, the most populous mode of the log luminance is the black
  leak, and darker modes a decade or more below it (a screen's margin that the LCD's image does not
  reach) are left out as unlit (modes by Otsu's threshold for three classes, classes whose means lie
  within a decade merged; Otsu 1979, doi:10.1109/TSMC.1979.4310076); the background is eroded by
  BACKGROUND_EROSION pixels, away from the halo that the pupil's blur and a photon gather spread around
  every symbol.

The figures:

- ``symbol_cd_m2``, ``background_cd_m2``: the mean apparent luminance over the symbol and background
  pixels: the symbol luminance and the background luminance;
- ``contrast_ratio``: CR = (L_sym + L_bg) / L_bg (the paper's and ISO 15008's form);
- ``spot``: the background smoothed over a window of ``SPOT_WINDOW`` of the display's width (a
  normalised box filter over background pixels only): its peak (cd/m^2), the peak over the
  background's median, and its size: the solid angle where the smoothed background exceeds half its
  peak, as the diameter (deg) of a disk of equal solid angle.

Against a real environment (the hybrid method's channels: the HUD's light and the environment's, each
an image of its own), symbols and background are told apart on the HUD channel, and the environment
channel gives what lies behind them:

- ``environment_behind_symbols_cd_m2``: the environment's luminance over the symbol pixels (seen through
  the windshield and the combiner);
- ``background_behind_symbols_cd_m2`` = that + the HUD's own background (its black leak), and
  ``contrast_ratio`` = (L_sym + L_b) / L_b with that L_b: the symbols' contrast against what the eye
  sees behind them (``hud_contrast_ratio``: the HUD alone, as in the dark);
- ``spot.environment_cd_m2``: the environment smoothed as the spot, at the spot's peak, and
  ``spot.contrast_against_environment`` = (L_env + L_spot) / L_env: how the HUD's brightest background
  region stands out against the environment behind it (1: invisible).
"""

from __future__ import annotations

import math

import numpy as np

from .sections import Sections, erode, find_sections

#: Window of the spot's smoothing, as a share of the display's width in pixels.
SPOT_WINDOW = 0.08
#: Every key of the figures (report.json's ``hud``) and of their ``spot``: a sweep's keys are checked
#: against them before its runs (tracer.scans.requirements).
HUD_KEYS = ("display_pixels", "note", "display_cd_m2", "symbol_pixels_from", "symbol_threshold_cd_m2", "unlit_pixels",
            "symbol_pixels", "background_pixels", "symbol_cd_m2", "background_cd_m2", "contrast_ratio",
            "environment_behind_symbols_cd_m2", "background_behind_symbols_cd_m2", "hud_contrast_ratio", "spot")
SPOT_KEYS = ("peak_cd_m2", "peak_pixel", "peak_over_median_background", "peak_over_symbol", "half_peak_diameter_deg",
             "smoothing_px", "environment_cd_m2", "contrast_against_environment")
#: Symbols are the pixels above this share of the display's 99th percentile of luminance: an LCD's
#: clear cells vary less than tenfold across a display, its black cells lie tenfold (CR >= 10) below.
SYMBOL_SHARE = 0.1
#: Pixels of erosion of the background (from the symbols' edges and the display's).
BACKGROUND_EROSION = 3
#: Log-luminance histogram bins for Otsu's threshold.
BINS = 256


def log_modes(logv: np.ndarray) -> list[float]:
    """Thresholds (log10 cd/m^2) between the modes of log luminances ``logv``: the three-class Otsu
    split (exhaustive over the histogram's pairs of bins), with neighbouring classes whose means lie
    within a decade merged; [] for one mode, [t] for two, [t_low, t_high] for three."""
    hist, edges = np.histogram(logv, BINS)
    p = hist / max(hist.sum(), 1)
    c = 0.5 * (edges[1:] + edges[:-1])
    w = np.concatenate([[0.0], np.cumsum(p)])
    m = np.concatenate([[0.0], np.cumsum(p * c)])
    i, j = np.triu_indices(BINS + 1, 1)
    keep = (i > 0) & (j < BINS)
    i, j = i[keep], j[keep]
    w0, w1, w2 = w[i], w[j] - w[i], 1 - w[j]
    m0, m1, m2 = m[i], m[j] - m[i], m[-1] - m[j]
    with np.errstate(divide="ignore", invalid="ignore"):
        score = np.where((w0 > 0) & (w1 > 0) & (w2 > 0), m0 * m0 / w0 + m1 * m1 / w1 + m2 * m2 / w2, -np.inf)
    k = int(np.argmax(score))
    cuts = [float(edges[i[k]]), float(edges[j[k]])]
    while cuts:
        bounds = [-np.inf, *cuts, np.inf]
        means = [logv[(logv >= a) & (logv < b)].mean() for a, b in zip(bounds[:-1], bounds[1:], strict=True)]
        gaps = np.diff(means)
        if gaps.min() >= 1.0:
            break
        cuts.pop(int(np.argmin(gaps)))
    return cuts


def _box_mean(values: np.ndarray, weights: np.ndarray, k: int) -> np.ndarray:
    """Normalised box filter of half-width k: sum(values w) / sum(w) over each (2k+1)^2 window."""
    def box(a):
        c = np.cumsum(np.cumsum(np.pad(a, ((k + 1, k), (k + 1, k))), axis=0), axis=1)
        n = 2 * k + 1
        return c[n:, n:] - c[:-n, n:] - c[n:, :-n] + c[:-n, :-n]
    num, den = box(values * weights), box(weights)
    return np.divide(num, den, out=np.zeros_like(num), where=den > 0)


def _threshold_masks(y: np.ndarray, mask: np.ndarray, out: dict) -> tuple[np.ndarray, np.ndarray] | None:
    """(symbols, background) of the display region ``mask`` by the luminance threshold of the module
    docstring, both eroded; None (with a note in ``out``) where the display has no dark cells."""
    vals = y[mask]
    pos = vals[vals > 0]
    top = float(np.percentile(pos, 99))
    if np.percentile(pos, 5) > SYMBOL_SHARE * top:  # no dark cells: one mode, nothing to tell apart
        return None
    t = SYMBOL_SHARE * top
    sym = mask & (y >= t)
    bg = mask & (y < t)
    dark = np.log10(y[bg & (y > 0)])
    cuts = log_modes(dark) if len(dark) >= 32 else []
    if cuts:  # the most populous mode is the black leak; modes below it are unlit
        counts = np.bincount(np.searchsorted(cuts, dark, side="right"), minlength=len(cuts) + 1)
        main = int(np.argmax(counts))
        if main > 0:
            unlit = bg & (y < 10 ** cuts[main - 1])
            out["unlit_pixels"] = int(unlit.sum())
            bg &= ~unlit
    out["symbol_threshold_cd_m2"] = t
    sym_in, bg_in = erode(sym, border_inside=True), bg
    for _ in range(BACKGROUND_EROSION):
        bg_in = erode(bg_in, border_inside=True)
    return (sym_in if sym_in.any() else sym), (bg_in if bg_in.any() else bg)


def hud_figures(world, y: np.ndarray, environment: np.ndarray | None = None,
                sections: Sections | None = None) -> dict | None:
    """The figures of the module docstring for an image ``y`` (H, W) cd/m^2 of ``world``'s eye (with
    ``environment``, ``y`` is the HUD channel alone and ``environment`` the environment channel's image);
    None where the eye sees no display. ``sections`` (:func:`tracer.analysis.sections.find_sections`) may
    be given when known."""
    sections = find_sections(world) if sections is None else sections
    if sections.display is None:
        return None
    mask = sections.pixels(sections.display, y.shape, fill=True)
    if mask.sum() < 16:
        return None
    eye = world.eye
    vals = y[mask]
    out: dict = {"display_pixels": int(mask.sum())}
    if np.count_nonzero(vals > 0) < 16:
        out["note"] = "the display region is dark"
        return out
    if "symbol" in sections.masks:
        sym, bg = (sections.pixels(sections.masks[k], y.shape) for k in ("symbol", "background"))
        found = sections.symbols_from if sym.any() and bg.any() else None
        area = sections.stride ** 2  # the pixels a followed chief ray stands for
    else:
        area = 1
        masks = _threshold_masks(y, mask, out)
        sym, bg = masks if masks is not None else (None, None)
        found = "luminance_threshold" if masks is not None else None
    if found is None:
        out["note"] = "the display is uniform (no symbols and background to tell apart)"
        out["display_cd_m2"] = float(vals.mean())
        return out
    l_sym = float(y[sym].mean())
    l_bg = float(y[bg].mean())
    out |= {"symbol_pixels_from": found, "symbol_pixels": int(sym.sum()), "background_pixels": int(bg.sum()),
            "symbol_cd_m2": l_sym, "background_cd_m2": l_bg,
            "contrast_ratio": (l_sym + l_bg) / l_bg if l_bg > 0 else None}
    if environment is not None:
        behind = float(environment[sym].mean())
        l_b = behind + l_bg
        out |= {"environment_behind_symbols_cd_m2": behind, "background_behind_symbols_cd_m2": l_b,
                "hud_contrast_ratio": out["contrast_ratio"],
                "contrast_ratio": (l_sym + l_b) / l_b if l_b > 0 else None}
    if bg.sum() >= 16 and l_bg > 0:
        cols = np.flatnonzero(mask.any(axis=0))
        k = max(1, int(round(SPOT_WINDOW * (cols[-1] - cols[0] + 1) / 2)))
        smooth = _box_mean(np.where(bg, y, 0.0), bg.astype(np.float64), k)
        smooth = np.where(bg, smooth, 0.0)
        peak = float(smooth.max())
        at = np.unravel_index(int(np.argmax(smooth)), smooth.shape)
        half = bg & (smooth >= 0.5 * peak)
        px_sr = (2 * eye.half_x / eye.focal / eye.width) * (2 * eye.half_y / eye.focal / eye.height)
        diameter = 2 * math.degrees(math.sqrt(half.sum() * area * px_sr / math.pi))
        median = float(np.median(y[bg]))
        out["spot"] = {"peak_cd_m2": peak, "peak_pixel": [int(at[1]), int(at[0])],
                       "peak_over_median_background": peak / median if median > 0 else None,
                       "peak_over_symbol": peak / l_sym if l_sym > 0 else None,
                       "half_peak_diameter_deg": diameter, "smoothing_px": 2 * k + 1}
        if environment is not None:
            env = float(_box_mean(np.where(bg, environment, 0.0), bg.astype(np.float64), k)[at])
            out["spot"] |= {"environment_cd_m2": env,
                            "contrast_against_environment": (env + peak) / env if env > 0 else None}
    return out
