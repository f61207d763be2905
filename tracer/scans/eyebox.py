"""Eyebox of a HUD: where the eye can move and still see the whole display lit.

For eye positions on a grid of offsets in the design eye's right/up plane, the deterministic
brightness-theorem analysis (:func:`tracer.transport.chains.specular_paths`: chief rays through every
specular branch, scattering surfaces lit directly by the emitters) predicts the luminance of the
display, with every LCD cell made clear, at five points of its virtual image: the centre of the
display field and points at :data:`CORNER` (80 %) of its half-extent toward its four corners
(:data:`FIELD_POINTS`). The points are fixed in space at the eye's accommodation distance (or are
fixed directions, for an eye focused at infinity), so an eye that moves looks at the same image
points, as a driver does. The eyebox is where all five stay at or above ``threshold`` (50 %) of
their value at the design eye. The display's own light is counted; the environment is left out.

The luminance of a field point is the brightness theorem's: the luminance of what the chain ends on
times the reflectances and transmittances along it (luminance is conserved along a lossless
specular chain; Potemin, Zhdanov et al., Proc. SPIE 10690, 106900I (2018), doi:10.1117/12.2312589,
and :mod:`tracer.transport.chains`). Only the chief ray from the pupil's centre is followed at each
offset: the eye travels some 100 mm across an eyebox while its pupil spans 2 to 8 mm, and the
pupil average differs from the chief ray only where a source is imaged into part of the pupil.

The analysis' quadrature follows light that reaches scattering surfaces directly from the emitters.
Where a scattering surface is lit through specular optics (hud-screen's rear-projection screen
behind its projection lens, hud-direct-condenser's scatterer behind a condenser), the scan adds a
photon map (:class:`tracer.methods.photon.PhotonMap`, the paper's sec. 4.1 bidirectional method):
``photons`` particles leave the lights once, and every eye offset gathers the same photons at the
points where its chief rays land on the screen. The field is then found where the eye sees the lit
screen, each value has a standard error (``photon_se_cd_m2``), and a map too sparse for a
:data:`MAX_PHOTON_ERROR` relative error at the design eye is reported (``valid`` false, ``reasons``),
as is a scene whose scattering surfaces are lit through optics and no photons are asked for.

Outputs (:func:`output_files`): eyebox.csv (one row per offset), eyebox.png (:func:`eyebox_chart`)
and eyebox.json (:meth:`EyeboxResult.summary`), written as a set (:mod:`tracer.products.outputs`).
"""

from __future__ import annotations

import csv
import dataclasses
import io
import json
import math
from dataclasses import dataclass

import numpy as np

from ..analysis.brightness import PILOT_PHOTONS, SPECULAR_SHARE, lit_through_optics, per_pixel
from ..core.units import luminance3
from ..methods.photon import PhotonMap
from ..products import charts
from ..products.outputs import OutputFile, png_file, write_as_set
from ..products.report import finite_json
from ..scene import Scene
from ..transport.chains import specular_paths
from ..transport.world import World

#: The field points, in the order of the luminance arrays: (name, sign of the right and up offsets).
FIELD_POINTS = (("centre", 0, 0), ("upper left", -1, 1), ("upper right", 1, 1), ("lower left", -1, -1),
                ("lower right", 1, -1))
#: Share of the display's half-extent at which the four outer field points lie.
CORNER = 0.8
#: Most eye offsets a scan may have (a typing slip in a step should not start an hour-long scan).
MAX_OFFSETS = 20_000
#: Particles of the photon map of a scan whose scattering surfaces are lit through specular optics.
DEFAULT_PHOTONS = 1_000_000
#: The most particles a photon map may have (about 5 s per million on hud-screen, 2 cores).
MAX_PHOTONS = 100_000_000
#: The largest relative standard error of the photon map's design-eye values for a valid scan.
MAX_PHOTON_ERROR = 0.1
#: Pixels of the grid on which the field is found on a lit screen (each gathers photons: the whole
#: grid of :func:`specular_paths`, 40,000 pixels, took 15 s of hud-screen's scan).
FIELD_PIXELS = 10_000
#: Where the field is found on a lit screen: the pixels whose luminance is at least this share of
#: the 90th percentile of the lit ones (an edge halfway up the screen image's border).
SCREEN_EDGE = 0.5
#: Files of :func:`output_files`, in the output folder.
OUTPUT_NAMES = ("eyebox.csv", "eyebox.png", "eyebox.json")


class FieldNotFound(ValueError):
    """The display field cannot be found from the scene: the caller must give it."""


class ScanArgumentError(ValueError):
    """An argument of :func:`eyebox_scan` out of its range: ``argument`` names it, ``message`` says why."""

    def __init__(self, argument: str, message: str):
        self.argument, self.message = argument, message
        super().__init__(f"{argument}: {message}")


@dataclass
class Field:
    """The display field as seen from the design eye, in tangent space of the eye's (right, up) axes:
    a direction gaze + a right + b up has coordinates (a, b). ``centre`` (2,), ``half`` (2,) the
    half-extents; ``from_scene`` says whether it was found from the scene or given."""

    centre: np.ndarray
    half: np.ndarray
    from_scene: bool

    @classmethod
    def given(cls, field_deg) -> Field:
        """A field of ``field_deg`` (full width, full height, deg) centred on the gaze."""
        return cls(np.zeros(2), np.tan(np.radians(np.asarray(field_deg, dtype=np.float64)) / 2), False)

    @property
    def deg(self) -> np.ndarray:
        """Full angular extent (deg) of the field, right and up: atan(c + h) - atan(c - h)."""
        return np.degrees(np.arctan(self.centre + self.half) - np.arctan(self.centre - self.half))

    @property
    def centre_deg(self) -> np.ndarray:
        return np.degrees(np.arctan(self.centre))

    def points(self) -> np.ndarray:
        """(5, 2) tangent coordinates of :data:`FIELD_POINTS`."""
        signs = np.array([(a, b) for _, a, b in FIELD_POINTS], dtype=np.float64)
        return self.centre + CORNER * signs * self.half


def clear_lcd(scene: Scene) -> Scene:
    """A copy of ``scene`` with every LCD cell clear (its slide made white); other objects shared. Its hash
    is the scene's marked, so that nothing kept by hash (tracer.core.kept) takes one for the other."""
    def clear(o):
        if o.material.type != "lcd":
            return o
        params = o.material.params | {"image": np.ones_like(o.material.params["image"])}
        return dataclasses.replace(o, material=dataclasses.replace(o.material, params=params))

    return dataclasses.replace(scene, objects=[clear(o) for o in scene.objects],
                               scene_hash=f"{scene.scene_hash}:lcd-clear")


def display_field(world: World, photons=None, survey: dict | None = None) -> Field:
    """The display field from the design eye: the angular extent of the pixels whose chief rays reach
    an LCD cell along the dominant chain through an LCD (:func:`tracer.transport.chains.specular_paths` on
    its pixel grid, or its result ``survey``), each pixel counted with its whole cell of the grid, so
    each edge lies within half a grid cell of the display's. With no LCD in view, the pixels of the
    dominant chain that ends on a scattering surface where it is lit (by the lights directly, or
    through optics where a photon map ``photons``, a :class:`tracer.methods.photon.PhotonMap`, follows
    them): at least :data:`SCREEN_EDGE` of the 90th percentile of its lit pixels (a rear-projection
    screen's image). Raises :class:`FieldNotFound` where neither is found (no LCD in view and no lit
    screen: hud-screen's screen, lit through its projection lens, without photons)."""
    res = survey if survey is not None else specular_paths(world, environment=False, photons=photons)
    px = None
    through_lcd = [p for p in res["paths"] if np.any(np.isfinite(p["lcd"]))]
    if through_lcd:
        px = res["pixels"][np.unique(through_lcd[0]["pixel"])]
    else:
        screens = [p for p in res["paths"] if p["path"].endswith(":scatter") and np.any(p["luminance"] > 0)]
        if screens:
            y = luminance3(screens[0]["luminance"].T)
            lit = y >= SCREEN_EDGE * np.percentile(y[y > 0], 90)
            px = res["pixels"][np.unique(screens[0]["pixel"][lit])]
    if px is None:
        ends = sorted({p["path"].split(" > ")[-1] for p in res["paths"]})
        seen = f" (they end on {', '.join(ends)})" if ends else ""
        raise FieldNotFound("the display field cannot be found from the scene: no chief ray from the eye reaches an "
                            f"LCD cell through the specular optics or a lit scattering surface{seen}; give it "
                            "(field_deg, --field FX FY)")
    eye = world.eye
    sx, sy = eye.pixel_centers()
    half_cell = 0.5 * res["stride"] * np.array([eye.pixel_w, eye.pixel_h]) / eye.focal
    a, b = sx[px % eye.width] / eye.focal, sy[px // eye.width] / eye.focal
    lo = np.array([a.min(), b.min()]) - half_cell
    hi = np.array([a.max(), b.max()]) + half_cell
    return Field(0.5 * (lo + hi), 0.5 * (hi - lo), True)


def offsets_mm(half_mm: float, step_mm: float) -> np.ndarray:
    """Grid offsets (mm): multiples of ``step_mm`` from -``half_mm`` to ``half_mm``, 0 among them."""
    n = math.floor(half_mm / step_mm + 1e-9)
    return step_mm * np.arange(-n, n + 1, dtype=np.float64)


def _component(mask: np.ndarray, seed: tuple[int, int]) -> np.ndarray:
    """The 4-connected component of boolean ``mask`` (ny, nx) containing ``seed`` (row, column)."""
    region = np.zeros_like(mask)
    if not mask[seed]:
        return region
    region[seed] = True
    while True:
        grown = region.copy()
        grown[1:] |= region[:-1]
        grown[:-1] |= region[1:]
        grown[:, 1:] |= region[:, :-1]
        grown[:, :-1] |= region[:, 1:]
        grown &= mask
        if np.array_equal(grown, region):
            return region
        region = grown


def _edges(x: np.ndarray, ratio: np.ndarray, region: np.ndarray, threshold: float) -> tuple[float, float, bool]:
    """(low edge, high edge, reaches the scan's end) of ``region`` along the last axis of the grid:
    over the region's lines, the outermost crossing of ``threshold`` by ``ratio``, interpolated
    linearly between the region's outermost point of each line and its neighbour outside."""
    lows, highs, clipped = [], [], False
    for line_r, line_q in zip(region, ratio, strict=True):
        idx = np.flatnonzero(line_r)
        if len(idx) == 0:
            continue
        for i, out, store in ((idx[0], idx[0] - 1, lows), (idx[-1], idx[-1] + 1, highs)):
            if not 0 <= out < len(x):
                clipped = True
                store.append(x[i])
                continue
            q_in, q_out = line_q[i], line_q[out]  # q_in >= threshold > q_out: out is not in the region
            store.append(x[i] + (q_in - threshold) / (q_in - q_out) * (x[out] - x[i]))
    return float(min(lows)), float(max(highs)), clipped


@dataclass
class EyeboxResult:
    """An eyebox scan (:func:`eyebox_scan`). Arrays are indexed [up, right(, field point)].

    right_mm (nx,), up_mm (ny,): eye offsets from the design eye along its right and up axes, mm;
    step_mm: the grid's step, mm.
    field: the display field (:class:`Field`); field_points (5, 2) its points' tangent coordinates.
    luminance_cd_m2 (ny, nx, 5): predicted luminance of each field point (clear LCD), cd/m^2.
    through_specular_cd_m2 (ny, nx, 5): luminance that the scattering surfaces' light through specular
    optics (not followed) would add were those optics clear, cd/m^2 (:mod:`tracer.transport.chains`).
    design_cd_m2 (5,): the field points at the design eye (offset 0, 0), cd/m^2.
    inside (ny, nx): every field point at or above ``threshold`` x its design value.
    region (ny, nx): the eyebox: the 4-connected part of ``inside`` that holds the design eye.
    coarse_cd_m2 (ny, nx, 5): the part of ``luminance_cd_m2`` from lights closer to the scattering
    surfaces than the analysis' quadrature resolves (a backlight right behind a screen), cd/m^2.
    valid, reasons: whether the analysis can predict this scene, and why not.
    photon_se_cd_m2 (ny, nx, 5): the standard error of each luminance where a photon map lit a
    scattering surface (Y cd/m^2; the sum of its chains' errors, an upper bound), else None;
    photon_map: the map's figures (:meth:`tracer.methods.photon.PhotonMap.summary`), else None.
    figures: :meth:`figures` (None when not valid).
    """

    scene: str
    right_mm: np.ndarray
    up_mm: np.ndarray
    step_mm: float
    field: Field
    threshold: float
    luminance_cd_m2: np.ndarray
    through_specular_cd_m2: np.ndarray
    design_cd_m2: np.ndarray
    valid: bool
    reasons: list[str]
    specular_blockers: dict[str, list[str]]
    coarse_cd_m2: np.ndarray | None = None
    photon_se_cd_m2: np.ndarray | None = None
    photon_map: dict | None = None

    @property
    def field_points(self) -> np.ndarray:
        return self.field.points()

    @property
    def design_index(self) -> tuple[int, int]:
        """(row, column) of the design eye in the grid."""
        return int(np.argmin(np.abs(self.up_mm))), int(np.argmin(np.abs(self.right_mm)))

    @property
    def relative(self) -> np.ndarray:
        """(ny, nx): the least, over the field points, of luminance over its design value; NaN where a
        design value is 0 (nothing to compare with)."""
        d = self.design_cd_m2
        if np.any(d <= 0):
            return np.full(self.luminance_cd_m2.shape[:2], np.nan)
        return (self.luminance_cd_m2 / d).min(axis=2)

    @property
    def inside(self) -> np.ndarray:
        """(ny, nx): every field point at or above the threshold times its design value (none when not valid)."""
        rel = self.relative
        return (rel >= self.threshold) if self.valid else np.zeros(rel.shape, bool)

    @property
    def region(self) -> np.ndarray:
        return _component(self.inside, self.design_index)

    def figures(self) -> dict | None:
        """What an optical engineer reads off an eyebox; None when the result is not valid.

        - ``width_mm``, ``height_mm``: the extent of the eyebox (:attr:`region`) along the eye's right
          and up axes, between its outermost edges; each edge is where the least relative luminance
          (:attr:`relative`) crosses the threshold, interpolated linearly between the region's
          outermost grid point on a grid line and its neighbour outside (within half a step of the
          true edge where the luminance falls like a step, closer where it falls smoothly);
          ``edges_mm`` {left, right, bottom, top}; ``reaches_scan_edge``: the region touches the
          scan's border, so the eyebox may be larger (widen the scan).
        - ``grid_width_mm``, ``grid_height_mm``: the span between the region's outermost grid points
          (a lower bound of the extent).
        - ``field_average_cd_m2``: the mean of the five field points' luminance, its minimum and
          maximum over the eyebox with the offsets (mm, right and up) where they occur.
        - ``uniformity``: ``design_eye`` = min / max of the five field points' luminance at the design
          eye; ``eyebox`` = min / max of all field points' luminance over every offset of the eyebox
          (the whole display, wherever the eye is in the eyebox), with ``eyebox_min_at`` (offset,
          field point) of that minimum.
        """
        if not self.valid:
            return None
        region = self.region
        rel = self.relative
        x, z = self.right_mm, self.up_mm
        left, right, clip_x = _edges(x, rel, region, self.threshold)
        bottom, top, clip_z = _edges(z, rel.T, region.T, self.threshold)
        rows, cols = np.nonzero(region)
        lum = self.luminance_cd_m2
        avg = lum.mean(axis=2)
        inner = np.where(region, avg, np.nan)
        k_min, k_max = np.nanargmin(inner), np.nanargmax(inner)

        def at(k):  # a flat index of the grid -> its offset [right, up], mm
            return [float(x[k % len(x)]), float(z[k // len(x)])]

        per_point = np.where(region[..., None], lum, np.nan)
        m_min = int(np.nanargmin(per_point))
        cell, point = divmod(m_min, len(FIELD_POINTS))
        d = self.design_cd_m2
        return {
            "width_mm": right - left, "height_mm": top - bottom,
            "edges_mm": {"left": left, "right": right, "bottom": bottom, "top": top},
            "reaches_scan_edge": bool(clip_x or clip_z),
            "grid_width_mm": float(x[cols.max()] - x[cols.min()]),
            "grid_height_mm": float(z[rows.max()] - z[rows.min()]),
            "offsets_in_eyebox": int(region.sum()),
            "field_average_cd_m2": {"design_eye": float(d.mean()),
                                    "min": float(inner.flat[k_min]), "min_at_mm": at(k_min),
                                    "max": float(inner.flat[k_max]), "max_at_mm": at(k_max)},
            "uniformity": {"design_eye": float(d.min() / d.max()),
                           "eyebox": float(np.nanmin(per_point) / np.nanmax(per_point)),
                           "eyebox_min_at": {"offset_mm": at(cell), "field_point": FIELD_POINTS[point][0]}},
        }

    def summary(self) -> dict:
        """The figures with everything needed to read them (eyebox.json)."""
        f = self.field
        return {
            "scene": self.scene,
            "method": "brightness-theorem analysis (tracer.transport.chains): the chief ray from each eye offset to "
                      "each field point through every specular branch, every LCD cell clear, the environment left out"
                      + ("; the light that reaches scattering surfaces through other surfaces from a photon map "
                         "(tracer.methods.photon.PhotonMap) shared by every offset" if self.photon_map else ""),
            "valid": self.valid, "reasons": self.reasons, "specular_blockers": self.specular_blockers,
            "photon_map": None if self.photon_map is None else self.photon_map | {
                "design_standard_error_cd_m2": self.photon_se_cd_m2[self.design_index].tolist()},
            "threshold": self.threshold,
            "field": {"from_scene": f.from_scene, "deg": f.deg.tolist(), "centre_deg": f.centre_deg.tolist(),
                      "corner_share": CORNER,
                      "points": [{"name": n, "tangent": p.tolist(), "design_cd_m2": float(v)}
                                 for (n, _, _), p, v in zip(FIELD_POINTS, self.field_points, self.design_cd_m2,
                                                            strict=True)]},
            "grid": {"right_mm": [float(self.right_mm[0]), float(self.right_mm[-1])],
                     "up_mm": [float(self.up_mm[0]), float(self.up_mm[-1])],
                     "step_mm": self.step_mm,
                     "offsets": int(self.right_mm.size * self.up_mm.size)},
            "figures": self.figures(),
        }


def check_scan(half_mm, step_mm, field_deg, threshold, photons: int = DEFAULT_PHOTONS, seed: int = 0):
    """Raise :class:`ScanArgumentError` naming the argument (half_mm, step_mm, field_deg, threshold,
    photons, seed) that is out of its range."""
    if isinstance(photons, bool) or not isinstance(photons, int | np.integer) or not 0 <= photons <= MAX_PHOTONS:
        raise ScanArgumentError("photons", f"a whole number of particles in [0, {MAX_PHOTONS:,}], got {photons!r}")
    if isinstance(seed, bool) or not isinstance(seed, int | np.integer) or not 0 <= seed < 2**63:
        raise ScanArgumentError("seed", f"must be a whole number in [0, 2^63), got {seed!r}")
    half = np.asarray(half_mm, dtype=np.float64)
    if half.shape != (2,) or not np.all(np.isfinite(half)) or np.any(half < 0) or np.any(half > 1000):
        raise ScanArgumentError("half_mm", f"two half-widths in [0, 1000] mm, got {half_mm}")
    if not (math.isfinite(step_mm) and 0 < step_mm <= 1000):
        raise ScanArgumentError("step_mm", f"must be a finite step in (0, 1000] mm, got {step_mm}")
    n = math.prod(2 * math.floor(h / step_mm + 1e-9) + 1 for h in half)
    if n == 1:  # the design eye alone: an eyebox of 0 x 0 mm, whatever the optics
        if not np.any(half > 0):
            raise ScanArgumentError("half_mm", "both half-widths are 0: the scan would hold the design eye alone")
        raise ScanArgumentError("step_mm", f"{step_mm:g} mm is longer than both half-widths (+-{half[0]:g} x "
                                           f"+-{half[1]:g} mm): the scan would hold the design eye alone")
    if n > MAX_OFFSETS:
        raise ScanArgumentError("step_mm", f"{step_mm:g} mm over +-{half[0]:g} x +-{half[1]:g} mm makes {n} eye "
                                           f"offsets, more than {MAX_OFFSETS}")
    if field_deg is not None:
        f = np.asarray(field_deg, dtype=np.float64)
        if f.shape != (2,) or not np.all(np.isfinite(f)) or np.any(f <= 0) or np.any(f >= 180):
            raise ScanArgumentError("field_deg", f"two angles in (0, 180) deg, got {field_deg}")
    if not (math.isfinite(threshold) and 0 < threshold <= 1):
        raise ScanArgumentError("threshold", f"must lie in (0, 1], got {threshold}")


def eyebox_scan(world: World, half_mm=(60.0, 30.0), step_mm: float = 5.0, field_deg=None, threshold: float = 0.5,
                progress=None, photons: int = DEFAULT_PHOTONS, seed: int = 0) -> EyeboxResult:
    """Scan the eyebox of ``world``'s scene (see the module docstring).

    half_mm: (right, up) half-widths of the grid of eye offsets, mm; step_mm: its step, mm (the
    offsets are multiples of it, the design eye among them). field_deg: (full width, full height)
    of the display field, deg, centred on the gaze; None finds it from the scene
    (:func:`display_field`; :class:`FieldNotFound` where it cannot be found). threshold: the share
    of the design-eye luminance every field point must keep inside the eyebox. ``progress``
    (fraction, message), if given, is called after every row of the grid (and while the photon map
    is built). ``photons``: particles of the photon map, built (on the random stream ``seed``) only
    where a scattering surface in view is lit through specular optics; 0 leaves that light out and
    the scan not valid.

    The scan runs on a world of its own, the scene with every LCD cell clear (:func:`clear_lcd`);
    the given world is used for its scene only. Raises :class:`ScanArgumentError` naming an argument
    out of its range before tracing anything.
    """
    check_scan(half_mm, step_mm, field_deg, threshold, photons, seed)
    scene = world.scene
    if any(o.material.type == "lcd" for o in scene.objects):
        world = World(clear_lcd(scene))
    eye = world.eye
    survey = specular_paths(world, environment=False)
    pmap = None
    if photons > 0 and lit_through_optics(world, survey, seed, min(photons, PILOT_PHOTONS)):
        share = 0.5  # of the progress: the photon map, then the grid

        def built(fraction):
            if progress is not None:
                progress(share * fraction, f"eyebox: photon map, {int(fraction * photons)} of {photons} photons")

        pmap = PhotonMap(world, photons, seed, progress=built)
        if field_deg is None:  # the field from the lit screen, on a grid of at most FIELD_PIXELS (each a gather)
            stride = max(1, math.ceil(math.sqrt(eye.width * eye.height / FIELD_PIXELS)))
            survey = specular_paths(world, stride=stride, environment=False, photons=pmap)
    else:
        share = 0.0
    fld = display_field(world, pmap, survey) if field_deg is None else Field.given(field_deg)
    tangents = fld.points()
    directions = eye.gaze + tangents[:, :1] * eye.right + tangents[:, 1:] * eye.up  # (5, 3)
    dist = eye.accommodation
    points = eye.position + dist * directions if math.isfinite(dist) else None
    xs, zs = offsets_mm(half_mm[0], step_mm), offsets_mm(half_mm[1], step_mm)
    n = len(FIELD_POINTS)
    lum = np.zeros((len(zs), len(xs), n))
    through = np.zeros_like(lum)
    coarse = np.zeros_like(lum)
    error = np.zeros_like(lum)
    blockers: dict[str, set] = {}
    for j, z in enumerate(zs):
        for i, x in enumerate(xs):
            # The moved eye's rays are given directions: it needs no retina (1 x 1 spares the pixel table).
            moved = dataclasses.replace(eye.spec, position=eye.position + x * eye.right + z * eye.up, resolution=(1, 1))
            d = points - moved.position if points is not None else directions
            res = specular_paths(world.with_eye(moved), directions=d, environment=False, photons=pmap)
            lum[j, i], _, through[j, i], coarse[j, i] = per_pixel(res["paths"], n)
            for path in res["paths"]:
                np.add.at(error[j, i], path["pixel"], path["photon_se"])
            for k, v in res["specular_blockers"].items():
                blockers.setdefault(k, set()).update(v)
        if progress is not None:
            progress(share + (1 - share) * (j + 1) / len(zs),
                     f"eyebox: {(j + 1) * len(xs)} of {len(zs) * len(xs)} eye offsets")
    design = lum[int(np.argmin(np.abs(zs))), int(np.argmin(np.abs(xs)))].copy()
    result = EyeboxResult(scene.name, xs, zs, float(step_mm), fld, float(threshold), lum, through, design, True, [],
                          {k: sorted(v) for k, v in sorted(blockers.items())}, coarse,
                          error if pmap is not None else None, pmap.summary() if pmap is not None else None)
    result.reasons = _reasons(result)
    result.valid = not result.reasons
    return result


def _reasons(r: EyeboxResult) -> list[str]:
    """Why the analysis cannot predict ``r``'s scene (empty when it can)."""
    reasons = []
    lum, through = r.luminance_cd_m2, r.through_specular_cd_m2
    unfollowed = through > SPECULAR_SHARE * (lum + through)
    if unfollowed.any():
        lit = ", ".join(f"{s} (through {', '.join(b)})" for s, b in r.specular_blockers.items())
        j, i = r.design_index
        reasons.append(f"scattering surfaces are lit through specular optics the analysis does not follow: {lit}; at "
                       f"{int(unfollowed.any(axis=2).sum())} of {unfollowed.shape[0] * unfollowed.shape[1]} eye "
                       f"offsets; at the design eye direct light would add {through[j, i].max():.4g} cd/m^2 to the "
                       f"{lum[j, i][np.argmax(through[j, i])]:.4g} predicted (--photons above 0 follows it with a "
                       "photon map)")
    if r.photon_se_cd_m2 is not None:
        j, i = r.design_index
        d, se = r.design_cd_m2, r.photon_se_cd_m2[j, i]
        rel = np.divide(se, d, out=np.full(d.shape, np.inf), where=d > 0)
        if np.any((rel > MAX_PHOTON_ERROR) & (d > 0)):
            k = int(np.argmax(np.where(d > 0, rel, 0)))
            reasons.append(f"the photon map is too sparse: the design eye's {FIELD_POINTS[k][0]} field point reads "
                           f"{d[k]:.4g} +- {se[k]:.2g} cd/m^2 ({100 * rel[k]:.0f} %, more than "
                           f"{100 * MAX_PHOTON_ERROR:g} %); give more photons (--photons)")
    if r.coarse_cd_m2 is not None:
        rough = r.coarse_cd_m2 > SPECULAR_SHARE * lum
        if rough.any():
            reasons.append(f"lights lie closer to the scattering surfaces than the analysis' quadrature resolves (a "
                           f"backlight right behind a screen), at {int(rough.any(axis=2).sum())} of "
                           f"{rough.shape[0] * rough.shape[1]} eye offsets: the predicted luminances are not reliable")
    dark = [name for (name, _, _), v in zip(FIELD_POINTS, r.design_cd_m2, strict=True) if v <= 0]
    if dark and not reasons:  # (dark because of the optics not followed, the reason above says)
        reasons.append(f"the analysis predicts no light at the design eye for the field point(s) {', '.join(dark)}: "
                       "the field is larger than the display, or the display is lit in a way the analysis does not "
                       "follow")
    return reasons


# -- outputs ------------------------------------------------------------------------------------------
def csv_text(result: EyeboxResult) -> str:
    """eyebox.csv: a header, then one row per eye offset (rows of the grid from the bottom, offsets
    right within a row): right_mm, up_mm, each field point's luminance (cd/m^2), inside (1 where
    every field point is at or above the threshold times its design value, else 0). Numbers are
    written in their shortest form that reads back exactly."""
    names = [f"{n.replace(' ', '_')}_cd_m2" for n, _, _ in FIELD_POINTS]
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(["right_mm", "up_mm", *names, "inside"])
    inside = result.inside
    for j, z in enumerate(result.up_mm):
        for i, x in enumerate(result.right_mm):
            w.writerow([repr(float(x)), repr(float(z)), *(repr(float(v)) for v in result.luminance_cd_m2[j, i]),
                        int(inside[j, i])])
    return buf.getvalue()


def read_csv(path) -> dict:
    """eyebox.csv read back: {"right_mm" (nx,), "up_mm" (ny,), "luminance_cd_m2" (ny, nx, 5),
    "inside" (ny, nx) bool}."""
    with open(path, newline="") as fh:
        rows = list(csv.reader(fh))
    head, body = rows[0], np.array(rows[1:], dtype=np.float64)
    if len(head) != 3 + len(FIELD_POINTS) or head[:2] != ["right_mm", "up_mm"] or head[-1] != "inside":
        raise ValueError(f"{path}: not an eyebox.csv (header {head})")
    xs, zs = np.unique(body[:, 0]), np.unique(body[:, 1])
    shape = (len(zs), len(xs))
    return {"right_mm": xs, "up_mm": zs, "luminance_cd_m2": body[:, 2:-1].reshape(*shape, len(FIELD_POINTS)),
            "inside": body[:, -1].reshape(shape).astype(bool)}


def _csv_file(result: EyeboxResult, name: str = "eyebox.csv") -> OutputFile:
    text = csv_text(result)

    def check(p):
        back = read_csv(p)
        if not np.array_equal(back["luminance_cd_m2"], result.luminance_cd_m2):
            raise ValueError("the luminances read back differ from those written")

    def write(p):
        with open(p, "w", newline="") as fh:
            fh.write(text)

    return OutputFile(name, write, check)


def write_csv(result: EyeboxResult, path) -> None:
    """Write :func:`csv_text` to ``path`` as a set (:func:`tracer.products.falsecolour.write_as_set`)."""
    f = _csv_file(result)
    write_as_set(path, f.write, f.check)


def _caption(result: EyeboxResult) -> str:
    fig = result.figures()
    if fig is not None:
        return (f"eyebox {fig['width_mm']:.0f} x {fig['height_mm']:.0f} mm: every field point >= "
                f"{100 * result.threshold:.3g} % of design")
    if result.reasons[0].startswith("scattering"):
        return "not valid: the display is lit through optics the analysis does not follow"
    return "not valid: no light at the design eye"


def eyebox_chart(result: EyeboxResult) -> tuple[np.ndarray, dict]:
    """eyebox.png (:func:`tracer.products.charts.eyebox_chart`): the least relative luminance of the field
    points over the grid of eye offsets, the eyebox outlined, the design eye marked, the threshold among
    the colour bar's ticks, the eyebox's size (or why there is none) in the title."""
    return charts.eyebox_chart(result.relative, result.region, result.right_mm, result.up_mm, result.threshold,
                               _caption(result))


def output_files(result: EyeboxResult) -> list[OutputFile]:
    """eyebox.csv, eyebox.png and eyebox.json, each with its read-back check (:mod:`tracer.products.outputs`)."""
    summary = result.summary()
    text = finite_json(summary, "eyebox.json")

    def check_json(p):
        if json.loads(p.read_text()) != json.loads(text):
            raise ValueError("the JSON read back differs from what was written")

    return [_csv_file(result), png_file("eyebox.png", eyebox_chart(result)[0]),
            OutputFile("eyebox.json", lambda p: p.write_text(text), check_json)]
