"""False-colour luminance view: a rendered luminance image (cd/m^2) on a logarithmic colour scale,
with a legend, as an 8-bit sRGB image. Everything here is numpy: no PIL, no matplotlib (the tracer
also runs inside Blender, which has neither).

- Scale: t = (log10 Y - log10 lo) / (log10 hi - log10 lo), clamped to [0, 1], through the viridis
  colour map (:data:`VIRIDIS`), whose luminance increases monotonically along it (to within the
  8-bit rounding of one channel), so brighter always reads brighter. The default range runs from
  the decade at or below the 1st percentile of the lit pixels (Y > 0) to the decade at or above the
  maximum, at most :data:`MAX_DECADES`
  decades (the top ones are kept: a HUD's symbols and its black leak, not the faint stray light
  below them). Pixels at or below 0 cd/m^2 (no light) are black, which the colour map never
  reaches; pixels outside the range take the colour of its end, and the legend says so with a
  triangle at that end of the bar (matplotlib's "extend" arrows).
- Legend: a colour bar beside the image with a tick at every decade, labelled 0.001, 0.01, 0.1, 1,
  10, 100, 1000 and 1e4, 1e5 ... (1e-4 ... below 0.001), the unit "cd/m²" above it and the
  no-light swatch below it, drawn with a 5 x 7 bitmap font (:data:`FONT`) scaled to the image.
- An image less than :data:`MIN_HEIGHT` px tall (HUD renders are often 300 x 100) is enlarged by an
  integer factor, nearest-neighbour, so that its pixels stay visible and the legend legible.

The colour bar, the font and :func:`write_as_set` serve the eyebox chart too (:mod:`tracer.scans.eyebox`).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from ..core.errors import SceneError
from ..core.imageio import read_exr_channels, read_image, write_png
from ..core.units import luminance
from .outputs import OutputFile, OutputSet

#: Control points of viridis (S. van der Walt, N. Smith, E. Firing, 2015; the mpl-colormaps table,
#: https://github.com/BIDS/colormap, CC0, as in matplotlib's _cm_listed.py): entries
#: (index into its 256-entry table, sRGB-encoded R, G, B), every 8th entry. Interpolated linearly in
#: the encoded values (as matplotlib does) they stay within 1.6/255 of the full table. Viridis is
#: perceptually uniform in CAM02-UCS and its luminance rises monotonically from end to end
#: (N. Smith, S. van der Walt, "A Better Default Colormap for Matplotlib", SciPy 2015).
VIRIDIS = np.array([
    (0, 0.267004, 0.004874, 0.329415), (8, 0.277018, 0.050344, 0.375715), (16, 0.282327, 0.094955, 0.417331),
    (24, 0.282884, 0.135920, 0.453427), (32, 0.278826, 0.175490, 0.483397), (40, 0.270595, 0.214069, 0.507052),
    (48, 0.258965, 0.251537, 0.524736), (56, 0.244972, 0.287675, 0.537260), (64, 0.229739, 0.322361, 0.545706),
    (72, 0.214298, 0.355619, 0.551184), (80, 0.199430, 0.387607, 0.554642), (88, 0.185556, 0.418570, 0.556753),
    (96, 0.172719, 0.448791, 0.557885), (104, 0.160665, 0.478540, 0.558115), (112, 0.149039, 0.508051, 0.557250),
    (120, 0.137770, 0.537492, 0.554906), (128, 0.127568, 0.566949, 0.550556), (135, 0.121148, 0.592739, 0.544641),
    (143, 0.120081, 0.622161, 0.534946), (151, 0.130067, 0.651384, 0.521608), (159, 0.153894, 0.680203, 0.504172),
    (167, 0.191090, 0.708366, 0.482284), (175, 0.239374, 0.735588, 0.455688), (183, 0.296479, 0.761561, 0.424223),
    (191, 0.360741, 0.785964, 0.387814), (199, 0.430983, 0.808473, 0.346476), (207, 0.506271, 0.828786, 0.300362),
    (215, 0.585678, 0.846661, 0.249897), (223, 0.668054, 0.861999, 0.196293), (231, 0.751884, 0.874951, 0.143228),
    (239, 0.835270, 0.886029, 0.102646), (247, 0.916242, 0.896091, 0.100717), (255, 0.993248, 0.906157, 0.143936),
])
COLOUR_MAP = "viridis"
#: The colour of pixels that receive no light (Y <= 0 cd/m^2): darker than any colour of the map.
NO_LIGHT = (0, 0, 0)
#: The default range spans at most this many decades.
MAX_DECADES = 8
#: Images less tall than this (px) are enlarged by an integer factor ...
MIN_HEIGHT = 400
#: ... as long as they stay at most this wide (px).
MAX_WIDTH = 4096
#: The legend's text is about this share of the image's height (and at least 2 font pixels per glyph pixel).
TEXT_SHARE = 0.04
#: Legend colours: background and ink.
PAPER, INK = (255, 255, 255), (0, 0, 0)

#: The bitmap font: each glyph 5 columns by 7 rows above the baseline (digits, capitals' and
#: ascenders' height), plus 2 rows below it for descenders (g, p, q, y, _), written as rows of "#" and
#: ".". Digits, letters and the punctuation of the legends, chart labels and scene field names.
FONT_ROWS = {
    "0": ".###. #...# #..## #.#.# ##..# #...# .###.",
    "1": "..#.. .##.. ..#.. ..#.. ..#.. ..#.. .###.",
    "2": ".###. #...# ....# ...#. ..#.. .#... #####",
    "3": "##### ...#. ..#.. ...#. ....# #...# .###.",
    "4": "...#. ..##. .#.#. #..#. ##### ...#. ...#.",
    "5": "##### #.... ####. ....# ....# #...# .###.",
    "6": "..##. .#... #.... ####. #...# #...# .###.",
    "7": "##### ....# ...#. ..#.. .#... .#... .#...",
    "8": ".###. #...# #...# .###. #...# #...# .###.",
    "9": ".###. #...# #...# .#### ....# ...#. .##..",
    "a": "..... ..... .###. ....# .#### #...# .####",
    "b": "#.... #.... #.##. ##..# #...# #...# ####.",
    "c": "..... ..... .###. #.... #.... #...# .###.",
    "d": "....# ....# .##.# #..## #...# #...# .####",
    "e": "..... ..... .###. #...# ##### #.... .###.",
    "f": "..##. .#..# .#... ###.. .#... .#... .#...",
    "g": "..... ..... .##.# #..## #...# #...# .#### ....# .###.",
    "h": "#.... #.... #.##. ##..# #...# #...# #...#",
    "i": "..#.. ..... .##.. ..#.. ..#.. ..#.. .###.",
    "j": "...#. ..... ..##. ...#. ...#. ...#. ...#. #..#. .##..",
    "k": "#.... #.... #..#. #.#.. ##... #.#.. #..#.",
    "l": ".##.. ..#.. ..#.. ..#.. ..#.. ..#.. .###.",
    "m": "..... ..... ##.#. #.#.# #.#.# #...# #...#",
    "n": "..... ..... #.##. ##..# #...# #...# #...#",
    "o": "..... ..... .###. #...# #...# #...# .###.",
    "p": "..... ..... #.##. ##..# #...# #...# ####. #.... #....",
    "q": "..... ..... .##.# #..## #...# #...# .#### ....# ....#",
    "r": "..... ..... #.##. ##..# #.... #.... #....",
    "s": "..... ..... .###. #.... .###. ....# ####.",
    "t": ".#... .#... ###.. .#... .#... .#..# ..##.",
    "u": "..... ..... #...# #...# #...# #..## .##.#",
    "v": "..... ..... #...# #...# #...# .#.#. ..#..",
    "w": "..... ..... #...# #...# #.#.# #.#.# .#.#.",
    "x": "..... ..... #...# .#.#. ..#.. .#.#. #...#",
    "y": "..... ..... #...# #...# #...# #...# .#### ....# .###.",
    "z": "..... ..... ##### ...#. ..#.. .#... #####",
    ".": "..... ..... ..... ..... ..... .##.. .##..",
    ",": "..... ..... ..... ..... ..... .##.. .##.. ..#.. .#...",
    "-": "..... ..... ..... ##### ..... ..... .....",
    "+": "..... ..#.. ..#.. ##### ..#.. ..#.. .....",
    "/": "..... ....# ...#. ..#.. .#... #.... .....",
    "%": "##... ##..# ...#. ..#.. .#... #..## ...##",
    "<": "...#. ..#.. .#... #.... .#... ..#.. ...#.",
    ">": ".#... ..#.. ...#. ....# ...#. ..#.. .#...",
    "(": "...#. ..#.. .#... .#... .#... ..#.. ...#.",
    ")": ".#... ..#.. ...#. ...#. ...#. ..#.. .#...",
    ":": "..... .##.. .##.. ..... .##.. .##.. .....",
    "=": "..... ..... ##### ..... ##### ..... .....",
    "²": ".##.. ...#. ..#.. .###. ..... ..... .....",
    " ": "..... ..... ..... ..... ..... ..... .....",
    "_": "..... ..... ..... ..... ..... ..... ..... #####",
    "[": ".###. .#... .#... .#... .#... .#... .###.",
    "]": ".###. ...#. ...#. ...#. ...#. ...#. .###.",
    "*": "..... ..#.. #.#.# .###. #.#.# ..#.. .....",
    "?": ".###. #...# ....# ...#. ..#.. ..... ..#..",
    "A": ".###. #...# #...# ##### #...# #...# #...#",
    "B": "####. #...# #...# ####. #...# #...# ####.",
    "C": ".###. #...# #.... #.... #.... #...# .###.",
    "D": "###.. #..#. #...# #...# #...# #..#. ###..",
    "E": "##### #.... #.... ####. #.... #.... #####",
    "F": "##### #.... #.... ####. #.... #.... #....",
    "G": ".###. #...# #.... #.### #...# #...# .####",
    "H": "#...# #...# #...# ##### #...# #...# #...#",
    "I": ".###. ..#.. ..#.. ..#.. ..#.. ..#.. .###.",
    "J": "..### ...#. ...#. ...#. ...#. #..#. .##..",
    "K": "#...# #..#. #.#.. ##... #.#.. #..#. #...#",
    "L": "#.... #.... #.... #.... #.... #.... #####",
    "M": "#...# ##.## #.#.# #.#.# #...# #...# #...#",
    "N": "#...# #...# ##..# #.#.# #..## #...# #...#",
    "O": ".###. #...# #...# #...# #...# #...# .###.",
    "P": "####. #...# #...# ####. #.... #.... #....",
    "Q": ".###. #...# #...# #...# #.#.# #..#. .##.#",
    "R": "####. #...# #...# ####. #.#.. #..#. #...#",
    "S": ".#### #.... #.... .###. ....# ....# ####.",
    "T": "##### ..#.. ..#.. ..#.. ..#.. ..#.. ..#..",
    "U": "#...# #...# #...# #...# #...# #...# .###.",
    "V": "#...# #...# #...# #...# #...# .#.#. ..#..",
    "W": "#...# #...# #...# #.#.# #.#.# #.#.# .#.#.",
    "X": "#...# #...# .#.#. ..#.. .#.#. #...# #...#",
    "Y": "#...# #...# .#.#. ..#.. ..#.. ..#.. ..#..",
    "Z": "##### ....# ...#. ..#.. .#... #.... #####",
}
GLYPH_W, GLYPH_H, GLYPH_DESCENT = 5, 7, 2
#: Columns from one glyph to the next (one blank column between glyphs).
ADVANCE = GLYPH_W + 1


def _glyphs() -> dict[str, np.ndarray]:
    out = {}
    for ch, rows in FONT_ROWS.items():
        r = rows.split()
        r += ["....."] * (GLYPH_H + GLYPH_DESCENT - len(r))
        out[ch] = np.array([[c == "#" for c in row] for row in r], bool)
        if out[ch].shape != (GLYPH_H + GLYPH_DESCENT, GLYPH_W):
            raise ValueError(f"glyph {ch!r} of the bitmap font is not {GLYPH_W} x {GLYPH_H + GLYPH_DESCENT}")
    return out


#: char -> (9, 5) bool bitmap (7 rows above the baseline, 2 below).
FONT = _glyphs()


# -- colour map ---------------------------------------------------------------------------------------
#: Entries of colour_map's lookup table: the map interpolated at t = i / 65535, which holds every
#: control point exactly (their t = k / 255, and 65535 = 255 x 257) and is within 0.002 of a level
#: of the interpolation everywhere; one gather instead of three interpolations per pixel.
_LUT_SIZE = 65536


def _lookup_table() -> np.ndarray:
    t = np.arange(_LUT_SIZE) / (_LUT_SIZE - 1)
    x = VIRIDIS[:, 0] / 255.0
    rgb = np.stack([np.interp(t, x, VIRIDIS[:, c]) for c in (1, 2, 3)], axis=-1)
    return np.rint(rgb * 255.0).astype(np.uint8)


_LUT = _lookup_table()


def colour_map(t) -> np.ndarray:
    """Viridis, interpolated linearly between :data:`VIRIDIS`'s control points, at positions ``t``
    (any shape, finite, clamped to [0, 1]): (..., 3) uint8, sRGB-encoded."""
    t = np.clip(np.asarray(t, dtype=np.float64), 0.0, 1.0)
    return _LUT[np.rint(t * (_LUT_SIZE - 1)).astype(np.intp)]


# -- text ---------------------------------------------------------------------------------------------
def text_bitmap(text: str, scale: int = 1) -> np.ndarray:
    """``text`` in the bitmap font: (9 scale, (6 len - 1) scale) bool, True where ink; each glyph
    pixel is a ``scale`` x ``scale`` block. Raises ``ValueError`` for a character the font lacks."""
    missing = sorted(set(text) - set(FONT))
    if missing:
        raise ValueError(f"the bitmap font has no glyph for {''.join(missing)!r}")
    if not text:
        return np.zeros(((GLYPH_H + GLYPH_DESCENT) * scale, 0), bool)
    gap = np.zeros((GLYPH_H + GLYPH_DESCENT, ADVANCE - GLYPH_W), bool)
    parts = []
    for ch in text:
        parts += [FONT[ch], gap]
    bitmap = np.concatenate(parts[:-1], axis=1)
    return np.kron(bitmap, np.ones((scale, scale), bool))


def text_size(text: str, scale: int) -> tuple[int, int]:
    """(height, width) px of :func:`text_bitmap` (``text``, ``scale``)."""
    return (GLYPH_H + GLYPH_DESCENT) * scale, max(0, ADVANCE * len(text) - 1) * scale


def draw_text(canvas: np.ndarray, text: str, x: int, y: int, scale: int, colour=INK, anchor: str = "left"):
    """Draw ``text`` into ``canvas`` (H, W, 3) uint8 in place, its baseline's glyph rows centred on
    row ``y`` (the 7 rows above the baseline: digits sit centred on a tick), starting at column ``x``
    (``anchor`` "left"), ending there ("right") or centred on it ("centre"). Parts outside the canvas
    are cut off. Returns the (top, left) corner of the text box."""
    bm = text_bitmap(text, scale)
    h, w = bm.shape
    left = {"left": x, "right": x - w, "centre": x - w // 2}[anchor]
    top = y - (GLYPH_H * scale) // 2
    r0, c0 = max(top, 0), max(left, 0)
    r1, c1 = min(top + h, canvas.shape[0]), min(left + w, canvas.shape[1])
    if r1 > r0 and c1 > c0:
        sub = bm[r0 - top:r1 - top, c0 - left:c1 - left]
        canvas[r0:r1, c0:c1][sub] = colour
    return top, left


def decade_label(exponent: int) -> str:
    """The label of 10^``exponent``: 0.001, 0.01, 0.1, 1, 10, 100, 1000; 1e4 and up, 1e-4 and down."""
    if 0 <= exponent <= 3:
        return str(10**exponent)
    if -3 <= exponent < 0:
        return "0." + "0" * (-exponent - 1) + "1"
    return f"1e{exponent}"


def value_label(v: float) -> str:
    """A compact label for a positive value: 4 significant digits from 0.001 to 9999 (``25``,
    ``0.125``), mantissa and exponent outside (``2.5e4``, ``1e-6``); decades as :func:`decade_label`."""
    e = math.floor(math.log10(v))
    if v == 10.0**e:
        return decade_label(e)
    if 1e-3 <= v < 1e4:
        return f"{v:.4g}"
    m = v / 10.0**e
    return f"{m:.3g}e{e}"


# -- the colour bar -----------------------------------------------------------------------------------
def font_scale(height_px: int) -> int:
    """Font pixels per glyph pixel for a figure ``height_px`` tall: text about TEXT_SHARE of it."""
    return max(2, round(TEXT_SHARE * height_px / GLYPH_H))


def colour_legend(height: int, bar_top: int, bar_bottom: int, ticks: list[tuple[float, str]], title: str,
                  scale: int, below: bool = False, above: bool = False, no_light: bool = False):
    """A colour bar with its ticks, labels and title: (panel (height, w, 3) uint8, geometry dict).

    The bar fills rows ``bar_top`` to ``bar_bottom`` - 1; row r shows the colour map at
    t = (bar_bottom - r - 0.5) / (bar_bottom - bar_top) (t = 1 at the top). ``ticks`` are (t, label):
    a tick mark right of the bar at the row of t, its label beside it (labels that would overlap
    their upper neighbour are left out, the ticks stay). ``title`` is written centred above the bar,
    ``below`` / ``above`` add a triangle in the end colour beneath / atop the bar (values beyond the
    range, clamped), ``no_light`` a black swatch labelled "no light" under the bar.

    The geometry: "bar" (top, bottom, left, right: rows and columns, ends exclusive), "ticks"
    [{"t", "row", "label", "labelled", "label_box": (top, left, height, width)}], "caps" {end: {top,
    bottom}}, "title_box", "scale", "width".
    """
    s = scale
    bar_w = 6 * s
    tick_len = 2 * s
    label_gap = s
    margin = 2 * s
    bar_h = bar_bottom - bar_top
    if bar_h < 2:
        raise ValueError("the colour bar needs at least 2 rows")
    text_h = text_size("0", s)[0]
    label_w = max([text_size(lab, s)[1] for _, lab in ticks] + [text_size("no light", s)[1] if no_light else 0])
    content_w = bar_w + tick_len + label_gap + label_w
    width = max(content_w, text_size(title, s)[1]) + 2 * margin
    panel = np.empty((height, width, 3), np.uint8)
    panel[:] = PAPER
    bar_left = (width - content_w) // 2
    rows = np.arange(bar_top, bar_bottom)
    t_rows = (bar_bottom - rows - 0.5) / bar_h
    panel[bar_top:bar_bottom, bar_left:bar_left + bar_w] = colour_map(t_rows)[:, None, :]
    # Triangular caps for clamped values, in the colour of the bar's end.
    cap_h, label_up, label_down = _reach(s)
    cols = np.arange(bar_w)
    half = (bar_w - 1) / 2
    k = np.arange(cap_h)[:, None]  # rows from the bar's end
    triangle = np.abs(cols[None, :] - half) <= half * (1 - (k + 0.5) / cap_h)
    caps = {}
    for end, on in (("below", below), ("above", above)):
        if on:
            r0 = bar_bottom if end == "below" else bar_top - cap_h
            block = panel[r0:r0 + cap_h, bar_left:bar_left + bar_w]
            block[triangle if end == "below" else triangle[::-1]] = colour_map(0.0 if end == "below" else 1.0)
            caps[end] = {"top": r0, "bottom": r0 + cap_h}
    # Ticks and labels.
    tick_left = bar_left + bar_w
    tick_t = 2 * (s // 4) + 1  # odd: centred on its row
    out_ticks = []
    last_top = None
    for t, label in sorted(ticks, key=lambda x: -x[0]):  # from the top down
        row = int(np.clip(round(bar_bottom - t * bar_h - 0.5), bar_top, bar_bottom - 1))
        panel[row - tick_t // 2:row + tick_t // 2 + 1, tick_left:tick_left + tick_len] = INK
        top = row - (GLYPH_H * s) // 2
        labelled = last_top is None or top >= last_top + text_h
        box = None
        if labelled:
            top, left = draw_text(panel, label, tick_left + tick_len + label_gap, row, s)
            box = (top, left, *text_size(label, s))
            last_top = top
        out_ticks.append({"t": float(t), "row": row, "label": label, "labelled": labelled, "label_box": box})
    # The title's box ends ``margin`` above the bar's top label and cap; the swatch starts as far below.
    title_row = bar_top - max(cap_h if above else 0, label_up) - margin - text_h + (GLYPH_H * s) // 2
    title_top, title_left = draw_text(panel, title, width // 2, title_row, s, anchor="centre")
    if no_light:
        sw_top = bar_bottom + max(cap_h if below else 0, label_down) + margin
        panel[sw_top:sw_top + bar_w, bar_left:bar_left + bar_w] = INK
        panel[sw_top + s:sw_top + bar_w - s, bar_left + s:bar_left + bar_w - s] = NO_LIGHT
        draw_text(panel, "no light", tick_left + tick_len + label_gap, sw_top + bar_w // 2, s)
    geometry = {"bar": {"top": bar_top, "bottom": bar_bottom, "left": bar_left, "right": bar_left + bar_w},
                "ticks": out_ticks, "caps": caps, "scale": s, "width": width,
                "title_box": (title_top, title_left, *text_size(title, s))}
    return panel, geometry


def _reach(scale: int) -> tuple[int, int, int]:
    """(height of a cap, rows a tick's label reaches above and below its row) at font ``scale``."""
    s = scale
    up = (GLYPH_H * s) // 2
    return 4 * s, up, text_size("0", s)[0] - up


def legend_space(scale: int) -> tuple[int, int]:
    """Rows (above, below) the colour bar that :func:`colour_legend` needs at font ``scale`` for its
    title, caps, end labels and no-light swatch."""
    s = scale
    margin, text_h = 2 * s, text_size("0", s)[0]
    cap_h, up, down = _reach(s)
    return margin + text_h + margin + max(cap_h, up), max(cap_h, down) + margin + max(6 * s, text_h) + margin


# -- false colour -------------------------------------------------------------------------------------
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
    ``info["upscale"]`` (nearest-neighbour) at the left, the legend at the right; info holds "lo",
    "hi" (cd/m^2), "decades" (log10 hi/lo), "range" (how lo and hi were chosen), "colour_map",
    "no_light_colour", "below" / "above" (fractions of the pixels clamped at the range's ends, lit
    pixels below lo and pixels above hi), "no_light" (fraction at or below 0 cd/m^2), "upscale",
    "image" (top, left, height, width of the image in rgb) and "legend" (the colour bar's geometry
    from :func:`colour_legend`, its columns in rgb's coordinates).

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
    img = colour_map(t)
    img[~lit] = NO_LIGHT
    img = np.repeat(np.repeat(img, k, axis=0), k, axis=1)
    below, above = bool(np.any(lit & (y < lo))), bool(np.any(y > hi))

    ih, iw = img.shape[:2]
    s = font_scale(ih)
    space_above, space_below = legend_space(s)
    height = max(ih, space_above + space_below + 12 * text_size("0", s)[0])
    decades = range(math.ceil(log_lo - 1e-9), math.floor(log_hi + 1e-9) + 1)
    ticks = [((e - log_lo) / (log_hi - log_lo), decade_label(e)) for e in decades]
    if len(ticks) < 2:  # a range within one decade: its ends are labelled too
        ticks += [(t0, value_label(v)) for t0, v in ((0.0, lo), (1.0, hi))
                  if all(abs(t0 - t) > 1e-9 for t, _ in ticks)]
    panel, geo = colour_legend(height, space_above, height - space_below, ticks, "cd/m²", s, below, above,
                               no_light=True)
    gap = 3 * s
    canvas = np.empty((height, iw + gap + panel.shape[1], 3), np.uint8)
    canvas[:] = PAPER
    top = (height - ih) // 2
    canvas[top:top + ih, :iw] = img
    canvas[:, iw + gap:] = panel
    shift = iw + gap
    geo["bar"]["left"] += shift
    geo["bar"]["right"] += shift
    for tk in geo["ticks"]:
        if tk["label_box"] is not None:
            b = tk["label_box"]
            tk["label_box"] = (b[0], b[1] + shift, b[2], b[3])
    b = geo["title_box"]
    geo["title_box"] = (b[0], b[1] + shift, b[2], b[3])
    n = y.size
    info = {"lo": lo, "hi": hi, "decades": log_hi - log_lo, "range": how, "colour_map": COLOUR_MAP,
            "no_light_colour": list(NO_LIGHT), "scale": "log10 of Y, cd/m^2",
            "below": float(np.count_nonzero(lit & (y < lo)) / n), "above": float(np.count_nonzero(y > hi) / n),
            "no_light": float(np.count_nonzero(~lit) / n), "upscale": k,
            "image": {"top": top, "left": 0, "height": ih, "width": iw}, "legend": geo}
    return canvas, info


#: The first four bytes of every OpenEXR file (the OpenEXR file layout, "magic number").
EXR_MAGIC = bytes((0x76, 0x2F, 0x31, 0x01))


def read_luminance(path) -> np.ndarray:
    """The luminance Y (H, W) cd/m^2 of an image.exr written by the tracer: its Y channel, or
    Y = 0.2126 R + 0.7152 G + 0.0722 B (:func:`tracer.core.units.luminance`) where it has none.

    Raises :class:`~tracer.core.errors.SceneError` naming the file, and the channel where one is at
    fault, for a file that is missing, not an OpenEXR file, without Y nor R, G and B, or holding
    non-finite values; :class:`~tracer.core.errors.ImageReadError` for one OpenImageIO cannot read."""
    p = Path(path)
    if not p.is_file():
        raise SceneError(str(path), "", "no such file" if not p.exists() else "is not a file")
    try:
        with open(p, "rb") as fh:
            magic = fh.read(4)
    except OSError as e:
        raise SceneError(str(path), "", f"cannot be read ({e.strerror or e})") from None
    if magic != EXR_MAGIC:
        raise SceneError(str(path), "", "is not an OpenEXR file (the false-colour view reads the luminance of an "
                                        "image.exr written by hud-trace render)")
    channels, _ = read_exr_channels(p)
    if "Y" in channels:
        name, y = "Y", channels["Y"]
    elif {"R", "G", "B"} <= set(channels):
        name, y = "R, G, B", luminance(np.stack([channels[c] for c in "RGB"], axis=-1))
    else:
        have = ", ".join(sorted(channels)) or "none"
        raise SceneError(str(path), "channels", f"has no Y channel, nor R, G and B to make it from (its channels: "
                                                f"{have})")
    if not np.all(np.isfinite(y)):
        raise SceneError(str(path), name, "holds non-finite values (NaN or Inf)")
    y = np.asarray(y, dtype=np.float64)
    low, high = float(y.min()), float(y.max())
    if low < -1e-6 * max(high, 0.0):  # rounding (a denoiser's, a colour transform's) is tolerated
        raise SceneError(str(path), name, f"holds negative luminance (down to {low:.4g} cd/m^2): not a luminance "
                                          "image")
    return y


def write_as_set(path, write, check) -> None:
    """Write one file as a set of one (:class:`tracer.products.outputs.OutputSet`): its folder is checked and
    locked, the file written beside it in a staging folder, read back by ``check(staged_path)``
    and only then moved onto ``path``. Raises :class:`~tracer.products.outputs.OutputFolderError` when the
    folder cannot take it, :class:`~tracer.products.outputs.OutputWriteError` when writing fails (``path``
    then keeps what it held)."""
    path = Path(path)
    outputs = OutputSet(path.parent, (path.name,)).open()
    try:
        outputs.commit([OutputFile(path.name, write, check)])
        outputs.keep()
    finally:
        outputs.close()


def png_file(name: str, rgb: np.ndarray) -> OutputFile:
    """An 8-bit PNG of ``rgb`` as a file of a set, checked by reading its pixels back."""
    def check(p):
        back = np.rint(read_image(p, linear=True) * 255.0).astype(np.uint8)
        if back.shape != rgb.shape or not np.array_equal(back, rgb):
            raise ValueError("the pixels read back differ from those written")

    return OutputFile(name, lambda p: write_png(p, rgb), check)


def save_false_colour(path, y, lo: float | None = None, hi: float | None = None) -> dict:
    """Write :func:`false_colour` (``y``, ``lo``, ``hi``) to the PNG file ``path`` as a set
    (:func:`write_as_set`); returns its info dict."""
    rgb, info = false_colour(y, lo, hi)
    f = png_file(Path(path).name, rgb)
    write_as_set(path, f.write, f.check)
    return info
