"""False-colour luminance view: a rendered luminance image (cd/m^2) on a logarithmic colour scale, with
its colour bar, as an 8-bit sRGB image.

- Scale: t = (log10 Y - log10 lo) / (log10 hi - log10 lo), clamped to [0, 1], through viridis
  (:data:`tracer.products.charts.COLOUR_MAP`), whose luminance rises monotonically along it, so brighter
  always reads brighter. The default range runs from the decade at or below the 1st percentile of the
  lit pixels (Y > 0) to the decade at or above the maximum, at most :data:`MAX_DECADES` decades (the
  top ones are kept: a HUD's symbols and its black leak, not the faint stray light below them). Pixels
  at or below 0 cd/m^2 (no light) are black, which the colour map never reaches; pixels outside the
  range take the colour of its end, and the colour bar says so with a triangle at that end.
- Colour bar (drawn by matplotlib, as the charts are): ticks a reader can read values off
  (:func:`legend_ticks`: every decade over three decades or more, 1, 2 and 5 times them over one to
  three, and even steps inside a range narrower than a decade), the unit above it and the no-light
  swatch below it, its text about :data:`TEXT_SHARE` of the picture's height.
- An image less than :data:`MIN_HEIGHT` px tall (HUD renders are often 300 x 100) is enlarged by an
  integer factor, nearest-neighbour, so that its pixels stay visible; its pixels are placed unresampled.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from . import charts
from .outputs import png_file, write_as_set

#: The colour of pixels that receive no light (Y <= 0 cd/m^2): darker than any colour of the map.
NO_LIGHT = (0, 0, 0)
#: The default range spans at most this many decades.
MAX_DECADES = 8
#: Images less tall than this (px) are enlarged by an integer factor ...
MIN_HEIGHT = 400
#: ... as long as they stay at most this wide (px).
MAX_WIDTH = 4096
#: The colour bar's text is about this share of the picture's height (at least 8 pt).
TEXT_SHARE = 0.03


def _nice_step(span: float, target: int = 5) -> float:
    """A 1-2-5 step that divides ``span`` into about ``target`` parts."""
    raw = span / target
    e = math.floor(math.log10(raw))
    f = raw / 10.0**e
    return (1 if f < 1.5 else 2 if f < 3.5 else 5 if f < 7.5 else 10) * 10.0**e


def legend_ticks(lo: float, hi: float) -> list[float]:
    """The colour bar's ticks, cd/m^2, within [lo, hi]: every decade where the range spans three or
    more; 1, 2 and 5 times each decade over one to three decades; over less than a decade, even 1-2-5
    steps (about five of them), so that a value inside a narrow range can be read off the bar."""
    decades = math.log10(hi / lo)
    e0, e1 = math.floor(math.log10(lo)), math.ceil(math.log10(hi))
    inside = lambda v: lo * (1 - 1e-9) <= v <= hi * (1 + 1e-9)  # noqa: E731
    if decades >= 3:
        return [10.0**e for e in range(e0, e1 + 1) if inside(10.0**e)]
    if decades >= 1:
        return [m * 10.0**e for e in range(e0, e1 + 1) for m in (1, 2, 5) if inside(m * 10.0**e)]
    step = _nice_step(hi - lo)
    first = math.ceil(lo / step - 1e-9)
    return [float(f"{k * step:.12g}") for k in range(first, math.floor(hi / step + 1e-9) + 1)]


def luminance_range(y: np.ndarray, lo: float | None = None, hi: float | None = None) -> tuple[float, float, str]:
    """(lo, hi, how) of the scale, cd/m^2: the given bounds, or the defaults of the module docstring
    for those not given; ``how`` says how they were chosen. Raises ``ValueError`` naming a bound
    that is not finite and positive, or a range with lo >= hi."""
    for name, v in (("lo", lo), ("hi", hi)):
        if v is not None and not (math.isfinite(v) and v > 0):
            raise ValueError(f"{name}: must be a finite luminance > 0 cd/m^2, got {v}")
    lit = y[y > 0]
    notes = []
    if lit.size == 0:
        d_lo, d_hi = 1.0, 10.0
        notes.append("no pixel is lit: 1 to 10 cd/m^2")
    else:
        top = math.ceil(math.log10(float(lit.max())))
        bottom = math.floor(math.log10(float(np.percentile(lit, 1))))
        if top - bottom > MAX_DECADES:
            bottom = top - MAX_DECADES
            notes.append(f"the lit pixels span more than {MAX_DECADES} decades: the top {MAX_DECADES} shown")
        if bottom == top:  # every lit pixel on one power of ten: the decade below it too
            bottom -= 1
        d_lo, d_hi = 10.0**bottom, 10.0**top
    how = []
    if lo is None or hi is None:
        how.append("from the decade at or below the 1st percentile of the lit pixels to the decade at or above "
                   f"their maximum (at most {MAX_DECADES} decades)")
    lo = d_lo if lo is None else float(lo)
    hi = d_hi if hi is None else float(hi)
    if lo >= hi:
        raise ValueError(f"lo: {lo:g} cd/m^2 is not below hi {hi:g} cd/m^2")
    return lo, hi, "; ".join(how + notes) if how or notes else "given"


def _check_luminance(y) -> np.ndarray:
    y = np.asarray(y, dtype=np.float64)
    if y.ndim != 2 or y.size == 0:
        raise ValueError(f"the luminance image must be a non-empty (H, W) array, got shape {y.shape}")
    if not np.all(np.isfinite(y)):
        raise ValueError("the luminance image holds non-finite values (NaN or Inf)")
    return y


def false_colour(y, lo: float | None = None, hi: float | None = None) -> tuple[np.ndarray, dict]:
    """The false-colour view of luminance ``y`` (H, W) cd/m^2, row 0 the top row.

    ``lo``, ``hi``: the range of the scale, cd/m^2 (see the module docstring for the defaults).

    Returns ``(rgb, info)``: rgb (H', W', 3) uint8, sRGB-encoded: the image enlarged by
    ``info["upscale"]`` (nearest-neighbour) at the left, the colour bar at the right; info holds "lo",
    "hi" (cd/m^2), "decades" (log10 hi/lo), "range" (how lo and hi were chosen), "colour_map",
    "no_light_colour", "below" / "above" (fractions of the pixels clamped at the range's ends, lit
    pixels below lo and pixels above hi), "no_light" (fraction at or below 0 cd/m^2), "upscale",
    "image" (top, left, height, width of the image in rgb) and "legend": the colour bar's "bar" (top,
    bottom, left, right: rows and columns of its coloured part, ends exclusive), "ticks" [{"value",
    "label", "row"}] (the row where the bar shows the value's colour), "caps" (the ends marked as
    clamped) and "title".

    Raises ``ValueError`` for an image that is not 2-D, empty or not finite, and for a bad range.
    """
    y = _check_luminance(y)
    lo, hi, how = luminance_range(y, lo, hi)
    h, w = y.shape
    k = max(1, min(math.ceil(MIN_HEIGHT / h), MAX_WIDTH // w))
    lit = y > 0
    log_lo, log_hi = math.log10(lo), math.log10(hi)
    with np.errstate(divide="ignore"):
        t = (np.log10(np.where(lit, y, 1.0)) - log_lo) / (log_hi - log_lo)
    img = charts.colours(t)
    img[~lit] = NO_LIGHT
    img = np.repeat(np.repeat(img, k, axis=0), k, axis=1)
    below, above = bool(np.any(lit & (y < lo))), bool(np.any(y > hi))
    extend = {(False, False): "neither", (True, False): "min", (False, True): "max", (True, True): "both"}[(below,
                                                                                                          above)]

    ih, iw = img.shape[:2]
    height = max(ih, 300)
    pt = max(8.0, TEXT_SHARE * height * 72 / charts.DPI)
    px = pt * charts.DPI / 72  # the text's height in pixels
    legend_w = int(round(6.5 * px + 0.8 * px * max(len(charts.value_label(v)) for v in legend_ticks(lo, hi))))
    width = iw + legend_w
    fig, canvas = charts.new_figure(width / charts.DPI, height / charts.DPI)
    top = (height - ih) // 2
    fig.figimage(img, xo=0, yo=height - top - ih, origin="upper")
    bar_left = iw + 1.5 * px
    bar_w = 1.2 * px
    bar_bottom = 4.0 * px  # room for the no-light swatch and the lower cap
    bar_top = 2.6 * px  # room for the unit and the upper cap
    cax = fig.add_axes((bar_left / width, bar_bottom / height, bar_w / width, 1 - (bar_bottom + bar_top) / height))
    import matplotlib.colorbar
    import matplotlib.colors

    ticks = legend_ticks(lo, hi)
    bar = matplotlib.colorbar.Colorbar(cax, cmap=charts.colour_map(), norm=matplotlib.colors.LogNorm(lo, hi),
                                       extend=extend, extendfrac=0.04, ticks=ticks)
    bar.minorticks_off()
    bar.ax.set_yticklabels([charts.value_label(v) for v in ticks], fontsize=pt)
    bar.ax.set_title("cd/m²", fontsize=pt, pad=0.9 * px if above else 0.4 * px)
    swatch = fig.add_axes((bar_left / width, 0.9 * px / height, bar_w / width, 1.1 * px / height))
    swatch.set_facecolor(np.array(NO_LIGHT) / 255)
    swatch.set_xticks([])
    swatch.set_yticks([])
    swatch.text(1.4, 0.5, "no light", transform=swatch.transAxes, va="center", ha="left", fontsize=pt)
    rgb = charts.pixels(canvas)
    b = charts.box(cax)
    legend = {"bar": {"top": b[0], "bottom": b[0] + b[2], "left": b[1], "right": b[1] + b[3]},
              "ticks": [{"value": v, "label": charts.value_label(v), "row": charts.to_pixel(cax, 0.5, v)[1]}
                        for v in ticks],
              "caps": [end for end, on in (("below", below), ("above", above)) if on], "title": "cd/m²"}
    n = y.size
    info = {"lo": lo, "hi": hi, "decades": log_hi - log_lo, "range": how, "colour_map": charts.COLOUR_MAP,
            "no_light_colour": list(NO_LIGHT), "scale": "log10 of Y, cd/m^2",
            "below": float(np.count_nonzero(lit & (y < lo)) / n), "above": float(np.count_nonzero(y > hi) / n),
            "no_light": float(np.count_nonzero(~lit) / n), "upscale": k,
            "image": {"top": top, "left": 0, "height": ih, "width": iw}, "legend": legend}
    return rgb, info


def save_false_colour(path, y, lo: float | None = None, hi: float | None = None) -> dict:
    """Write :func:`false_colour` (``y``, ``lo``, ``hi``) to the PNG file ``path`` as a set
    (:func:`tracer.products.outputs.write_as_set`); returns its info dict."""
    rgb, info = false_colour(y, lo, hi)
    f = png_file(Path(path).name, rgb)
    write_as_set(path, f.write, f.check)
    return info
