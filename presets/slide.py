"""The LCD slides of hud-direct (paper Fig. 6): clear symbols on a black background, drawn from a
5 x 7 pixel font so that no image file is committed, and a grid for the optical analysis's variants."""

from __future__ import annotations

from pathlib import Path

import numpy as np

try:  # inside the Blender extension, presets and tracer are subpackages of the extension package
    from ..tracer.core.imageio import write_png
except ImportError:  # presets and tracer as top-level packages (command line, tests)
    from tracer.core.imageio import write_png

FONT = {  # 5 x 7 glyphs, one string of five bits per row, top row first
    "0": ["01110", "10001", "10011", "10101", "11001", "10001", "01110"],
    "1": ["00100", "01100", "00100", "00100", "00100", "00100", "01110"],
    "2": ["01110", "10001", "00001", "00010", "00100", "01000", "11111"],
    "3": ["11110", "00001", "00001", "01110", "00001", "00001", "11110"],
    "4": ["00010", "00110", "01010", "10010", "11111", "00010", "00010"],
    "5": ["11111", "10000", "11110", "00001", "00001", "10001", "01110"],
    "6": ["00110", "01000", "10000", "11110", "10001", "10001", "01110"],
    "7": ["11111", "00001", "00010", "00100", "01000", "01000", "01000"],
    "8": ["01110", "10001", "10001", "01110", "10001", "10001", "01110"],
    "9": ["01110", "10001", "10001", "01111", "00001", "00010", "01100"],
    "k": ["10000", "10000", "10010", "10100", "11000", "10100", "10010"],
    "m": ["00000", "00000", "11010", "10101", "10101", "10001", "10001"],
    "h": ["10000", "10000", "10110", "11001", "10001", "10001", "10001"],
    "/": ["00001", "00010", "00010", "00100", "01000", "01000", "10000"],
    " ": ["00000"] * 7,
}


def draw_text(canvas: np.ndarray, text: str, x0: int, y0: int, scale: int):
    """Set the pixels of ``text`` (scale x scale cells per font bit) to 1, top-left at (x0, y0)."""
    x = x0
    for ch in text:
        bits = np.array([[int(b) for b in row] for row in FONT[ch]], dtype=bool)
        block = np.kron(bits, np.ones((scale, scale), dtype=bool))
        canvas[y0:y0 + block.shape[0], x:x + block.shape[1]] |= block
        x += 6 * scale


def slide_array(width: int = 240, height: int = 80) -> np.ndarray:
    """(height, width) float array: 1 = clear cell, 0 = black cell."""
    c = np.zeros((height, width), dtype=bool)
    draw_text(c, "88", 14, 12, 8)
    draw_text(c, "km/h", 118, 40, 4)
    # A turn arrow at the right: a shaft and a head.
    c[22:62, 208:216] = True
    for k in range(14):
        c[14 + k, 212 - k:213 + k] = True
    c[68:72, 10:230] = True  # a thin bar: a lane/progress marker
    return c.astype(np.float64)


def grid_array(width: int = 240, height: int = 80, lines=(5, 3), thickness: int = 2) -> np.ndarray:
    """(height, width) float array of a grid slide: ``lines`` [across, up] clear lines ``thickness``
    pixels wide, the outermost along the slide's edges, on black: the optical analysis's field grid
    (tracer.scene.format.TARGET field_grid), for a render that shows the distortion it reports."""
    c = np.zeros((height, width), dtype=bool)
    for k in range(lines[0]):
        x = round(k * (width - thickness) / (lines[0] - 1))
        c[:, x:x + thickness] = True
    for k in range(lines[1]):
        y = round(k * (height - thickness) / (lines[1] - 1))
        c[y:y + thickness, :] = True
    return c.astype(np.float64)


def slide_image(path: Path, width: int = 240, height: int = 80, grid: bool = False) -> Path:
    """Write the slide (the symbols, or with ``grid`` the grid) as an 8-bit PNG (0 or 255: exact in
    sRGB and linear alike)."""
    a = (255 * (grid_array(width, height) if grid else slide_array(width, height))).astype(np.uint8)
    path.parent.mkdir(parents=True, exist_ok=True)
    write_png(path, np.repeat(a[:, :, None], 3, axis=2))
    return path
