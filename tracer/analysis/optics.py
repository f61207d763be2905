"""HUD optical analysis: where the image is and how good it is (virtual image distance, look-down and
look-over angles, field of view, magnification, pixel size, static and dynamic distortion, binocular
convergence and dipvergence, ghost separation, astigmatism, field curvature, focus variation, spot
size and PGU usage), as a HUD design review asks for them: the metrics of Ansys Speos' HUD Optical
Analysis, with the definitions and closed forms of ../shared/reference/hud-optical-metrics.md (its
binocular limits from L. Gu et al., Appl. Opt. 59(16), 4893 (2020), doi:10.1364/AO.389870, and K.
Moffitt, "Comprehensive guidelines for binocular display alignment", 2003). Each metric's definition
is in :data:`DEFINITIONS`, and optics.json carries it.

The analysis is deterministic. The brightness-theorem analysis (:func:`tracer.transport.chains.specular_paths`)
names the specular chains from the design eye point: the brightest that reaches the PGU is the primary
image, the next one that reaches the same PGU by another way (the windshield's second surface) the
ghost. The PGU is the first LCD on the primary chain, else the surface it ends on (a diffuse screen, an
emitter), or the scene's ``target.pgu``. On a grid of PGU field points and of eye points across the
eyebox, chief rays are solved onto the field points through each chain and thin bundles traced
around them (:mod:`.imaging`), through the same optics the renders trace (exact surfaces included).

Eye points: the design eye point (DEP) is the scene's eye position; the eyebox (``target.eyebox_mm``)
is centred on it, across the vehicle's forward direction; binocular pairs are the eye points whose two
eyes, IPD / 2 to either side, both lie in the eyebox.
"""

from __future__ import annotations

import copy
import math
import time
from dataclasses import dataclass

import numpy as np

from ..core.errors import SceneError
from ..core.kept import KeptResults
from ..optics.materials import LCD
from ..scene.binocular import vehicle_axes
from ..scene.format import TARGET
from ..transport.chains import specular_paths
from ..transport.sequential import Chain, Plane, chain_from_events
from .imaging import Imaging, VehicleFrame

MRAD, ARCMIN = 1e3, 180 * 60 / math.pi

#: Every metric of optics.json: (unit, definition).
DEFINITIONS = {
    "vid_mm": ("mm", "Virtual image distance: 1 / the mean of the thin bundle's vergences in its horizontal and "
                     "vertical sections, from the eye point"),
    "vergence_d": ("D", "The thin bundle's mean vergence, 1 / VID in dioptres (1/m)"),
    "vid_tangential_mm": ("mm", "1 / vergence of the bundle's vertical section (the plane of a HUD's folds)"),
    "vid_sagittal_mm": ("mm", "1 / vergence of the bundle's horizontal section"),
    "astigmatism_d": ("D", "|difference of the principal vergences| of the thin bundle (the eye notices 0.25 D)"),
    "field_curvature_d": ("D", "Spread (max - min) of the vergence over the field points, at the design eye point"),
    "field_curvature_mm": ("mm", "Spread (max - min) of the VID over the field points, at the design eye point"),
    "focus_variation_d": ("D", "Largest spread (max - min) of a field point's vergence across the eyebox"),
    "look_down_deg": ("deg", "Elevation of the PGU centre's image below the horizontal through the eye point"),
    "look_over_deg": ("deg", "Azimuth of the PGU centre's image to the right of the forward direction"),
    "fov_h_deg": ("deg", "Horizontal angle between the images of the middle row's end field points"),
    "fov_v_deg": ("deg", "Vertical angle between the images of the middle column's end field points"),
    "magnification_h": ("1", "Horizontal image size at the centre's VID over the PGU's size (tangent of half the "
                             "FOV times twice the VID, over the PGU width)"),
    "magnification_v": ("1", "The same vertically"),
    "pixel_size_arcmin": ("arcmin", "Angle one PGU pixel subtends in the image at the centre (the eye resolves "
                                    "about 1 arcmin); PGU pixels from the LCD's image"),
    "static_distortion_mrad": ("mrad", "Largest distance of a field point's image (image_x, image_y) from the best "
                                       "rectangular grid (least squares centre and H and V scales), at the design "
                                       "eye point"),
    "static_distortion_percent": ("%", "The same as % of the ideal grid's half-diagonal"),
    "rotation_mrad": ("mrad", "Tilt of the line through the images of the left and right edges' middles, positive "
                              "counter-clockwise"),
    "smile_mrad": ("mrad", "Largest bow of a row: its middle image's elevation minus the mean of its two ends'"),
    "trapezoid_h_percent": ("%", "(top row width - bottom row width) / their mean"),
    "trapezoid_v_percent": ("%", "(left column height - right column height) / their mean"),
    "dynamic_distortion_mrad": ("mrad", "Largest change of a field point's image direction from the design eye "
                                        "point to an eye point, after the change the eye's move gives a point at "
                                        "the target distance (exactly, for the design eye point's image direction)"),
    "convergence_mrad": ("mrad", "Horizontal disparity of a binocular pair: the angle between its two lines of "
                                 "sight in the horizontal minus that toward a point at the target distance along "
                                 "the pair's middle line of sight (positive: converge, nearer than the target; "
                                 "negative: diverge)"),
    "divergence_mrad": ("mrad", "The largest negative convergence over the pairs and field points, as a positive "
                                "number"),
    "dipvergence_mrad": ("mrad", "Vertical disparity: the left eye's elevation minus the right eye's, in Helmholtz "
                                 "angles (elevation atan2(d.up, d.forward) about the interocular axis: a real point "
                                 "gives 0); the summary, the largest magnitude"),
    "vergence_angle_mrad": ("mrad", "The left eye's Helmholtz azimuth asin(d.right) minus the right eye's "
                                    "(2 atan(IPD / 2D) for a point at distance D straight ahead)"),
    "image_x_mrad": ("mrad", "A field point's image on the plane across the centre's line of sight (gnomonic: the "
                             "tangent of its angle from the centre, to the right); distortion is measured there"),
    "image_y_mrad": ("mrad", "The same, upward"),
    "ghost_separation_arcmin": ("arcmin", "Angle between the primary and the ghost image of the same field point "
                                          "from the same eye point"),
    "ghost_offset_h_arcmin": ("arcmin", "Ghost azimuth minus primary azimuth (signed)"),
    "ghost_offset_v_arcmin": ("arcmin", "Ghost elevation minus primary elevation (signed)"),
    "ghost_ratio": ("1", "The ghost chain's luminance factor over the primary's at the centre: the Fresnel R and T "
                         "and the mirrors' reflectances, s and p light followed apart as the renders follow them "
                         "(tracer.optics.polar), with the PGU's own polarisation"),
    "ghost_separation_centre_arcmin": ("arcmin", "The ghost separation of the PGU's centre"),
    "vid_min_mm": ("mm", "The nearest field point's VID (over the eyebox: of any field point from any eye point)"),
    "vid_max_mm": ("mm", "The furthest field point's VID"),
    "astigmatism_centre_d": ("D", "The astigmatism of the PGU centre's bundle"),
    "field_points_seen": ("1", "Field points whose chief ray converges onto the PGU unblocked (of those of the grid)"),
    "eye_points_seeing_every_field_point": ("1", "Eye points from which every field point is seen (of the grid's)"),
    "binocular_pairs": ("1", "Binocular pairs whose two eyes both lie in the eyebox"),
    "pgu_mm": ("mm", "A field point on the PGU's plane, along its x and y"),
    "azimuth_deg": ("deg", "A chief ray's azimuth, positive to the right of forward"),
    "elevation_deg": ("deg", "A chief ray's elevation, positive up"),
    "distortion_mrad": ("mrad", "A field point's distance from its place on the best rectangular grid"),
    "distortion_h_mrad": ("mrad", "Its horizontal part (image minus ideal, to the right)"),
    "distortion_v_mrad": ("mrad", "Its vertical part (up)"),
    "ideal_x_mrad": ("mrad", "The field point's place on the best rectangular grid, to the right"),
    "ideal_y_mrad": ("mrad", "The same, upward"),
    "offset_mm": ("mm", "An eye point's offset from the design eye point [right, up]"),
    "midpoint_mm": ("mm", "A binocular pair's midpoint offset from the design eye point [right, up]"),
    "dynamic_distortion_max_mrad": ("mrad", "An eye point's largest dynamic distortion over the field points"),
    "ghost_separation_max_arcmin": ("arcmin", "An eye point's largest ghost separation over the field points"),
    "convergence_max_mrad": ("mrad", "A pair's convergence of largest magnitude over the field points (signed)"),
    "dipvergence_max_mrad": ("mrad", "A pair's dipvergence of largest magnitude over the field points (signed)"),
    "row": ("1", "A field point's row, from the image's top"),
    "column": ("1", "A field point's column, from the image's left"),
    "spot_rms_arcmin": ("arcmin", "RMS radius of the spot of rays over the whole pupil, each solved onto the field "
                                  "point, for an eye focused at the bundle's VID"),
    "pgu_usage": ("1", "Share of the PGU's active area whose image from the design eye point lies inside the "
                       "target field of view"),
    "vid_minus_target_mm": ("mm", "VID minus the target distance (where the target gives it)"),
    "look_down_minus_target_deg": ("deg", "Look-down angle minus the target's"),
    "look_over_minus_target_deg": ("deg", "Look-over angle minus the target's"),
    "fov_h_minus_target_deg": ("deg", "Horizontal field of view minus the target's"),
    "fov_v_minus_target_deg": ("deg", "Vertical field of view minus the target's"),
}

#: The summary metrics judged against requirements and given to report.json and sweeps.
DESIGN_KEYS = ("vid_mm", "vergence_d", "vid_min_mm", "vid_max_mm", "astigmatism_d", "field_curvature_d",
               "field_curvature_mm", "look_down_deg", "look_over_deg", "fov_h_deg", "fov_v_deg", "magnification_h",
               "magnification_v", "pixel_size_arcmin", "static_distortion_mrad", "static_distortion_percent",
               "rotation_mrad", "smile_mrad", "trapezoid_h_percent", "trapezoid_v_percent", "ghost_separation_arcmin",
               "ghost_separation_centre_arcmin", "ghost_offset_v_arcmin", "ghost_offset_h_arcmin", "ghost_ratio",
               "spot_rms_arcmin", "pgu_usage")


class OpticsError(ValueError):
    """The analysis cannot run on this scene (no chain reaches a PGU, the PGU is not planar...)."""


@dataclass
class PGU:
    """The PGU: its object, plane, half sizes (mm, along the plane's x and y) and pixels (or None)."""

    name: str
    plane: Plane
    half: np.ndarray
    pixels: tuple[int, int] | None


def pgu_of(world, name: str) -> PGU:
    """The PGU object ``name`` as a plane: its vertices' best-fit plane, x along the object's local x."""
    obj = world.scene.object(name)
    v = obj.vertices
    c0 = v.mean(axis=0)
    _, sv, vt = np.linalg.svd(v - c0, full_matrices=False)
    if sv[-1] > 1e-3 * sv[0]:
        raise OpticsError(f"the PGU {name} is not planar (its vertices lie {sv[-1] / math.sqrt(len(v)):.3g} mm "
                          "from their best plane, rms); the analysis images a flat PGU")
    normal = vt[2]
    x = obj.local_x - (obj.local_x @ normal) * normal
    if np.linalg.norm(x) < 1e-6:
        x = vt[0]
    x /= np.linalg.norm(x)
    y = np.cross(normal, x)
    q = np.stack([(v - c0) @ x, (v - c0) @ y])
    lo, hi = q.min(axis=1), q.max(axis=1)
    centre = c0 + 0.5 * (lo[0] + hi[0]) * x + 0.5 * (lo[1] + hi[1]) * y
    pixels = None
    mat = world.materials[world.slot_material[obj.slot]]
    if isinstance(mat, LCD):
        img = obj.material.params.get("image")
        if img is not None:
            pixels = (int(img.shape[1]), int(img.shape[0]))
    return PGU(name, Plane(centre, normal, x, y), 0.5 * (hi - lo), pixels)


@dataclass
class Chains:
    """The chains the analysis images: ``primary`` and ``ghost`` (or None), and the PGU's name."""

    primary: Chain
    ghost: Chain | None
    pgu: str


def _events(world, labels: list[str], pgu: str | None) -> tuple[list[str], str] | None:
    """(the events before the PGU, the PGU's name) of a chain's labels, or None where it reaches none."""
    by_name = {o.name: o for o in world.scene.objects}
    for k, lab in enumerate(labels):
        name, _, lobe = lab.rpartition(":") if ":" in lab else (lab, "", "")
        obj = by_name.get(name)
        if obj is None:
            return None
        if pgu is not None:
            if name == pgu:
                return labels[:k], name
            continue
        mat = world.materials[world.slot_material[obj.slot]]
        if isinstance(mat, LCD) or lobe in ("scatter", ""):
            return labels[:k], name
    return None


def find_chains(world, pgu: str | None = None, rays: int = 3000) -> Chains:
    """The primary and ghost chains from the eye to the PGU (see the module docstring), from chief rays
    of about ``rays`` retina pixels."""
    eye = world.eye
    stride = max(1, math.ceil(math.sqrt(eye.width * eye.height / rays)))
    res = specular_paths(world, stride=stride, environment=False, max_depth=16)
    groups: dict[tuple, float] = {}
    for p in res["paths"]:
        ev = _events(world, p["path"].split(" > "), pgu)
        if ev is None:
            continue
        key = (tuple(ev[0]), ev[1])
        groups[key] = groups.get(key, 0.0) + float(np.sum(p["factor"]))
    if not groups:
        where = f"the PGU {pgu} (target.pgu)" if pgu else "an LCD, a scattering surface or an emitter"
        seen = sorted(((len(p["pixel"]), p["path"]) for p in res["paths"]), reverse=True)[:3]
        total = sum(len(p["pixel"]) for p in res["paths"]) or 1
        what = "; ".join(f"{path} ({100 * k / total:.0f} %)" for k, path in seen) or \
            "nothing: every chief ray leaves the scene"
        raise OpticsError(f"no specular chain from the eye reaches {where}: aim the eye (the camera) at the "
                          f"display's image; its view of {eye.spec.fov_deg[0]:g} x {eye.spec.fov_deg[1]:g} deg "
                          f"sees {what}")
    ranked = sorted(groups.items(), key=lambda kv: -kv[1])
    (events, name), _ = ranked[0]
    ghost = next((chain_from_events(world, list(ev), nm) for (ev, nm), _ in ranked[1:] if nm == name), None)
    return Chains(chain_from_events(world, list(events), name), ghost, name)


def eyebox_offsets(eyebox: np.ndarray, grid: tuple[int, int]) -> np.ndarray:
    """(2, k) offsets (mm, right and up) of the eyebox grid, edges included, row by row from the top."""
    nx, ny = grid
    xs = np.linspace(-0.5, 0.5, nx) * eyebox[0] if nx > 1 else np.zeros(1)
    ys = np.linspace(0.5, -0.5, ny) * eyebox[1] if ny > 1 else np.zeros(1)
    gx, gy = np.meshgrid(xs, ys)
    return np.stack([gx.ravel(), gy.ravel()])


def _world_points(dep, frame, offsets):
    return dep[:, None] + offsets[0] * frame.right[:, None] + offsets[1] * frame.up[:, None]


def _vergence_parts(v: np.ndarray) -> dict[str, np.ndarray]:
    """Per bundle (n,): the mean vergence (1/mm), the sections' vergences and the astigmatism (1/mm) of
    vergence matrices ``v`` (2, 2, n) (principal vergences: the eigenvalues of the symmetric part)."""
    mean = 0.5 * (v[0, 0] + v[1, 1])
    half = np.sqrt((0.5 * (v[0, 0] - v[1, 1])) ** 2 + (0.5 * (v[0, 1] + v[1, 0])) ** 2)
    return {"mean": mean, "h": v[0, 0], "v": v[1, 1], "astigmatism": 2 * half}


def _distance(vergence: np.ndarray) -> np.ndarray:
    """1 / vergence (mm), NaN where the vergence is 0 or unknown (an image at infinity has no distance)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(vergence != 0, 1.0 / vergence, np.nan)


def _nan(fn, a, default=None):
    """``fn`` of the finite values of ``a``, or ``default`` where there are none."""
    a = np.asarray(a, dtype=np.float64)
    a = a[np.isfinite(a)]
    return float(fn(a)) if a.size else default


def _spread(a: np.ndarray, axis: int) -> np.ndarray:
    """max - min of the finite values of ``a`` along ``axis`` (NaN where there are none)."""
    finite = np.isfinite(a)
    hi = np.where(finite, a, -np.inf).max(axis=axis)
    lo = np.where(finite, a, np.inf).min(axis=axis)
    return np.where(finite.any(axis=axis), hi - lo, np.nan)


def _signed_max(a) -> float | None:
    """The value of largest magnitude among the finite values of ``a`` (its sign kept)."""
    a = np.asarray(a, dtype=np.float64).ravel()
    a = a[np.isfinite(a)]
    return float(a[np.argmax(np.abs(a))]) if a.size else None


class Analysis:
    """The optical analysis of a world (see the module docstring); :meth:`run` gives optics.json's dict."""

    def __init__(self, world):
        self.world = world
        # the scene's target block over the format's defaults (a loaded scene has them already)
        self.target = {f.name: f.default for f in TARGET.fields if f.default is not None} | world.scene.target
        eye = world.eye
        self.frame = VehicleFrame(*vehicle_axes(world.scene))
        self.dep = np.asarray(eye.position, dtype=np.float64)
        self.chains = find_chains(world, self.target.get("pgu"))
        try:
            self.pgu = pgu_of(world, self.chains.pgu)
        except OpticsError as e:
            if self.target.get("pgu") is None:
                raise
            raise SceneError(world.scene.file, "target.pgu", str(e)) from None
        self.primary = Imaging(world, self.chains.primary, self.pgu.plane, self.frame)
        self.ghost = Imaging(world, self.chains.ghost, self.pgu.plane, self.frame) if self.chains.ghost else None
        self._scan = None

    # -- first guesses -------------------------------------------------------------------------------
    def _initial(self, targets: np.ndarray) -> np.ndarray:
        """First guesses (2, n) for the DEP's chief rays onto ``targets`` (2, n): the nearest landing of a
        scan of directions over the eye's view."""
        if self._scan is None:
            eye = self.world.eye
            half = np.radians(np.asarray(eye.spec.fov_deg)) * 0.6
            gaze = self.frame.angles(eye.gaze.reshape(3, 1))[:, 0]
            hs, vs = np.meshgrid(np.linspace(-half[0], half[0], 61), np.linspace(-half[1], half[1], 31))
            hv = np.stack([hs.ravel() + gaze[0], vs.ravel() + gaze[1]])
            lnd = self.primary.land(np.repeat(self.dep[:, None], hv.shape[1], axis=1), self.frame.direction(hv))
            if not lnd.ok.any():
                raise OpticsError(f"no ray from the design eye point through {self.chains.primary.text} lands on the "
                                  "PGU's plane")
            self._scan = (hv[:, lnd.ok], lnd.xy[:, lnd.ok])
        hv, xy = self._scan
        d2 = ((xy[:, :, None] - targets[:, None, :]) ** 2).sum(axis=0)
        return hv[:, np.argmin(d2, axis=0)]

    def image_directions(self, points_mm: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Where the design eye point sees PGU points ``points_mm`` (2, n; the PGU plane's coordinates,
        :class:`PGU`): unit directions (3, n) of their primary images' chief rays (NaN where none
        converges) and (n,) whether each converged."""
        hv, ok = self._solve_dep(self.primary, np.asarray(points_mm, dtype=np.float64))
        return np.where(ok, self.frame.direction(np.where(ok, hv, 0.0)), np.nan), ok

    def _solve_dep(self, imaging: Imaging, targets: np.ndarray, guess: np.ndarray | None = None):
        n = targets.shape[1]
        return imaging.solve(np.repeat(self.dep[:, None], n, axis=1), targets,
                             self._initial(targets) if guess is None else guess)

    # -- the field grid ------------------------------------------------------------------------------
    def field_grid(self) -> dict:
        """The field points: ``targets`` (2, nx ny) PGU mm, row by row from the image's top, columns from its
        left; ``u``, ``w`` (nx ny,) their nominal coordinates (-1..1, right and up in the image);
        ``axes`` (2, 2): the PGU (x, y) directions of the image's right and up (columns); ``extras`` (2, 5):
        the centre and the middles of the left, right, top and bottom edges."""
        nx, ny = self.target["field_grid"]
        centre = np.zeros((2, 1))
        hv0, ok = self._solve_dep(self.primary, centre)
        if not ok[0]:
            raise OpticsError(f"no chief ray from the design eye point lands on the centre of the PGU {self.pgu.name} "
                              f"through {self.chains.primary.text}")
        step = 0.05 * float(self.pgu.half.min())
        probe = np.array([[step, 0.0], [0.0, step]])
        hv, ok = self._solve_dep(self.primary, probe, np.repeat(hv0, 2, axis=1))
        if not ok.all():
            raise OpticsError("the chief rays near the PGU's centre do not converge")
        jac = (hv - hv0) / step  # columns: d(h, v)/dx, d(h, v)/dy
        across = 0 if abs(jac[0, 0]) >= abs(jac[0, 1]) else 1
        right, up = np.zeros(2), np.zeros(2)
        right[across] = np.sign(jac[0, across]) * self.pgu.half[across]
        up[1 - across] = np.sign(jac[1, 1 - across]) * self.pgu.half[1 - across]
        gu, gw = np.meshgrid(np.linspace(-1, 1, nx), np.linspace(1, -1, ny))
        u, w = gu.ravel(), gw.ravel()
        eu, ew = np.array([0.0, -1, 1, 0, 0]), np.array([0.0, 0, 0, 1, -1])
        return {"targets": np.outer(right, u) + np.outer(up, w), "u": u, "w": w, "grid": (nx, ny),
                "axes": np.stack([right, up], 1), "extras": np.outer(right, eu) + np.outer(up, ew),
                "half_mm": np.array([abs(right).max(), abs(up).max()])}

    # -- the design eye point ------------------------------------------------------------------------
    def design_eye(self, field: dict, spot: bool = True) -> dict:
        """Chief rays, bundles, ghosts and spots of the field points (and the extras) from the DEP."""
        pts = np.concatenate([field["targets"], field["extras"]], axis=1)
        hv, ok = self._solve_dep(self.primary, pts)
        dep = np.repeat(self.dep[:, None], pts.shape[1], axis=1)
        verg = self.primary.vergence(dep, np.where(np.isfinite(hv), hv, 0.0))
        verg[:, :, ~ok] = np.nan
        self.centre_hv = hv[:, field["targets"].shape[1]]  # the PGU centre's, the first extra
        out = {"points": pts, "hv": hv, "ok": ok, "vergence": verg,
               "factor": self.primary.land(dep, self.frame.direction(np.where(ok, hv, 0.0))).factor}
        if self.ghost is not None:
            ghv, gok = self._solve_dep(self.ghost, pts, np.where(np.isfinite(hv), hv, self._initial(pts)))
            out |= {"ghost_hv": ghv, "ghost_ok": gok,
                    "ghost_factor": self.ghost.land(dep, self.frame.direction(np.where(gok, ghv, 0.0))).factor}
        if spot:
            rad = np.full(pts.shape[1], np.nan)
            k = np.flatnonzero(ok)
            if len(k):
                rad[k] = self.primary.spot(self.dep, hv[:, k], pts[:, k], verg[:, :, k], self.world.eye.pupil_radius)
            out["spot"] = rad
        return out

    # -- eye points ----------------------------------------------------------------------------------
    def eye_points(self, field: dict, design: dict, offsets: np.ndarray, tid: float) -> dict:
        """Chief rays (2, e, f) of the field points from the eye points at ``offsets`` (2, e) mm (right, up)
        from the DEP, their bundles' vergence parts and ghosts, and the dynamic distortion against an
        image at ``tid`` mm."""
        pts = field["targets"]
        nf, ne = pts.shape[1], offsets.shape[1]
        eyes = _world_points(self.dep, self.frame, offsets)  # (3, e)
        ee = np.repeat(eyes, nf, axis=1)
        tt = np.tile(pts, ne)
        known = np.isfinite(design["hv"][0, :nf])  # field points the DEP sees: the others have no expectation
        d0 = self.frame.direction(np.where(known, design["hv"][:, :nf], 0.0))
        image = self._target_points(self.dep[:, None], d0, self.centre_hv, tid)
        expected = np.tile(image, ne) - ee
        expected /= np.linalg.norm(expected, axis=0)
        exp_hv = np.where(np.tile(known, ne), self.frame.angles(expected), np.nan)
        hv, ok = self.primary.solve(ee, tt, np.where(np.isfinite(exp_hv), exp_hv, self._initial(tt)))
        verg = self.primary.vergence(ee, np.where(ok, hv, 0.0))
        verg[:, :, ~ok] = np.nan
        out = {"eyes": eyes, "hv": hv.reshape(2, ne, nf), "ok": ok.reshape(ne, nf),
               "vergence": {k: v.reshape(ne, nf) for k, v in _vergence_parts(verg).items()},
               "dynamic": (hv - exp_hv).reshape(2, ne, nf)}
        if self.ghost is not None:
            ghv, gok = self.ghost.solve(ee, tt, np.where(ok, hv, np.where(np.isfinite(exp_hv), exp_hv,
                                                                           self._initial(tt))))
            out |= {"ghost_hv": ghv.reshape(2, ne, nf), "ghost_ok": gok.reshape(ne, nf)}
        return out

    def pairs(self, field: dict, offsets: np.ndarray, mids: dict, tid: float) -> dict:
        """Binocular pairs centred on the eye points ``offsets`` (2, e) whose two eyes lie in the eyebox:
        convergence and dipvergence (rad) per pair and field point; ``mids``: :meth:`eye_points` of
        the same offsets."""
        ipd = float(self.target["ipd_mm"])
        box = np.asarray(self.target["eyebox_mm"], dtype=np.float64)
        inside = np.flatnonzero(np.abs(offsets[0]) + 0.5 * ipd <= 0.5 * box[0] + 1e-9)
        if len(inside) == 0:
            return {"index": inside}
        mid = offsets[:, inside]
        both = np.concatenate([mid - [[0.5 * ipd], [0.0]], mid + [[0.5 * ipd], [0.0]]], axis=1)
        pts = field["targets"]
        nf, npair = pts.shape[1], len(inside)
        eyes = _world_points(self.dep, self.frame, both)
        ee = np.repeat(eyes, nf, axis=1)
        hv_mid = mids["hv"][:, inside].reshape(2, -1)  # (2, p f): where the midpoint sees each field point
        known = np.isfinite(hv_mid[0])
        d_mid = self.frame.direction(np.where(known, hv_mid, 0.0))
        m_world = np.repeat(_world_points(self.dep, self.frame, mid), nf, axis=1)
        image = self._target_points(m_world, d_mid, self.centre_hv, tid)
        exp = np.tile(image, 2) - ee
        exp /= np.linalg.norm(exp, axis=0)
        exp = np.where(np.tile(known, 2), exp, np.nan)
        targets = np.tile(pts, 2 * npair)
        guess = np.where(np.isfinite(exp[:2]), self.frame.angles(np.where(np.isfinite(exp), exp, 1.0)),
                         self._initial(targets))
        hv, ok = self.primary.solve(ee, targets, guess)
        # Helmholtz angles: the two eyes lie along the frame's right, so a real point gives no dipvergence
        helm = np.where(ok, self.frame.helmholtz(self.frame.direction(np.where(ok, hv, 0.0))), np.nan)
        helm = helm.reshape(2, 2, npair, nf)
        exp_helm = self.frame.helmholtz(exp).reshape(2, 2, npair, nf)
        left, right = helm[:, 0], helm[:, 1]
        angle = left[0] - right[0]
        conv = angle - (exp_helm[0, 0] - exp_helm[0, 1])
        dip = left[1] - right[1]
        return {"index": inside, "convergence": conv, "dipvergence": dip, "angle": angle}

    def _target_points(self, eyes: np.ndarray, d: np.ndarray, centre_hv: np.ndarray, tid: float) -> np.ndarray:
        """(3, n): where the lines of sight from ``eyes`` (3, n or 1) along ``d`` (3, n) meet the target image
        plane, square to the centre's line of sight ``centre_hv`` (2,) from the DEP at ``tid`` mm from it."""
        c = self.frame.direction(np.asarray(centre_hv, dtype=np.float64).reshape(2, 1))[:, 0]
        reach = (self.dep + tid * c - eyes.T).T  # (3, n)
        s = (c @ reach) / (c @ d)
        return eyes + s * d

    def usage(self, field: dict, centre_hv: np.ndarray, fov_deg) -> float | None:
        """The share of the PGU's area whose image from the DEP lies inside the target field of view
        (a rectangle of angles around ``centre_hv``, the target's image centre)."""
        if fov_deg is None:
            return None
        half = 0.5 * np.radians(np.asarray(fov_deg, dtype=np.float64))
        gu, gw = np.meshgrid(np.linspace(-1, 1, 41) * 40 / 41, np.linspace(1, -1, 21) * 20 / 21)  # cell centres
        pts = np.outer(field["axes"][:, 0], gu.ravel()) + np.outer(field["axes"][:, 1], gw.ravel())
        hv, ok = self._solve_dep(self.primary, pts)
        inside = ok & (np.abs(hv[0] - centre_hv[0]) <= half[0]) & (np.abs(hv[1] - centre_hv[1]) <= half[1])
        return float(inside.mean())

    # -- the whole analysis --------------------------------------------------------------------------
    def run(self, eyebox: bool = True, spot: bool = True) -> dict:
        """The analysis as optics.json's dict: the design eye point always, the eyebox grid and the binocular
        pairs with ``eyebox``, the spots with ``spot``."""
        t0 = time.perf_counter()
        field = self.field_grid()
        design = self.design_eye(field, spot)
        out = self._design(field, design)
        seconds = {"design_eye": time.perf_counter() - t0}
        if eyebox:
            t1 = time.perf_counter()
            tid = out["target"]["distance_mm"]["value"]
            offsets = eyebox_offsets(np.asarray(self.target["eyebox_mm"], dtype=np.float64), self.target["eye_grid"])
            eyes = self.eye_points(field, design, offsets, tid)
            pairs = self.pairs(field, offsets, eyes, tid)
            box = self._eyebox(offsets, eyes, pairs)
            out["summary"]["eyebox"] = box.pop("summary")
            out |= box
            seconds["eyebox"] = time.perf_counter() - t1
        out["seconds"] = seconds
        return out

    # -- the report ----------------------------------------------------------------------------------
    def _design(self, field: dict, design: dict) -> dict:
        nf = field["targets"].shape[1]
        nx, ny = field["grid"]
        hv, ok = design["hv"], design["ok"]
        parts = _vergence_parts(design["vergence"])
        c = nf  # the centre is the first extra
        left, right, top, bottom = nf + 1, nf + 2, nf + 3, nf + 4
        vid = _distance(parts["mean"])
        t = self.target
        centre_hv = hv[:, c]
        def given(key, measured):
            return {"value": float(t[key]), "source": "given"} if key in t else \
                {"value": measured, "source": "measured"}

        target_block = {
            "distance_mm": given("distance_mm", float(vid[c])),
            "look_down_deg": given("look_down_deg", float(-np.degrees(centre_hv[1]))),
            "look_over_deg": given("look_over_deg", float(np.degrees(centre_hv[0]))),
            "fov_deg": {"value": [float(x) for x in t["fov_deg"]], "source": "given"} if "fov_deg" in t else
            {"value": None, "source": "absent"},
            "eyebox_mm": [float(x) for x in t["eyebox_mm"]], "ipd_mm": float(t["ipd_mm"]),
            "field_grid": list(field["grid"]), "eye_grid": list(t["eye_grid"]),
        }
        fov_h = hv[0, right] - hv[0, left]
        fov_v = hv[1, top] - hv[1, bottom]
        half = field["half_mm"]
        # The image's shape on the plane across the centre's line of sight (gnomonic coordinates, rad):
        # a rectangle square to the line of sight is a rectangle there, whatever its size.
        g = slice(0, nf)
        gp = self.frame.gnomonic(hv, hv[:, c])
        # static distortion against the best rectangular grid: x = x0 + a u, y = y0 + b w (least squares)
        u, w = field["u"], field["w"]
        fit_h = np.polyfit(u[ok[g]], gp[0, g][ok[g]], 1) if ok[g].sum() >= 2 else (np.nan, np.nan)
        fit_v = np.polyfit(w[ok[g]], gp[1, g][ok[g]], 1) if ok[g].sum() >= 2 else (np.nan, np.nan)
        ideal = np.stack([np.polyval(fit_h, u), np.polyval(fit_v, w)])
        resid = gp[:, g] - ideal
        dist = np.sqrt((resid ** 2).sum(axis=0))
        half_diag = math.hypot(fit_h[0], fit_v[0])
        rows = gp[:, g].reshape(2, ny, nx)
        mid_col = rows[:, :, nx // 2] if nx % 2 else 0.5 * (rows[:, :, nx // 2 - 1] + rows[:, :, nx // 2])
        smile = mid_col[1] - 0.5 * (rows[1, :, 0] + rows[1, :, -1])
        width_top, width_bottom = rows[0, 0, -1] - rows[0, 0, 0], rows[0, -1, -1] - rows[0, -1, 0]
        height_left, height_right = rows[1, 0, 0] - rows[1, -1, 0], rows[1, 0, -1] - rows[1, -1, -1]
        pixel = None
        if self.pgu.pixels is not None:
            pitch = math.sqrt(4 * self.pgu.half[0] * self.pgu.half[1] / (self.pgu.pixels[0] * self.pgu.pixels[1]))
            pixel = pitch * abs(fov_h) / (2 * half[0]) * ARCMIN
        centre_vid = float(vid[c])
        summary = {
            "vid_mm": centre_vid, "vergence_d": float(parts["mean"][c] * 1e3),
            "vid_min_mm": _nan(np.min, vid[g]), "vid_max_mm": _nan(np.max, vid[g]),
            "vid_tangential_mm": float(_distance(parts["v"][c])), "vid_sagittal_mm": float(_distance(parts["h"][c])),
            "astigmatism_d": _nan(np.max, parts["astigmatism"][g] * 1e3),
            "astigmatism_centre_d": float(parts["astigmatism"][c] * 1e3),
            "field_curvature_d": _nan(np.ptp, parts["mean"][g] * 1e3),
            "field_curvature_mm": _nan(np.ptp, vid[g]),
            "look_down_deg": float(-np.degrees(centre_hv[1])), "look_over_deg": float(np.degrees(centre_hv[0])),
            "fov_h_deg": float(np.degrees(fov_h)), "fov_v_deg": float(np.degrees(fov_v)),
            "magnification_h": float(2 * centre_vid * math.tan(abs(fov_h) / 2) / (2 * half[0])),
            "magnification_v": float(2 * centre_vid * math.tan(abs(fov_v) / 2) / (2 * half[1])),
            "pixel_size_arcmin": pixel,
            "static_distortion_mrad": _nan(np.max, dist * MRAD),
            "static_distortion_percent": _nan(np.max, dist / half_diag * 100) if half_diag > 0 else None,
            "rotation_mrad": float(math.atan2(gp[1, right] - gp[1, left], gp[0, right] - gp[0, left]) * MRAD),
            "smile_mrad": _signed_max(smile * MRAD),
            "trapezoid_h_percent": float((width_top - width_bottom) / (0.5 * (width_top + width_bottom)) * 100),
            "trapezoid_v_percent": float((height_left - height_right) / (0.5 * (height_left + height_right)) * 100),
        }
        # against the target, where it gives the figure
        for key, target_key, measured in (("vid_minus_target_mm", "distance_mm", centre_vid),
                                          ("look_down_minus_target_deg", "look_down_deg", summary["look_down_deg"]),
                                          ("look_over_minus_target_deg", "look_over_deg", summary["look_over_deg"])):
            if target_key in t:
                summary[key] = measured - float(t[target_key])
        if "fov_deg" in t:
            summary["fov_h_minus_target_deg"] = summary["fov_h_deg"] - float(t["fov_deg"][0])
            summary["fov_v_minus_target_deg"] = summary["fov_v_deg"] - float(t["fov_deg"][1])
        per_field = {
            "pgu_mm": field["targets"].T.tolist(), "azimuth_deg": np.degrees(hv[0, g]), "elevation_deg":
            np.degrees(hv[1, g]), "vid_mm": vid[g], "vid_tangential_mm": _distance(parts["v"][g]),
            "vid_sagittal_mm": _distance(parts["h"][g]), "vergence_d": parts["mean"][g] * 1e3,
            "astigmatism_d": parts["astigmatism"][g] * 1e3, "distortion_mrad": dist * MRAD,
            "distortion_h_mrad": resid[0] * MRAD, "distortion_v_mrad": resid[1] * MRAD,
            "image_x_mrad": gp[0, g] * MRAD, "image_y_mrad": gp[1, g] * MRAD,
            "ideal_x_mrad": ideal[0] * MRAD, "ideal_y_mrad": ideal[1] * MRAD,
        }
        if "spot" in design:
            summary["spot_rms_arcmin"] = _nan(np.max, design["spot"][g] * ARCMIN)
            per_field["spot_rms_arcmin"] = design["spot"][g] * ARCMIN
        if "ghost_hv" in design:
            sep, off = self._separation(hv, design["ghost_hv"])
            summary |= {"ghost_separation_arcmin": _nan(np.max, sep[g] * ARCMIN),
                        "ghost_separation_centre_arcmin": float(sep[c] * ARCMIN),
                        "ghost_offset_h_arcmin": float(off[0, c] * ARCMIN),
                        "ghost_offset_v_arcmin": float(off[1, c] * ARCMIN),
                        "ghost_ratio": float(design["ghost_factor"][c] / design["factor"][c])
                        if design["factor"][c] > 0 else None}
            per_field |= {"ghost_separation_arcmin": sep[g] * ARCMIN, "ghost_offset_h_arcmin": off[0, g] * ARCMIN,
                          "ghost_offset_v_arcmin": off[1, g] * ARCMIN}
        fov = target_block["fov_deg"]["value"]
        aim_hv = np.array([math.radians(target_block["look_over_deg"]["value"]),
                           -math.radians(target_block["look_down_deg"]["value"])])
        summary["pgu_usage"] = self.usage(field, aim_hv, fov)
        summary["field_points_seen"] = f"{int(ok[g].sum())}/{nf}"
        fields = [{k: _value(v, j) for k, v in per_field.items()} | {"row": j // nx, "column": j % nx}
                  for j in range(nf)]
        return {"target": target_block, "summary": {"design_eye": summary}, "field_points": fields}

    def _separation(self, hv: np.ndarray, ghv: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(angle (...,) rad between primary and ghost directions, (2, ...) ghost minus primary angles)."""
        shape = hv.shape[1:]
        a = self.frame.direction(hv.reshape(2, -1))
        b = self.frame.direction(ghv.reshape(2, -1))
        sep = 2 * np.arcsin(np.clip(0.5 * np.linalg.norm(a - b, axis=0), 0, 1))
        return sep.reshape(shape), ghv - hv

    def _eyebox(self, offsets, eyes, pairs) -> dict:
        ne = offsets.shape[1]
        vm = eyes["vergence"]["mean"]  # (e, f) 1/mm
        dyn = np.sqrt((eyes["dynamic"] ** 2).sum(axis=0))  # (e, f) rad
        summary = {
            "focus_variation_d": _nan(np.max, _spread(vm, axis=0) * 1e3),
            "dynamic_distortion_mrad": _nan(np.max, dyn * MRAD),
            "vid_min_mm": _nan(np.min, _distance(vm)), "vid_max_mm": _nan(np.max, _distance(vm)),
            "astigmatism_d": _nan(np.max, eyes["vergence"]["astigmatism"] * 1e3),
            "eye_points_seeing_every_field_point": f"{int(eyes['ok'].all(axis=1).sum())}/{ne}",
        }
        points = []
        gsep = None
        if "ghost_hv" in eyes:
            gsep, goff = self._separation(eyes["hv"], eyes["ghost_hv"])
            summary["ghost_separation_arcmin"] = _nan(np.max, gsep * ARCMIN)
            summary["ghost_offset_v_arcmin"] = _signed_max(goff[1] * ARCMIN)
        pair_rows = []
        if len(pairs["index"]):
            conv, dip = pairs["convergence"] * MRAD, pairs["dipvergence"] * MRAD
            summary |= {"convergence_mrad": _nan(np.max, np.maximum(conv, 0)), "divergence_mrad":
                        _nan(np.max, np.maximum(-conv, 0)), "dipvergence_mrad": _nan(np.max, np.abs(dip)),
                        "binocular_pairs": len(pairs["index"])}
            for k, e in enumerate(pairs["index"].tolist()):
                pair_rows.append({"midpoint_mm": offsets[:, e].tolist(),
                                  "vergence_angle_mrad": _value(pairs["angle"][k] * MRAD, None),
                                  "convergence_mrad": _value(conv[k], None), "dipvergence_mrad": _value(dip[k], None),
                                  "convergence_max_mrad": _signed_max(conv[k]),
                                  "dipvergence_max_mrad": _signed_max(dip[k])})
        else:
            summary |= {"convergence_mrad": None, "divergence_mrad": None, "dipvergence_mrad": None,
                        "binocular_pairs": 0}
        for e in range(ne):
            row = {"offset_mm": offsets[:, e].tolist(), "field_points_seen": int(eyes["ok"][e].sum()),
                   "azimuth_deg": _value(np.degrees(eyes["hv"][0, e]), None),
                   "elevation_deg": _value(np.degrees(eyes["hv"][1, e]), None),
                   "vid_mm": _value(_distance(vm[e]), None),
                   "astigmatism_d": _value(eyes["vergence"]["astigmatism"][e] * 1e3, None),
                   "dynamic_distortion_mrad": _value(dyn[e] * MRAD, None),
                   "dynamic_distortion_max_mrad": _nan(np.max, dyn[e] * MRAD)}
            if gsep is not None:
                row["ghost_separation_arcmin"] = _value(gsep[e] * ARCMIN, None)
                row["ghost_separation_max_arcmin"] = _nan(np.max, gsep[e] * ARCMIN)
            points.append(row)
        return {"summary": summary, "eye_points": points, "pairs": pair_rows}


def _value(a, j):
    """JSON form of entry ``j`` of ``a`` (or of the whole array where ``j`` is None): NaN as None."""
    if isinstance(a, list):
        return a[j] if j is not None else a
    x = np.asarray(a, dtype=np.float64)
    if j is not None:
        x = x[..., j]
    if x.ndim == 0:
        return float(x) if np.isfinite(x) else None
    return [None if not np.isfinite(v) else float(v) for v in x.ravel()]


#: The eyebox summary's metrics (optics.json's ``summary.eyebox``).
EYEBOX_KEYS = ("focus_variation_d", "dynamic_distortion_mrad", "vid_min_mm", "vid_max_mm", "astigmatism_d",
               "ghost_separation_arcmin", "ghost_offset_v_arcmin", "convergence_mrad", "divergence_mrad",
               "dipvergence_mrad", "binocular_pairs")
#: Further design-eye figures that optics.json's summary carries besides :data:`DESIGN_KEYS`.
DESIGN_EXTRAS = ("vid_tangential_mm", "vid_sagittal_mm", "astigmatism_centre_d", "vid_minus_target_mm",
                 "look_down_minus_target_deg", "look_over_minus_target_deg", "fov_h_minus_target_deg",
                 "fov_v_minus_target_deg")
#: What a requirement's KEY may name: ``design_eye.KEY`` or ``eyebox.KEY``.
REQUIREMENT_KEYS = {"design_eye": DESIGN_KEYS + DESIGN_EXTRAS, "eyebox": EYEBOX_KEYS}


def check_metric(names: list, where: str) -> None:
    """Refuse a metric path (``["design_eye", "vid_mm"]``) that names no metric of optics.json's summary
    (:data:`REQUIREMENT_KEYS`). Raises :class:`OpticsError` beginning with ``where``."""
    import difflib

    if len(names) != 2 or names[0] not in REQUIREMENT_KEYS:
        raise OpticsError(f"{where}: KEY must be design_eye.METRIC or eyebox.METRIC (design_eye.vid_mm)")
    known = REQUIREMENT_KEYS[names[0]]
    if names[1] not in known:
        near = difflib.get_close_matches(names[1], known, n=1)
        hint = f" (did you mean {near[0]!r}?)" if near else ""
        raise OpticsError(f"{where}: {names[0]} has no metric {names[1]!r}{hint}; see docs/user/optics.md")


def check_requirements(scene, eyebox: bool = True) -> None:
    """Refuse, before any ray, a requirement of ``scene``'s target whose KEY names no metric of
    optics.json's summary (:func:`check_metric`), or one on the eyebox where ``eyebox`` is false:
    :class:`~tracer.core.errors.SceneError` naming scene.json and ``target.requirements[i]``."""
    for i, req in enumerate(scene.target.get("requirements", [])):
        names = [arg for _, arg in req.steps]
        try:
            check_metric(names, repr(req.text))
        except OpticsError as e:
            raise SceneError(scene.file, f"target.requirements[{i}]", str(e)) from None
        if names[0] == "eyebox" and not eyebox:
            raise SceneError(scene.file, f"target.requirements[{i}]",
                             f"{req.text!r} is judged over the eyebox, which this run leaves out (--no-eyebox)")



def _exact_objects(world, chains: Chains) -> list[str]:
    """The objects on the chains that have exact surfaces."""
    slots = {slot for chain in (chains.primary, chains.ghost) if chain for slot, _ in chain.steps}
    return sorted(o.name for o in world.scene.objects if o.slot in slots and o.surfaces)


def _numbers(block: dict) -> dict:
    return {k: v for k, v in block.items() if isinstance(v, (int, float)) and not isinstance(v, bool)}


def mesh_comparison(exact: dict, meshed: dict) -> dict:
    """What the meshes alone would cost each summary metric: {section: {metric: {"exact", "mesh",
    "error"}}}, the error mesh - exact in the metric's unit."""
    out = {}
    for section in ("design_eye", "eyebox"):
        a, b = _numbers(exact["summary"].get(section, {})), _numbers(meshed["summary"].get(section, {}))
        out[section] = {k: {"exact": a[k], "mesh": b[k], "error": b[k] - a[k]} for k in a if k in b}
    return out


def analyse(scene, eyebox: bool = True, spot: bool = True, compare_mesh: bool = True, world=None) -> dict:
    """optics.json's document for ``scene`` (tracer.scene.Scene): the chains, the target, the summary at
    the design eye point (and over the eyebox with ``eyebox``), the requirements judged, every field
    point, eye point and binocular pair, each metric's unit and definition, and, where an optic of the
    chains has exact surfaces and ``compare_mesh``, the same summary traced on the meshes alone.
    Raises :class:`OpticsError` where the scene shows no image to analyse."""
    from ..transport.world import World

    check_requirements(scene, eyebox)
    t0 = time.perf_counter()
    world = World(scene) if world is None else world
    analysis = Analysis(world)
    out = analysis.run(eyebox=eyebox, spot=spot)
    doc = {
        "scene": scene.name,
        "chains": {"pgu": analysis.chains.pgu, "primary": analysis.chains.primary.text,
                   "ghost": analysis.chains.ghost.text if analysis.chains.ghost else None},
        "design_eye_mm": [float(x) for x in analysis.dep],
        "vehicle_axes": {"forward": analysis.frame.forward.tolist(), "right": analysis.frame.right.tolist(),
                         "up": analysis.frame.up.tolist()},
        "exact_surfaces": _exact_objects(world, analysis.chains),
    }
    doc |= out
    doc["warnings"] = _warnings(out, analysis)
    doc["requirements"] = [r.judge(out["summary"]) for r in scene.target.get("requirements", [])]
    doc["requirements_met"] = all(r["met"] for r in doc["requirements"])
    if compare_mesh and doc["exact_surfaces"]:
        meshed = Analysis(World(scene, exact_surfaces=False)).run(eyebox=eyebox, spot=spot)
        doc["mesh_comparison"] = mesh_comparison(out, meshed)
    units = {k: {"unit": u, "definition": d} for k, (u, d) in DEFINITIONS.items()}
    doc["definitions"] = units
    doc["seconds"] = dict(out["seconds"]) | {"total": time.perf_counter() - t0}
    return doc


def _warnings(out: dict, analysis: Analysis) -> list[str]:
    """What a person should know before trusting the figures."""
    s = out["summary"]["design_eye"]
    t = analysis.target
    warn = []
    seen, total = (int(x) for x in s["field_points_seen"].split("/"))
    if seen < total:
        warn.append(f"the design eye point sees {seen} of {total} field points (the others' rays miss an optic or "
                    "are blocked): the summary covers those it sees")
    if abs(s["look_over_deg"]) > 90:
        warn.append(f"the image lies {s['look_over_deg']:.1f} deg from the vehicle's forward direction: does "
                    "target.forward point forward?")
    box = out["summary"].get("eyebox")
    if box is not None and box["binocular_pairs"] == 0:
        warn.append(f"no binocular pair fits: IPD {float(t['ipd_mm']):g} mm against an eyebox "
                    f"{float(t['eyebox_mm'][0]):g} mm wide (target.ipd_mm, target.eyebox_mm)")
    return warn


def report_block(doc: dict) -> dict:
    """report.json's ``optics`` block (and a sweep's ``optics.*`` figures) of :func:`analyse`'s document:
    the chains, the target's values, the design eye's and the eyebox's summaries, the requirements."""
    return {"chains": doc["chains"], "target": {k: (v["value"] if isinstance(v, dict) else v)
                                                 for k, v in doc["target"].items()},
            **doc["summary"], "requirements": doc["requirements"], "requirements_met": doc["requirements_met"],
            "warnings": doc["warnings"], "seconds": doc["seconds"]["total"]}


#: Render blocks of the optical analysis by scene hash: it depends on the scene alone (its own eye), so a
#: scene rendered again (F12 after F12, a sweep's repeated runs) is analysed once. Handed out as copies.
KEPT_BLOCKS = KeptResults(16, copy=copy.deepcopy)


def optics_block(scene, world=None) -> dict:
    """report.json's ``optics`` block for a render (:func:`report_block`, without spots and the mesh
    comparison), or {"error": why} where the scene shows no image to analyse or lacks a target field the
    analysis needs (the render does not fail for it; its requirements were checked before the render).
    ``world``: the scene's own (saves building it). Kept by the scene's hash (:data:`KEPT_BLOCKS`; its
    ``seconds`` are those of the analysis that made it)."""
    from ..transport.sequential import ChainError

    def make() -> dict:
        try:
            return report_block(analyse(scene, spot=False, compare_mesh=False, world=world))
        except SceneError as e:  # a field the analysis needs (target.forward for a vertical gaze, target.pgu)
            return {"error": f"{e.field}: {e.message}"}
        except (OpticsError, ChainError) as e:
            return {"error": str(e)}

    return KEPT_BLOCKS.get(scene.scene_hash, make)
