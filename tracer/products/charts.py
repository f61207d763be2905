"""Charts in one style, drawn by matplotlib: a sweep's figures against its parameter, the eyebox map,
the false-colour view's colour bar (:mod:`.falsecolour`) and the benchmarks' convergence charts.

matplotlib is used through its object API on the Agg canvas: no pyplot (no global state, no display),
so the same code runs on the command line, in worker processes and inside Blender, whose extension
bundles matplotlib. A picture comes back as an (H, W, 3) uint8 sRGB array, which the output sets
write as PNG and read back (:mod:`.outputs`), with its geometry in pixels (row 0 at the top) for the
tests and for sweep.json. Every axis names its quantity and its unit.
"""

from __future__ import annotations

import math

import numpy as np

#: Pixels per inch of every chart (sizes below are in inches at this resolution).
DPI = 100
#: Font size of tick labels, legends and captions, pt; titles one point larger.
FONT_PT = 9
#: Colours: a requirement's threshold and the eyebox's outline, the recommended range, grid lines.
THRESHOLD = "#e00000"
SHADE = "#d5edd5"
GRID = "#dddddd"
#: The colour map of every chart and of the false-colour view: viridis (van der Walt, Smith and Firing
#: 2015), perceptually uniform, its luminance rising monotonically from end to end.
COLOUR_MAP = "viridis"


def _mpl():
    """matplotlib's figure and Agg canvas, imported when a chart is drawn (not when the tracer is)."""
    import matplotlib

    matplotlib.rcParams.update({"font.size": FONT_PT, "axes.titlesize": FONT_PT + 1, "axes.labelsize": FONT_PT,
                                "legend.fontsize": FONT_PT - 1})
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    return Figure, FigureCanvasAgg


def colour_map():
    """The charts' colour map (matplotlib's viridis, 256 entries)."""
    import matplotlib

    return matplotlib.colormaps[COLOUR_MAP]


def colours(t) -> np.ndarray:
    """The colour map at positions ``t`` (any shape, clamped to [0, 1]): (..., 3) uint8, sRGB-encoded,
    exactly the colours the map's 256 entries give an image drawn through it."""
    t = np.clip(np.asarray(t, dtype=np.float64), 0.0, 1.0)
    lut = np.rint(colour_map()(np.arange(256))[:, :3] * 255.0).astype(np.uint8)
    return lut[np.minimum((t * 256).astype(np.intp), 255)]


def new_figure(width_in: float, height_in: float):
    """A blank figure of the charts' style and its canvas."""
    Figure, Canvas = _mpl()
    fig = Figure(figsize=(width_in, height_in), dpi=DPI, facecolor="white")
    return fig, Canvas(fig)


def value_label(v: float) -> str:
    """A compact tick label: 4 significant digits from 0.001 to 9999 (``25``, ``0.125``), mantissa and
    exponent outside (``2.5e4``, ``1e-6``), 0 as ``0``, signed."""
    if v == 0:
        return "0"
    a = abs(v)
    e = math.floor(math.log10(a))
    if 1e-3 <= a < 1e4:
        text = f"{a:.4g}"
    else:
        m = a / 10.0**e
        text = f"1e{e}" if abs(m - 1) < 1e-9 else f"{m:.3g}e{e}"
    return ("-" if v < 0 else "") + text


def style(ax, log_x: bool = False, log_y: bool = False):
    """The charts' axes: log scales where asked, labelled at 1, 2 and 5 times each decade in plain
    numbers (:func:`value_label`), a light grid behind the data."""
    from matplotlib.ticker import FuncFormatter, LogLocator, NullFormatter

    for log, axis, scale in ((log_x, ax.xaxis, ax.set_xscale), (log_y, ax.yaxis, ax.set_yscale)):
        if log:
            scale("log")
            axis.set_major_locator(LogLocator(subs=(1.0, 2.0, 5.0)))
            axis.set_minor_formatter(NullFormatter())
        axis.set_major_formatter(FuncFormatter(lambda v, _pos: value_label(v)))
    ax.grid(True, which="major", color=GRID, linewidth=0.8)
    ax.set_axisbelow(True)


def pixels(canvas) -> np.ndarray:
    """The drawn figure as (H, W, 3) uint8 sRGB."""
    canvas.draw()
    return np.asarray(canvas.buffer_rgba())[..., :3].copy()


def to_pixel(ax, x, y) -> tuple[float, float]:
    """(column, row) of the data point (x, y) in the figure's picture, row 0 at the top."""
    px, py = ax.transData.transform((x, y))
    return float(px), float(ax.figure.bbox.height - py)


def box(ax) -> list[int]:
    """The axes' plot box in the picture: [top, left, height, width], pixels."""
    b = ax.get_window_extent()
    h = ax.figure.bbox.height
    return [int(round(h - b.y1)), int(round(b.x0)), int(round(b.height)), int(round(b.width))]


def pretty_unit(unit: str) -> str:
    """A unit as a chart writes it: cd/m^2 as cd/m², 1 (a ratio) as nothing."""
    return {"1": "", "cd/m^2": "cd/m²", "mm^2": "mm²", "(cd/m^2)^2": "(cd/m²)²"}.get(unit, unit)


def label(name: str, unit: str) -> str:
    """An axis label: the quantity and, where it has one, its unit."""
    u = pretty_unit(unit)
    return f"{name}, {u}" if u else name


def is_log(values) -> bool:
    """Log axis where the values are positive and span more than a decade."""
    values = [v for v in values if v is not None and math.isfinite(v)]
    return bool(values) and min(values) > 0 and max(values) > 10 * min(values)


# -- the sweep ----------------------------------------------------------------------------------------
def sweep_chart(panels: list[dict], x: dict, series: list[dict], caption: list[str]) -> tuple[np.ndarray, dict]:
    """A sweep's chart: one panel per figure against the swept parameter.

    ``panels``: [{"key", "unit", "thresholds": [{"requirement", "value"}], "shaded": [[from, to]]
    (parameter intervals), "points": {run: figure}}]; ``x``: {"field", "unit", "log", "values": {run:
    parameter}}; ``series``: [{"label", "runs": [run, ...] in order of the parameter, "meets": {run:
    bool}, "curves": {panel key: {run: (parameter (k,), figure (k,))}}}] where a curve joins a run to the
    next as the recommendation interpolates between them; ``caption``: lines above the panels.

    Each run is a marker (filled where it meets every requirement), each series a line in its colour
    of the colour map, each threshold a dashed red line, each recommended interval shaded. Returns
    (rgb, geometry): {"width", "height", "panels": [{"key", "box", "x": {"log", "ticks": [{"value",
    "px"}]}, "y": {...}, "thresholds": [{"requirement", "value", "row"}], "shaded": [[first, last
    column]], "points": [{"run", "row", "column", "meets"}]}]}, in pixels of the picture.
    """
    import textwrap

    caption = [part for line in caption for part in textwrap.wrap(line, 110)]
    n = max(1, len(panels))
    legend_rows = len(series) if len(series) > 1 else 0
    height_in = 0.65 + 0.2 * len(caption) + 2.1 * n + 0.45 + 0.2 * legend_rows
    fig, canvas = new_figure(7.2, height_in)
    top = 1 - (0.45 + 0.2 * len(caption)) / height_in
    bottom = (0.55 + 0.2 * legend_rows) / height_in
    grid = fig.add_gridspec(n, 1, left=0.13, right=0.97, top=top, bottom=bottom, hspace=0.45)
    cmap = colour_map()
    tints = [cmap(t) for t in (np.linspace(0.0, 0.8, len(series)) if len(series) > 1 else [0.25] * len(series))]
    for i, line in enumerate(caption):
        fig.text(0.01, 1 - (0.1 + 0.2 * i) / height_in, line, va="top", ha="left", fontsize=FONT_PT)
    axes = []
    for p, panel in enumerate(panels):
        ax = fig.add_subplot(grid[p])
        values = list(panel["points"].values()) + [q["value"] for q in panel["thresholds"]]
        style(ax, x["log"], is_log(values))
        for lo, hi in panel["shaded"]:
            ax.axvspan(lo, hi, color=SHADE, linewidth=0, zorder=0)
        for q in panel["thresholds"]:
            ax.axhline(q["value"], color=THRESHOLD, linestyle=(0, (4, 2)), linewidth=1.5, zorder=2)
            ax.annotate(q["requirement"].split(maxsplit=1)[1] if " " in q["requirement"] else q["requirement"],
                        (1, q["value"]), xycoords=("axes fraction", "data"), xytext=(-3, 3),
                        textcoords="offset points", ha="right", va="bottom", color=THRESHOLD)
        for s, tint in zip(series, tints, strict=True):
            for cx, cy in s["curves"].get(panel["key"], {}).values():
                ax.plot(cx, cy, color=tint, linewidth=1.5, zorder=3)
            for run in s["runs"]:
                if run in panel["points"]:
                    met = s["meets"][run]
                    ax.plot([x["values"][run]], [panel["points"][run]], "o", markersize=6, color=tint,
                            markerfacecolor=tint if met else "white", markeredgewidth=1.5, zorder=4)
        if not panel["points"]:
            ax.text(0.5, 0.5, "no run has this figure", transform=ax.transAxes, ha="center", va="center")
        ax.set_title(panel["key"], loc="left")
        ax.set_ylabel(pretty_unit(panel["unit"]) or "ratio")
        axes.append(ax)
    if axes:
        axes[-1].set_xlabel(label(x["field"], x["unit"]))
        xs = list(x["values"].values())
        if xs:
            lo, hi = min(xs), max(xs)
            if x["log"] and lo > 0:
                pad = (hi / lo) ** 0.04 if hi > lo else 1.5
                axes[0].set_xlim(lo / pad, hi * pad)
            else:
                pad = 0.04 * (hi - lo) or (0.1 * abs(lo) or 1.0)
                axes[0].set_xlim(lo - pad, hi + pad)
            for ax in axes[1:]:
                ax.set_xlim(axes[0].get_xlim())
    if legend_rows:
        handles = [fig.axes[0].plot([], [], "-o", color=t, markerfacecolor=t)[0] for t in tints]
        fig.legend(handles, [s["label"] for s in series], loc="lower left", bbox_to_anchor=(0.12, 0.0),
                   frameon=False, fontsize=FONT_PT - 1)
    rgb = pixels(canvas)
    geometry = {"width": rgb.shape[1], "height": rgb.shape[0], "panels": []}
    for ax, panel in zip(axes, panels, strict=True):
        top_, left_, h_, w_ = box(ax)
        ylo, yhi = ax.get_ylim()
        xlo, xhi = ax.get_xlim()
        geometry["panels"].append({
            "key": panel["key"], "box": [top_, left_, h_, w_],
            "x": {"log": x["log"], "lo": xlo, "hi": xhi,
                  "ticks": [{"value": float(t), "px": to_pixel(ax, t, ylo)[0]} for t in ax.get_xticks()
                            if xlo <= t <= xhi]},
            "y": {"log": ax.get_yscale() == "log", "lo": ylo, "hi": yhi,
                  "ticks": [{"value": float(t), "px": to_pixel(ax, xlo, t)[1]} for t in ax.get_yticks()
                            if ylo <= t <= yhi]},
            "thresholds": [{"requirement": q["requirement"], "value": q["value"],
                            "row": to_pixel(ax, xlo, q["value"])[1]} for q in panel["thresholds"]],
            "shaded": [[to_pixel(ax, lo, ylo)[0], to_pixel(ax, hi, ylo)[0]] for lo, hi in panel["shaded"]],
            "points": [{"run": run, "column": to_pixel(ax, x["values"][run], v)[0],
                        "row": to_pixel(ax, x["values"][run], v)[1],
                        "meets": any(s["meets"].get(run, False) for s in series)}
                       for run, v in panel["points"].items()]})
    return rgb, geometry


# -- the eyebox ---------------------------------------------------------------------------------------
def eyebox_chart(relative: np.ndarray, region: np.ndarray, right_mm: np.ndarray, up_mm: np.ndarray,
                 threshold: float, caption: str) -> tuple[np.ndarray, dict]:
    """The eyebox map: over the grid of eye offsets (``right_mm`` (nx,), ``up_mm`` (ny,) from the design
    eye), the least relative luminance ``relative`` (ny, nx) of the display's field points in % of its
    design value (black where NaN: nothing comparable), the eyebox ``region`` (ny, nx) outlined in red,
    the design eye (offset 0, 0) a red cross, a colour bar with the ``threshold`` among its ticks.

    Returns (rgb, geometry): {"box": the map's [top, left, height, width] px, "cells": {"right_mm",
    "up_mm"}: the pixel column and row of each offset's centre, "top_of_scale": the relative value at
    the colour bar's top}."""
    ny, nx = relative.shape
    step_x = float(right_mm[1] - right_mm[0]) if nx > 1 else 1.0
    step_y = float(up_mm[1] - up_mm[0]) if ny > 1 else 1.0
    finite = np.isfinite(relative)
    top = max(1.0, math.ceil(10 * np.nanmax(relative)) / 10) if finite.any() else 1.0
    aspect = (ny * step_y) / (nx * step_x)
    width_in = 7.0
    height_in = min(7.0, max(3.0, 0.9 + 5.0 * aspect))
    fig, canvas = new_figure(width_in, height_in)
    ax = fig.add_axes((0.1, 0.14, 0.72, 1 - 0.14 - 0.45 / height_in))
    cax = fig.add_axes((0.86, 0.14, 0.025, 1 - 0.14 - 0.45 / height_in))
    cmap = colour_map().with_extremes(bad="black")
    extent = (right_mm[0] - step_x / 2, right_mm[-1] + step_x / 2, up_mm[0] - step_y / 2, up_mm[-1] + step_y / 2)
    shown = np.where(finite, 100 * relative, np.nan)
    image = ax.imshow(shown, cmap=cmap, vmin=0.0, vmax=100 * top, origin="lower", extent=extent,
                      interpolation="nearest", aspect="auto")
    # The eyebox's outline: the edges between cells inside and outside it, in one collection.
    padded = np.pad(region, 1, constant_values=False)
    jj, ii = np.nonzero(padded[:-1, 1:-1] != padded[1:, 1:-1])  # horizontal edges: below row jj, column ii
    x0 = right_mm[0] + (ii - 0.5) * step_x
    y0 = up_mm[0] + (jj - 0.5) * step_y
    segments = [[(a, b), (a + step_x, b)] for a, b in zip(x0, y0, strict=True)]
    jj, ii = np.nonzero(padded[1:-1, :-1] != padded[1:-1, 1:])  # vertical edges: left of column ii, row jj
    x0 = right_mm[0] + (ii - 0.5) * step_x
    y0 = up_mm[0] + (jj - 0.5) * step_y
    segments += [[(a, b), (a, b + step_y)] for a, b in zip(x0, y0, strict=True)]
    from matplotlib.collections import LineCollection

    ax.add_collection(LineCollection(segments, colors=THRESHOLD, linewidths=2))
    ax.plot([0.0], [0.0], "+", color=THRESHOLD, markersize=12, markeredgewidth=2)
    ax.set_xlim(extent[:2])
    ax.set_ylim(extent[2:])
    ax.set_xlabel(label("eye offset right", "mm"))
    ax.set_ylabel(label("eye offset up", "mm"))
    ax.set_title(caption, loc="left")
    bar = fig.colorbar(image, cax=cax)
    ticks = sorted(set(np.round(np.arange(0, 100 * top + 1e-9, 25), 6)) | {round(100 * threshold, 6)})
    bar.set_ticks(ticks)
    bar.set_label("least field point, % of design")
    rgb = pixels(canvas)
    geometry = {"box": box(ax), "top_of_scale": top,
                "cells": {"right_mm": [to_pixel(ax, v, 0.0)[0] for v in right_mm],
                          "up_mm": [to_pixel(ax, 0.0, v)[1] for v in up_mm]}}
    return rgb, geometry
