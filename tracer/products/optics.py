"""The optical analysis's output set (``hud-trace optics``; tracer.analysis.optics.analyse gives the
document): optics.json, optics.csv and the pictures a design review reads.

- optics.json: the document, every non-finite number written as null (a field point no chief ray
  reaches).
- optics.csv: one row per eye point and field point (the design eye point's rows first), the metrics
  that belong to one ray: image angles, VID, astigmatism, distortion, ghost separation.
- optics-distortion.png: the image of the PGU's field grid from the design eye point, drawn over the
  best rectangular grid, its departures from it magnified by a stated factor.
- optics-eyebox.png: maps over the eyebox of the dynamic distortion, the ghost separation (each the
  worst field point at each eye point), and the convergence or divergence and the dipvergence of the
  binocular pair centred there (the worst field point, signed).
- optics-vid.png: the VID (and astigmatism) of each field point from the design eye point.
"""

from __future__ import annotations

import csv
import io
import json
import math

import numpy as np

from . import charts
from .outputs import OutputFile, png_file

OUTPUT_NAMES = ("optics.json", "optics.csv", "optics-distortion.png", "optics-eyebox.png", "optics-vid.png")

#: optics.csv's columns after the eye point's and field point's coordinates.
CSV_METRICS = ("azimuth_deg", "elevation_deg", "vid_mm", "astigmatism_d", "distortion_mrad", "dynamic_distortion_mrad",
               "ghost_separation_arcmin")


def clean(value):
    """``value`` with every NaN or infinite float replaced by None (JSON's null), recursively."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {k: clean(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [clean(v) for v in value]
    if isinstance(value, np.generic):
        return clean(value.item())
    return value


# -- what a person reads --------------------------------------------------------------------------
def readouts(doc: dict) -> list[tuple[str, str]]:
    """The analysis's summary as (label, text) rows, for the command line and Blender's HUD Optics panel."""
    s = doc["summary"]["design_eye"]

    def f(key, unit, fmt=".3g", where=s):
        v = where.get(key)
        return "n/a" if v is None or not math.isfinite(v) else f"{v:{fmt}} {unit}".rstrip()

    rows = [("Chain", doc["chains"]["primary"]),
            ("VID", f"{f('vid_mm', 'mm', '.1f')} ({f('vid_tangential_mm', '', '.1f')} tangential, "
                    f"{f('vid_sagittal_mm', '', '.1f')} sagittal)"),
            ("Look-down, look-over", f"{f('look_down_deg', 'deg', '.2f')}, {f('look_over_deg', 'deg', '.2f')}"),
            ("Field of view", f"{f('fov_h_deg', '', '.2f')} x {f('fov_v_deg', 'deg', '.2f')}"),
            ("Magnification", f"{f('magnification_h', '')} x {f('magnification_v', '')} (H x V)"),
            ("Static distortion", f"{f('static_distortion_mrad', 'mrad')}; smile {f('smile_mrad', 'mrad')}, "
                                  f"rotation {f('rotation_mrad', 'mrad')}, trapezoid {f('trapezoid_h_percent', '%')}"),
            ("Astigmatism, field curvature", f"{f('astigmatism_d', 'D')}, {f('field_curvature_d', 'D')}"),
            ("Spot, pixel", f"{f('spot_rms_arcmin', 'arcmin')} rms, {f('pixel_size_arcmin', 'arcmin')}")]
    if doc["chains"]["ghost"]:
        rows.append(("Ghost", f"{f('ghost_separation_centre_arcmin', 'arcmin')} at the centre, "
                              f"{f('ghost_separation_arcmin', 'arcmin')} at most; luminance ratio "
                              f"{f('ghost_ratio', '')}"))
    if s.get("pgu_usage") is not None:
        rows.append(("PGU usage", f"{100 * s['pgu_usage']:.1f} %"))
    box = doc["summary"].get("eyebox")
    if box:
        rows += [("Eye points", f"{box['eye_points_seeing_every_field_point']} see every field point"),
                 ("Dynamic distortion", f('dynamic_distortion_mrad', 'mrad', where=box)),
                 ("Convergence, divergence", f"{f('convergence_mrad', 'mrad', where=box)}, "
                                             f"{f('divergence_mrad', 'mrad', where=box)}"),
                 ("Dipvergence", f('dipvergence_mrad', 'mrad', where=box)),
                 ("Focus variation", f('focus_variation_d', 'D', where=box))]
    for r in doc["requirements"]:
        rows.append(("Requirement", f"{r['requirement']}: " + ("met" if r["met"] else f"NOT met ({r['why']})")))
    return rows


# -- optics.csv ------------------------------------------------------------------------------------
def csv_rows(doc: dict) -> list[list]:
    """optics.csv's rows, header first: eye (``design`` or ``eyebox``), eye_right_mm, eye_up_mm,
    field_row, field_column, pgu_x_mm, pgu_y_mm, then :data:`CSV_METRICS` (empty where unknown)."""
    head = ["eye", "eye_right_mm", "eye_up_mm", "field_row", "field_column", "pgu_x_mm", "pgu_y_mm", *CSV_METRICS]
    rows = [head]
    fields = doc["field_points"]
    for f in fields:
        rows.append(["design", 0.0, 0.0, f["row"], f["column"], *f["pgu_mm"],
                     *[f.get(k) for k in CSV_METRICS]])
    for e in doc.get("eye_points", []):
        for j, f in enumerate(fields):
            per = {k: (e[k][j] if isinstance(e.get(k), list) else None) for k in CSV_METRICS}
            rows.append(["eyebox", *e["offset_mm"], f["row"], f["column"], *f["pgu_mm"],
                         *[per[k] for k in CSV_METRICS]])
    return rows


def csv_text(doc: dict) -> str:
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    for row in csv_rows(doc):
        w.writerow(["" if v is None else (repr(float(v)) if isinstance(v, (float, np.floating)) else v)
                    for v in row])
    return buf.getvalue()


def read_csv(path) -> list[dict]:
    """optics.csv's rows as dicts (numbers as floats, empty cells as None)."""
    with open(path, newline="") as fh:
        rows = list(csv.DictReader(fh))
    out = []
    for r in rows:
        out.append({k: (v if k == "eye" else (float(v) if v != "" else None)) for k, v in r.items()})
    return out


# -- pictures --------------------------------------------------------------------------------------
def _nice(x: float) -> float:
    """The largest of 1, 2, 5 times a power of ten that is at most ``x`` (x > 0)."""
    e = math.floor(math.log10(x))
    for m in (5, 2, 1):
        if m * 10 ** e <= x:
            return m * 10 ** e
    return 10 ** e


def exaggeration(ideal: np.ndarray, actual: np.ndarray) -> float:
    """The factor the distortion picture magnifies departures by: the largest departure drawn as about
    a tenth of the grid's half-diagonal (1, 2 or 5 times a power of ten; 1 where that would shrink it)."""
    half = 0.5 * math.hypot(np.ptp(ideal[0]), np.ptp(ideal[1]))
    dev = np.nanmax(np.hypot(*(actual - ideal))) if np.isfinite(actual).any() else 0.0
    if not dev > 0 or not half > 0:
        return 1.0
    return max(1.0, _nice(0.1 * half / dev))


def distortion_chart(doc: dict) -> tuple[np.ndarray, dict]:
    """optics-distortion.png: the best rectangular grid (grey) and the image of the field grid (dots
    and lines) with its departures magnified by :func:`exaggeration`, in mrad on the plane across the
    centre's line of sight, seen from the design eye point."""
    fields = doc["field_points"]
    nx, ny = doc["target"]["field_grid"]
    arr = lambda key: np.array([np.nan if f[key] is None else f[key] for f in fields], dtype=float)  # noqa: E731
    ideal = np.stack([arr("ideal_x_mrad"), arr("ideal_y_mrad")])
    actual = np.stack([arr("image_x_mrad"), arr("image_y_mrad")])
    k = exaggeration(ideal, actual)
    shown = ideal + k * (actual - ideal)
    s = doc["summary"]["design_eye"]
    fig, canvas = charts.new_figure(7.0, 4.2)
    ax = fig.add_axes((0.11, 0.13, 0.85, 0.72))
    for grid, colour, width, marker in ((ideal, charts.GRID, 1.5, None), (shown, "#1f4e99", 1.2, "o")):
        g = grid.reshape(2, ny, nx)
        for r in range(ny):
            ax.plot(g[0, r], g[1, r], color=colour, linewidth=width, marker=marker, markersize=3)
        for c in range(nx):
            ax.plot(g[0, :, c], g[1, :, c], color=colour, linewidth=width)
    ax.set_aspect("equal", adjustable="datalim")
    charts.style(ax)
    ax.set_xlabel(charts.label("image right (plane across the centre's line of sight)", "mrad"))
    ax.set_ylabel(charts.label("image up", "mrad"))

    def fmt(key, unit):
        v = s.get(key)
        return "n/a" if v is None or not math.isfinite(v) else f"{v:.3g} {unit}"

    ax.set_title(f"{doc['scene']}: distortion from the design eye point, departures drawn x{k:g}\n"
                 f"static {fmt('static_distortion_mrad', 'mrad')}, smile {fmt('smile_mrad', 'mrad')}, rotation "
                 f"{fmt('rotation_mrad', 'mrad')}, trapezoid {fmt('trapezoid_h_percent', '%')} (H)", loc="left")
    rgb = charts.pixels(canvas)
    return rgb, {"box": charts.box(ax), "exaggeration": k}


def _grid(values: list, offsets: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(xs, ys, grid (ny, nx)) of per-point ``values`` at ``offsets`` (k, 2), NaN where absent."""
    xs, ys = np.unique(offsets[:, 0]), np.unique(offsets[:, 1])
    grid = np.full((len(ys), len(xs)), np.nan)
    for v, (x, y) in zip(values, offsets, strict=True):
        grid[np.searchsorted(ys, y), np.searchsorted(xs, x)] = np.nan if v is None else v
    return xs, ys, grid


def _map(fig, rect, xs, ys, grid, title, unit, signed=False, partial=None):
    ax = fig.add_axes(rect)
    step_x = xs[1] - xs[0] if len(xs) > 1 else 10.0
    step_y = ys[1] - ys[0] if len(ys) > 1 else 10.0
    extent = (xs[0] - step_x / 2, xs[-1] + step_x / 2, ys[0] - step_y / 2, ys[-1] + step_y / 2)
    finite = np.isfinite(grid)
    top = float(np.nanmax(np.abs(grid))) if finite.any() else 1.0
    top = top if top > 0 else 1.0
    cmap = charts.colour_map().with_extremes(bad="#444444")
    image = ax.imshow(grid, cmap=cmap, origin="lower", extent=extent, interpolation="nearest", aspect="auto",
                      vmin=-top if signed else 0.0, vmax=top)
    for j, y in enumerate(ys):
        for i, x in enumerate(xs):
            v = grid[j, i]
            if np.isfinite(v):
                star = "*" if partial is not None and partial[j, i] else ""
                ax.text(x, y, f"{v:.2g}{star}", ha="center", va="center", fontsize=charts.FONT_PT - 2,
                        color="white" if (v + top if signed else v) < (1.2 * top if signed else 0.6 * top)
                        else "black")
    ax.plot([0.0], [0.0], "+", color=charts.THRESHOLD, markersize=10, markeredgewidth=2)
    ax.set_title(title, loc="left")
    ax.set_xlabel(charts.label("eye right", "mm"))
    ax.set_ylabel(charts.label("eye up", "mm"))
    bar = fig.colorbar(image, ax=ax, fraction=0.05, pad=0.02)
    bar.set_label(charts.pretty_unit(unit))
    return ax


def eyebox_chart(doc: dict) -> tuple[np.ndarray, dict]:
    """optics-eyebox.png: four maps over the eyebox (the worst field point at each eye point or pair
    midpoint; grey where no chief ray reaches every field point, or no pair fits)."""
    fig, canvas = charts.new_figure(10.0, 7.0)
    eyes = doc.get("eye_points", [])
    pairs = doc.get("pairs", [])
    boxes = {}
    panels = []
    if eyes:
        off = np.array([e["offset_mm"] for e in eyes])
        nf = len(doc["field_points"])
        partial = _grid([e["field_points_seen"] < nf for e in eyes], off)[2] > 0
        panels.append(("dynamic distortion (worst field point)", "mrad", off,
                       [e["dynamic_distortion_max_mrad"] for e in eyes], False, partial))
        panels.append(("ghost separation (worst field point)", "arcmin", off,
                       [e.get("ghost_separation_max_arcmin") for e in eyes], False, partial))
    if pairs:
        poff = np.array([p["midpoint_mm"] for p in pairs])
        panels.append(("convergence (+) / divergence (-) of the pair centred here", "mrad", poff,
                       [p["convergence_max_mrad"] for p in pairs], True, None))
        panels.append(("dipvergence of the pair centred here", "mrad", poff,
                       [p["dipvergence_max_mrad"] for p in pairs], True, None))
    rects = [(0.07, 0.57, 0.36, 0.33), (0.55, 0.57, 0.36, 0.33), (0.07, 0.08, 0.36, 0.33), (0.55, 0.08, 0.36, 0.33)]
    for (title, unit, off, values, signed, partial), rect in zip(panels, rects, strict=False):
        xs, ys, grid = _grid(values, off)
        boxes[title] = charts.box(_map(fig, rect, xs, ys, grid, title, unit, signed, partial))
    if not panels:
        fig.text(0.5, 0.5, "the eyebox was not analysed (hud-trace optics --no-eyebox)", ha="center",
                 fontsize=charts.FONT_PT + 3)
    box = doc["summary"].get("eyebox", {})
    fig.suptitle(f"{doc['scene']}: over the eyebox {doc['target']['eyebox_mm'][0]:g} x "
                 f"{doc['target']['eyebox_mm'][1]:g} mm (IPD {doc['target']['ipd_mm']:g} mm); "
                 f"{box.get('eye_points_seeing_every_field_point', 'no')} eye points see every field point "
                 "(*: the worst of those seen)",
                 x=0.07, ha="left", fontsize=charts.FONT_PT + 1)
    return charts.pixels(canvas), {"panels": boxes}


def vid_chart(doc: dict) -> tuple[np.ndarray, dict]:
    """optics-vid.png: each field point's VID (m, the colour) and astigmatism (D), from the design eye
    point, laid out as the image shows them."""
    fields = doc["field_points"]
    nx, ny = doc["target"]["field_grid"]
    vid = np.array([np.nan if f["vid_mm"] is None else f["vid_mm"] / 1e3 for f in fields]).reshape(ny, nx)
    ast = np.array([np.nan if f["astigmatism_d"] is None else f["astigmatism_d"] for f in fields]).reshape(ny, nx)
    fig, canvas = charts.new_figure(7.0, 3.8)
    ax = fig.add_axes((0.1, 0.15, 0.74, 0.66))
    cax = fig.add_axes((0.87, 0.15, 0.025, 0.66))
    cmap = charts.colour_map().with_extremes(bad="#444444")
    image = ax.imshow(vid, cmap=cmap, interpolation="nearest", aspect="auto",
                      extent=(-0.5, nx - 0.5, ny - 0.5, -0.5))
    lo, hi = (np.nanmin(vid), np.nanmax(vid)) if np.isfinite(vid).any() else (0.0, 1.0)
    for r in range(ny):
        for c in range(nx):
            if np.isfinite(vid[r, c]):
                light = hi > lo and (vid[r, c] - lo) / (hi - lo) > 0.6
                ax.text(c, r, f"{vid[r, c]:.3f} m\n{ast[r, c]:.3f} D", ha="center", va="center",
                        fontsize=charts.FONT_PT - 1, color="black" if light else "white")
    ax.set_xticks(range(nx), [f"{x:+.0%}" for x in np.linspace(-1, 1, nx)])
    ax.set_yticks(range(ny), [f"{y:+.0%}" for y in np.linspace(1, -1, ny)])
    ax.set_xlabel("field point across the image (share of the half-width)")
    ax.set_ylabel("up the image")
    s = doc["summary"]["design_eye"]
    ax.set_title(f"{doc['scene']}: virtual image distance and astigmatism per field point (design eye)\n"
                 f"centre {s['vid_mm'] / 1e3:.3f} m; field curvature {s['field_curvature_d']:.3g} D", loc="left")
    bar = fig.colorbar(image, cax=cax)
    bar.set_label("VID, m")
    return charts.pixels(canvas), {"box": charts.box(ax)}


def output_files(doc: dict) -> list[OutputFile]:
    """optics.json, optics.csv and the three pictures, each with its read-back check."""
    doc = clean(doc)
    text = json.dumps(doc, indent=2, allow_nan=False) + "\n"
    table = csv_text(doc)

    def check_json(p):
        if json.loads(p.read_text()) != json.loads(text):
            raise ValueError("the JSON read back differs from what was written")

    def check_csv(p):
        if p.read_text() != table:
            raise ValueError("the CSV read back differs from what was written")

    return [OutputFile("optics.json", lambda p: p.write_text(text), check_json),
            OutputFile("optics.csv", lambda p: p.write_text(table), check_csv),
            png_file("optics-distortion.png", distortion_chart(doc)[0]),
            png_file("optics-eyebox.png", eyebox_chart(doc)[0]),
            png_file("optics-vid.png", vid_chart(doc)[0])]
