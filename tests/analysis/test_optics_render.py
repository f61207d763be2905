"""The render agrees with the optical analysis (tracer/analysis/optics.py): on hud-direct showing a grid
of one-pixel lines, seen through 0.25 arcmin pixels around the image's centre, the ghost line lies where
the analysis puts it (within one pixel), a wedge windshield fuses it with the line (the ghost strokes'
luminance measured), the ghost carries the analysis's luminance ratio, and an eye accommodated at the
reported VID sees the line at its sharpest; a grid slide's crossings lie where the analysis images them,
as distorted as it reports."""

import numpy as np
import pytest

from presets.hud_direct_optics import WEDGE_MRAD
from presets.slide import grid_array
from tests.support.imaging import hud_direct_grid
from tests.support.render import render
from tracer.analysis.optics import Analysis, analyse
from tracer.scene import load_scene
from tracer.transport.world import World

pytestmark = pytest.mark.slow

FOV_DEG = (1.0, 0.5)
RESOLUTION = (240, 120)
ARCMIN_PER_PX = FOV_DEG[1] * 60 / RESOLUTION[1]
#: The band of columns the vertical profile averages: right of the grid's middle vertical line.
COLUMNS = slice(160, 200)
RAYS = 3_000_000


def _scene(folder, accommodation_mm=None, **kw):
    """hud-direct (or a variant through ``kw``) showing the 5 x 3 grid of one LCD pixel wide lines, the eye's
    view narrowed onto the image's centre."""
    eye = {"fov_deg": list(FOV_DEG), "resolution": list(RESOLUTION)}
    if accommodation_mm is not None:
        eye["accommodation_distance_mm"] = accommodation_mm
    return hud_direct_grid(folder, eye, **kw)


def _line_fit(y: np.ndarray, near: int, across: np.ndarray, at: float) -> float:
    """The row of a bright line running across the columns ``across`` of ``y`` near row ``near``: in each
    column inside the image and lit, the luminance-weighted row within 4 of ``near``; a straight line
    through them, read at column ``at``."""
    rows = np.arange(near - 4, near + 5)
    xs, cs = [], []
    for k in across:
        if not 0 <= k < y.shape[1]:
            continue
        prof = y[rows, k]
        w = np.maximum(prof - prof.min(), 0)
        if w.sum() <= 0 or prof.max() < 1000.0:  # cd/m^2: outside the display
            continue
        xs.append(k)
        cs.append((rows * w).sum() / w.sum())
    a, b = np.polyfit(xs, cs, 1)
    return float(a * at + b)


def _blobs(profile: np.ndarray, background: float) -> list[dict]:
    """The profile's runs above half of its peak over the background, as {"rows", "centre" (the
    luminance-weighted row), "plateau" (the mean of the run's inner rows), "sum"}, top first."""
    above = profile - background
    lit = above > 0.25 * above.max()
    runs, k = [], 0
    while k < len(profile):
        if lit[k]:
            j = k
            while j + 1 < len(profile) and lit[j + 1]:
                j += 1
            rows = np.arange(max(0, k - 1), min(len(profile), j + 2))
            w = np.maximum(above[rows], 0)
            runs.append({"rows": (k, j), "centre": float((rows * w).sum() / w.sum()),
                         "plateau": float(above[k + 1:j].mean()) if j - k >= 2 else float(above[k:j + 1].max()),
                         "sum": float(w.sum())})
            k = j + 1
        else:
            k += 1
    return runs


@pytest.fixture(scope="module")
def flat(tmp_path_factory):
    folder = _scene(tmp_path_factory.mktemp("flat") / "flat")
    doc = analyse(load_scene(folder), eyebox=False, compare_mesh=False)
    y, _, _ = render(folder, "backward", RAYS, seed=1)
    return doc, y[:, COLUMNS].mean(axis=1)


def test_the_ghost_lies_where_the_analysis_puts_it(flat):
    doc, profile = flat
    background = float(np.median(profile))
    blobs = _blobs(profile, background)
    assert len(blobs) == 2, blobs
    ghost, primary = blobs  # the ghost above: rows run down
    measured = (primary["centre"] - ghost["centre"]) * ARCMIN_PER_PX
    predicted = doc["summary"]["design_eye"]["ghost_offset_v_arcmin"]
    assert predicted > 3.0
    assert measured == pytest.approx(predicted, abs=ARCMIN_PER_PX)
    # and with the analysis's luminance ratio (the s and p channels apart: 0.574, not the unpolarised 0.735)
    ratio = doc["summary"]["design_eye"]["ghost_ratio"]
    assert ghost["sum"] / primary["sum"] == pytest.approx(ratio, rel=0.03)


def test_the_wedge_shows_one_line_where_the_flat_windshield_shows_two(flat, tmp_path):
    _, flat_profile = flat
    folder = _scene(tmp_path / "wedge", windshield={"wedge_mrad": WEDGE_MRAD})
    y, _, _ = render(folder, "backward", RAYS, seed=1)
    profile = y[:, COLUMNS].mean(axis=1)
    background = float(np.median(profile))
    blobs = _blobs(profile, background)
    assert len(blobs) == 1, blobs
    ghost_rows = slice(*_blobs(flat_profile, float(np.median(flat_profile)))[0]["rows"])
    ghost_rows = slice(ghost_rows.start, ghost_rows.stop + 1)
    flat_ghost = float(flat_profile[ghost_rows].mean() - np.median(flat_profile))
    wedge_ghost = float(profile[ghost_rows].mean() - background)
    assert flat_ghost > 1000.0  # cd/m^2 above the background, where the flat windshield's ghost lies
    assert abs(wedge_ghost) < 0.01 * flat_ghost  # nothing there: the ghost lies under the line
    # the fused line holds the primary's and the ghost's light together
    flat_sum = sum(b["sum"] for b in _blobs(flat_profile, float(np.median(flat_profile))))
    assert blobs[0]["sum"] == pytest.approx(flat_sum, rel=0.03)


def test_an_eye_accommodated_at_the_vid_sees_the_line_sharpest(tmp_path):
    """The fused line's RMS width against the eye's accommodation, at five vergences 0.1 D apart
    around the reported VID's: the parabola through the squared widths has its vertex within 0.03 D of
    1 / VID (the eye's depth of field is about 0.3 D)."""
    base = _scene(tmp_path / "a", windshield={"wedge_mrad": WEDGE_MRAD})
    vid = analyse(load_scene(base), eyebox=False, compare_mesh=False)["summary"]["design_eye"]["vid_mm"]
    vergences = 1e3 / vid + np.array([-0.2, -0.1, 0.0, 0.1, 0.2])  # D
    widths = []
    for k, v in enumerate(vergences):
        folder = _scene(tmp_path / f"v{k}", accommodation_mm=1e3 / v, windshield={"wedge_mrad": WEDGE_MRAD})
        y, _, _ = render(folder, "backward", RAYS // 2, seed=1)
        profile = y[:, COLUMNS].mean(axis=1)
        above = np.maximum(profile - np.median(profile), 0)
        rows = np.arange(len(profile))
        c = (rows * above).sum() / above.sum()
        widths.append((((rows - c) ** 2) * above).sum() / above.sum())
    a, b, _ = np.polyfit(vergences, widths, 2)
    assert a > 0
    assert -b / (2 * a) == pytest.approx(1e3 / vid, abs=0.03)


def test_a_grid_slide_renders_the_distortion_reported(tmp_path):
    """hud-direct-wedge (one image: the ghost fused) showing the 5 x 3 grid of one-pixel lines at its own 1
    arcmin pixels: every line crossing lies where the analysis's chief ray to the crossing's PGU point
    says, within a pixel, and the crossings depart from the best rectangular grid by the static distortion
    the analysis reports (2.1 mrad, 7 pixels), within a pixel."""
    folder = hud_direct_grid(tmp_path / "g", windshield={"wedge_mrad": WEDGE_MRAD})
    slide = grid_array(240, 80, thickness=1)
    scene = load_scene(folder)
    world = World(scene)
    analysis = Analysis(world)
    # the line crossings' PGU coordinates: texture coordinates to the LCD's plane through its mesh's uv
    lcd = scene.object(analysis.pgu.name)
    design = np.column_stack([lcd.uv, np.ones(len(lcd.uv))])
    affine = np.linalg.lstsq(design, lcd.vertices, rcond=None)[0]  # world = [u, v, 1] @ affine
    cols = [c for c in range(240) if slide[:, c].all()]
    rows = [r for r in range(80) if slide[r].all()]
    assert len(cols) == 5 and len(rows) == 3
    uu, vv = np.meshgrid([(c + 0.5) / 240 for c in cols], [1 - (r + 0.5) / 80 for r in rows])
    world_pts = np.column_stack([uu.ravel(), vv.ravel(), np.ones(uu.size)]) @ affine
    d, ok = analysis.image_directions(analysis.pgu.plane.local(world_pts.T))
    assert ok.all()
    eye = world.eye
    z = eye.gaze @ d
    col = ((eye.focal * (eye.right @ d) / z) / eye.half_x + 1) * eye.width / 2 - 0.5
    row = (1 - (eye.focal * (eye.up @ d) / z) / eye.half_y) * eye.height / 2 - 0.5
    y, _, _ = render(folder, "backward", RAYS, seed=2)
    measured = []
    for c, r in zip(col, row, strict=True):
        ci, ri = int(round(c)), int(round(r))
        # each line's centre in every column (row) of a band either side of the crossing, fitted by a
        # straight line through the lit ones and read at the crossing: the lines tilt near the corners
        h = _line_fit(y, ri, np.r_[ci - 8:ci - 2, ci + 3:ci + 9], c)
        v = _line_fit(y.T, ci, np.r_[ri - 8:ri - 2, ri + 3:ri + 9], r)
        measured.append((v, h))
    measured = np.array(measured)
    error = np.hypot(measured[:, 0] - col, measured[:, 1] - row)
    assert error.max() < 1.0, error
    # the crossings against the best rectangular grid, in mrad (pixels of 1 arcmin on the retina's tangent plane)
    u = np.tile(np.linspace(-1, 1, 5), 3)
    w = np.repeat([1.0, 0.0, -1.0], 5)
    fx, fy = np.polyfit(u, measured[:, 0], 1), np.polyfit(w, measured[:, 1], 1)
    resid = np.hypot(measured[:, 0] - np.polyval(fx, u), measured[:, 1] - np.polyval(fy, w))
    pixel_mrad = 2 * eye.half_x / eye.focal / eye.width * 1e3
    reported = analyse(scene, eyebox=False, compare_mesh=False)["summary"]["design_eye"]["static_distortion_mrad"]
    assert reported > 5 * pixel_mrad
    assert resid.max() * pixel_mrad == pytest.approx(reported, abs=pixel_mrad)
