"""The eyebox scan (tracer.scans.eyebox): a scene whose eyebox has a closed form, the design-eye value
against the brightness theorem's prediction, the CSV round trip, the chart, a scene the analysis
cannot predict, and ``hud-trace eyebox`` with its refusals."""

import json
import math
import subprocess
import sys

import numpy as np
import pytest

from presets._build import SceneBuilder, frame_bars, frame_matrix, rectangle
from tests.support.paths import ROOT
from tracer.analysis.brightness import brightness_theorem
from tracer.core.imageio import read_image, write_png
from tracer.products.charts import THRESHOLD, colours
from tracer.scans.eyebox import (
    FIELD_POINTS,
    FieldNotFound,
    ScanArgumentError,
    display_field,
    eyebox_chart,
    eyebox_scan,
    read_csv,
    write_csv,
)
from tracer.scene import load_scene
from tracer.transport.world import World

#: The framed-LCD scene: an emitter panel (luminance L cd/m^2) seen through an LCD (transmittance T,
#: contrast CR, half-sizes A mm, its slide black in a middle band) in an absorbing frame, both below
#: a flat 45-degree mirror (reflectance R). Unfolded by the mirror, the eye looks along +y at the
#: LCD D_LCD mm away and the panel D_EYE mm away, where the eye is focused and the field points lie.
L, R, T, CR = 1000.0, 0.85, 0.5, 100.0
A = (52.0, 27.0)
D_LCD, D_EYE, MIRROR_Y = 400.0, 600.0, 200.0


def framed_lcd_scene(folder, accommodation_mm=D_EYE):
    sb = SceneBuilder(folder, "framed-lcd", "an emitter seen through a framed LCD in a flat mirror")
    sb.add("mirror", rectangle(400, 400), {"type": "mirror", "reflectance": R},
           frame_matrix([0.0, MIRROR_Y, 0.0], [1, 0, 0], [0, -1, -1]))
    slide = np.full((10, 20, 3), 255, np.uint8)
    slide[:, 8:12] = 0  # black cells across the middle: the scan must clear them
    (folder / "textures").mkdir(parents=True)
    write_png(folder / "textures" / "slide.png", slide)
    lcd = frame_matrix([0.0, MIRROR_Y, MIRROR_Y - D_LCD], [1, 0, 0], [0, 0, 1])
    v, f, uv = rectangle(2 * A[0], 2 * A[1])
    sb.add("lcd", (v, f), {"type": "lcd", "image": "textures/slide.png", "transmittance": T, "contrast_ratio": CR},
           lcd, uv=uv)
    frame_bars(sb, "frame", (2 * A[0], 2 * A[1]), 200.0, lcd)
    sb.add("panel", rectangle(800, 800), {"type": "absorber"},
           frame_matrix([0.0, MIRROR_Y, MIRROR_Y - D_EYE], [1, 0, 0], [0, 0, 1]), emission={"luminance": L})
    return sb.write(eye={"position": [0, 0, 0], "gaze": [0, 1, 0], "up": [0, 0, 1], "pupil_diameter_mm": 4.0,
                         "focal_length_mm": 16.67, "accommodation_distance_mm": accommodation_mm,
                         "resolution": [128, 96],
                         "fov_deg": [30.0, 22.5]})


def hud_trace(*args):
    return subprocess.run([sys.executable, "-m", "tracer.cli", *map(str, args)], cwd=ROOT, capture_output=True,
                          text=True, timeout=600)


@pytest.fixture(scope="module")
def framed(tmp_path_factory):
    folder = framed_lcd_scene(tmp_path_factory.mktemp("framed") / "scene")
    world = World(load_scene(folder))
    return folder, world, eyebox_scan(world, half_mm=(45, 24), step_mm=3)


@pytest.mark.parametrize("focus", ["600 mm", "infinity"])
def test_the_eyebox_of_a_framed_lcd_follows_from_similar_triangles(framed, tmp_path, focus):
    """From an eye moved by o, the chief ray toward a field point of tangent tau (fixed at the
    accommodation distance s) crosses the LCD's plane at o (1 - D_LCD / s) + tau D_LCD; the point
    stays lit while that lies within the LCD's half-size a, so the eyebox spans
    o in [-(a + tau_min D_LCD), a - tau_max D_LCD] / (1 - D_LCD / s). At infinite focus the field
    points are directions, and 1 - D_LCD / s is 1."""
    if focus == "600 mm":
        _, world, r = framed
        s_mm = D_EYE
    else:
        world = World(load_scene(framed_lcd_scene(tmp_path / "s", "infinity")))
        r = eyebox_scan(world, half_mm=(30, 12), step_mm=2)
        s_mm = math.inf
    # The field found from the scene: the LCD's angular extent, each edge within half a pixel.
    eye = world.eye
    cell = np.array([eye.pixel_w, eye.pixel_h]) / eye.focal
    f = r.field
    assert f.from_scene
    for ax in (0, 1):
        assert abs(f.centre[ax]) < 1e-9
        assert abs(f.half[ax] - A[ax] / D_LCD) <= 0.5 * cell[ax] + 1e-9
    tau = r.field_points
    k = 1 - D_LCD / s_mm
    fig = r.figures()
    step = float(r.right_mm[1] - r.right_mm[0])
    for ax, (lo_name, hi_name, extent) in enumerate((("left", "right", "width_mm"), ("bottom", "top", "height_mm"))):
        lo = -(A[ax] + tau[:, ax].min() * D_LCD) / k
        hi = (A[ax] - tau[:, ax].max() * D_LCD) / k
        assert abs(fig["edges_mm"][lo_name] - lo) <= step / 2 + 1e-9
        assert abs(fig["edges_mm"][hi_name] - hi) <= step / 2 + 1e-9
        assert abs(fig[extent] - (hi - lo)) <= step
    # With tau_max - tau_min = 1.6 a / D_LCD (the corners at 80 % of the LCD's half-field): (2a - 1.6a) / k,
    # about 62 x 32 mm at s = 600 mm and 21 x 11 mm at infinity.
    assert np.allclose([fig["width_mm"], fig["height_mm"]], 0.4 * np.array(A) / k, atol=step + 4)
    assert not fig["reaches_scan_edge"]
    # Inside, every field point sees the panel through the clear LCD: L R T; outside, one sees the frame.
    lum = r.luminance_cd_m2
    assert np.all(np.isclose(lum, L * R * T, rtol=1e-6) | (lum == 0))
    np.testing.assert_allclose(r.design_cd_m2, L * R * T, rtol=1e-6)
    inside = np.all(lum > 0, axis=2)
    np.testing.assert_array_equal(r.inside, inside)
    np.testing.assert_array_equal(r.region, inside)  # one rectangle around the design eye
    assert fig["uniformity"] == {"design_eye": 1.0, "eyebox": 1.0, "eyebox_min_at": fig["uniformity"]["eyebox_min_at"]}
    assert fig["field_average_cd_m2"]["min"] == pytest.approx(L * R * T, rel=1e-6)
    # Each grid point's verdict agrees with the closed form (points within 1e-6 mm of an edge aside).
    xs, zs = np.meshgrid(r.right_mm, r.up_mm)
    ok = np.ones(xs.shape, bool)
    for ax, o in enumerate((xs, zs)):
        lo = -(A[ax] + tau[:, ax].min() * D_LCD) / k
        hi = (A[ax] - tau[:, ax].max() * D_LCD) / k
        ok &= (o >= lo) & (o <= hi)
    np.testing.assert_array_equal(r.inside, ok)


def test_the_design_eye_value_is_the_brightness_theorems_prediction(framed):
    """tracer.analysis.brightness.brightness_theorem predicts the clear cells ("symbol") at L R T over the pupil;
    the scan, which clears every cell, reads the same at the design eye for every field point
    (the black band at the centre of the slide included)."""
    _, world, r = framed
    h, w = world.eye.height, world.eye.width
    bt = brightness_theorem(world, np.zeros((h, w)), np.zeros((h, w)))
    assert bt["valid"]
    sym = bt["symbol"]
    assert sym["predicted_cd_m2"] == pytest.approx(L * R * T, rel=1e-6)
    tol = 3 * sym["predicted_standard_error_cd_m2"] + 1e-6 * sym["predicted_cd_m2"]
    assert np.all(np.abs(r.design_cd_m2 - sym["predicted_cd_m2"]) <= tol)
    assert bt["background"]["predicted_cd_m2"] == pytest.approx(L * R * T / CR, rel=1e-6)


def test_the_csv_round_trips(framed, tmp_path):
    _, _, r = framed
    path = tmp_path / "out" / "eyebox.csv"
    write_csv(r, path)
    back = read_csv(path)
    np.testing.assert_array_equal(back["right_mm"], r.right_mm)
    np.testing.assert_array_equal(back["up_mm"], r.up_mm)
    np.testing.assert_array_equal(back["luminance_cd_m2"], r.luminance_cd_m2)
    np.testing.assert_array_equal(back["inside"], r.inside)
    lines = path.read_text().splitlines()
    assert lines[0] == "right_mm,up_mm," + ",".join(f"{n.replace(' ', '_')}_cd_m2" for n, _, _ in FIELD_POINTS) + \
        ",inside"
    assert len(lines) == 1 + r.right_mm.size * r.up_mm.size
    assert sorted(p.name for p in path.parent.iterdir()) == ["eyebox.csv"]


def _rgb(hex_colour: str) -> np.ndarray:
    return np.array([int(hex_colour[k:k + 2], 16) for k in (1, 3, 5)])


def test_the_chart_shows_each_offsets_relative_luminance_the_outline_and_the_design_eye(framed):
    """At every offset's centre the map shows the colour of its relative luminance; every edge between a
    cell inside the eyebox and one outside is drawn red, no cell centre but the design eye's is."""
    _, _, r = framed
    rgb, geo = eyebox_chart(r)
    cols, rows = geo["cells"]["right_mm"], geo["cells"]["up_mm"]
    region = r.region
    ny, nx = region.shape

    def at(x, y):
        return rgb[int(round(y)), int(round(x))].astype(int)

    centres = np.array([[at(cols[i], rows[j]) for i in range(nx)] for j in range(ny)])
    expected = colours(r.relative / geo["top_of_scale"]).astype(int)
    j0, i0 = r.design_index
    off = np.ones(region.shape, bool)
    off[j0, i0] = False  # the design eye's cross covers its centre
    assert np.abs(centres[off] - expected[off]).max() <= 1
    red = _rgb(THRESHOLD)
    assert np.abs(centres[j0, i0] - red).max() <= 40
    assert not np.any(np.all(np.abs(centres[off] - red) <= 40, axis=-1))
    edges = 0
    for j in range(ny):
        for i in range(nx - 1):
            if region[j, i] != region[j, i + 1]:
                assert np.abs(at((cols[i] + cols[i + 1]) / 2, rows[j]) - red).max() <= 40, (j, i)
                edges += 1
    for j in range(ny - 1):
        for i in range(nx):
            if region[j, i] != region[j + 1, i]:
                assert np.abs(at(cols[i], (rows[j] + rows[j + 1]) / 2) - red).max() <= 40, (j, i)
                edges += 1
    assert edges >= 4


@pytest.mark.slow
def test_a_screen_lit_through_a_projection_lens_is_scanned_with_a_photon_map(preset):
    """hud-screen's rear-projection screen receives its light through the projection lens, which the
    analysis' quadrature does not follow. Issue 31: its eyebox was a chart of zeros marked "not
    valid", after asking for --field. A photon map follows that light now: the field is found where
    the eye sees the lit screen, and the scan is valid with each value's standard error. Without
    photons the result is flagged, with the reason, and gives no figures, as before."""
    world = World(load_scene(preset("hud-screen")))
    with pytest.raises(FieldNotFound, match="field"):
        display_field(world)
    r = eyebox_scan(world, half_mm=(10, 5), step_mm=5, field_deg=(6, 2), photons=0)
    assert not r.valid and r.figures() is None and not r.inside.any() and r.photon_map is None
    assert any("projection_lens" in reason and "screen" in reason for reason in r.reasons)
    assert r.specular_blockers == {"screen": ["projection_lens"]}
    assert np.all(r.through_specular_cd_m2 > 0) and json.dumps(r.summary())
    assert r.summary()["valid"] is False

    r = eyebox_scan(world, half_mm=(10, 5), step_mm=5, photons=1_000_000, seed=3)
    assert r.valid and r.reasons == [] and r.figures() is not None, r.reasons
    assert r.field.from_scene and 3 < r.field.deg[0] < 7 and 1 < r.field.deg[1] < 2.6  # within the eye's 7 x 2.6 deg
    assert np.all(r.through_specular_cd_m2 == 0) and np.all(r.design_cd_m2 > 0)
    rel = r.photon_se_cd_m2[r.design_index] / r.design_cd_m2
    assert np.all(rel < 0.1), rel
    summary = json.loads(json.dumps(r.summary()))
    assert summary["photon_map"]["photons_emitted"] == 1_000_000 and summary["photon_map"]["seed"] == 3
    assert summary["photon_map"]["radius_mm"] > 0 and "photon map" in summary["method"]


@pytest.mark.slow
@pytest.mark.parametrize("baffle", [True, False], ids=["through the mirror alone", "and directly"])
def test_a_screen_lit_through_a_mirror_fold_reads_what_its_mirror_image_gives(tmp_path, baffle):
    """A screen lit only through a mirror (an absorbing baffle blocks the emitter's direct view: the
    quadrature sees no specular blocker, so a pilot photon map finds the light) against the same
    light from the emitter's mirror image with rho x its luminance, which the quadrature follows
    directly (a second method). Without the baffle the screen sees the emitter directly too: the
    quadrature gives that light and the photons (stored after their first event) the mirror's, and
    the second method has the emitter beside its image, so light counted twice would show. Every eye
    offset and field point agrees within the photon map's standard error (alpha 0.01, Sidak over the
    comparisons); field points that fall off the screen read 0 in both."""
    from tests.support.scenes import folded_screen_scene
    from tests.support.stats import z_bound

    scan = dict(half_mm=(40, 20), step_mm=20, field_deg=(6, 6))
    folded = eyebox_scan(World(load_scene(folded_screen_scene(tmp_path / "fold", baffle=baffle))),
                         photons=4_000_000, seed=1, **scan)
    image = eyebox_scan(World(load_scene(folded_screen_scene(tmp_path / "image", image=True, baffle=baffle))), **scan)
    assert image.photon_map is None and image.valid
    assert folded.photon_map is not None and folded.valid, folded.reasons
    a, b, se = folded.luminance_cd_m2, image.luminance_cd_m2, folded.photon_se_cd_m2
    np.testing.assert_array_equal(a == 0, b == 0)
    lit = b > 0
    assert lit.sum() >= 50
    z = np.abs(a[lit] - b[lit]) / se[lit]
    assert z.max() < z_bound(int(lit.sum())), (z.max(), a[lit], b[lit])
    assert np.all(se[lit] < 0.1 * b[lit])


def test_arguments_out_of_range_are_refused_before_any_ray(framed):
    _, world, _ = framed
    for kw, arg in ((dict(step_mm=0), "step_mm"), (dict(step_mm=math.nan), "step_mm"),
                    (dict(half_mm=(-1, 5)), "half_mm"), (dict(half_mm=(1000, 1000), step_mm=1), "step_mm"),
                    (dict(field_deg=(0, 2)), "field_deg"), (dict(threshold=1.5), "threshold"),
                    (dict(threshold=0), "threshold"),
                    # the design eye alone, "eyebox 0.0 x 0.0 mm" with exit 0 (a mm-cm slip; hand-built input)
                    (dict(step_mm=100), "step_mm"), (dict(half_mm=(0, 0)), "half_mm")):
        with pytest.raises(ScanArgumentError) as e:
            eyebox_scan(world, **kw)
        assert e.value.argument == arg


@pytest.mark.slow
def test_command_line_writes_the_set_and_refuses_bad_input(framed, tmp_path):
    folder, _, r = framed
    out = tmp_path / "eb"
    res = hud_trace("eyebox", folder, "--out", out, "--half", 45, 24, "--step", 3, "--quiet")
    assert res.returncode == 0, res.stderr
    assert sorted(p.name for p in out.iterdir()) == ["eyebox.csv", "eyebox.json", "eyebox.png"]
    summary = json.loads((out / "eyebox.json").read_text())
    assert summary["valid"] and summary["figures"] == json.loads(json.dumps(r.figures()))
    assert summary["field"]["from_scene"] is True
    np.testing.assert_array_equal(read_csv(out / "eyebox.csv")["luminance_cd_m2"], r.luminance_cd_m2)
    png = np.rint(read_image(out / "eyebox.png", linear=True) * 255).astype(np.uint8)
    np.testing.assert_array_equal(png, eyebox_chart(r)[0])
    assert f"eyebox {r.figures()['width_mm']:.1f} x {r.figures()['height_mm']:.1f} mm" in res.stderr

    (tmp_path / "file").write_text("x")
    cases = {
        "step zero": ((folder, "--step", 0), "--step: must be"),
        "negative half": ((folder, "--half", -5, 10), "--half: two half-widths"),
        "too many offsets": ((folder, "--half", 500, 500, "--step", 0.5), "--step: 0.5 mm"),
        "threshold": ((folder, "--threshold", 1.5), "--threshold: must lie in (0, 1]"),
        "step longer than the scan": ((folder, "--step", 100), "--step: 100 mm is longer than both half-widths"),
        "field": ((folder, "--field", 0, 2), "--field: two angles"),
        "unknown scene": (("no-such-preset",), "no-such-preset: neither a scene folder nor a preset"),
        "no LCD in view": (("analytic-mirror",), "--field: the display field cannot be found"),
        "out is a file": ((folder, "--out", tmp_path / "file"), "file: exists and is not a folder"),
        "photons": ((folder, "--photons", -1), "--photons: a whole number of particles in [0, 100,000,000]"),
        "seed": ((folder, "--seed", -1), "--seed: must be a whole number in [0, 2^63)"),
    }
    for case, (args, message) in cases.items():
        target = tmp_path / "refused"
        res = hud_trace("eyebox", *args, *(() if "--out" in args else ("--out", target)), "--quiet")
        assert res.returncode == 2, (case, res.stderr)
        lines = res.stderr.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith("error: ") and message in lines[0], (case, res.stderr)
        assert not target.exists(), case
    res = hud_trace("eyebox", "hud-screen", "--field", 6, 2, "--half", 5, 5, "--step", 5, "--out", tmp_path / "scr",
                    "--photons", 0, "--quiet")
    assert res.returncode == 3 and "not valid" in res.stderr and "projection_lens" in res.stderr
    assert json.loads((tmp_path / "scr" / "eyebox.json").read_text())["valid"] is False


def test_a_backlight_closer_than_the_quadrature_resolves_is_not_scanned(tmp_path):
    """A screen (Lambertian transmitter) 1 mm over a 200 mm panel, seen from 500 mm: the analysis'
    quadrature (cells of 71 mm) predicts it 4.7 times too bright there (tests/analysis/test_brightness.py), so
    the scan says it cannot predict the scene, with the reason; 600 mm over the panel it can."""
    valid = {}
    for gap in (1.0, 600.0):
        sb = SceneBuilder(tmp_path / f"g{gap:g}", "backlight", "a screen over a panel")
        sb.add("screen", rectangle(600.0, 600.0)[:2], {"type": "lambertian_transmitter", "transmittance": 0.5})
        sb.add("panel", rectangle(200.0, 200.0)[:2], {"type": "absorber"},
               frame_matrix([0, 0, -gap], [1, 0, 0], [0, 0, 1]), emission={"luminance": 1000.0})
        folder = sb.write(eye={"position": [0.0, 0.0, 500.0], "gaze": [0, 0, -1], "up": [0, 1, 0],
                               "pupil_diameter_mm": 4.0, "accommodation_distance_mm": 500.0,
                               "resolution": [16, 16], "fov_deg": [2.0, 2.0]})
        r = eyebox_scan(World(load_scene(folder)), half_mm=(4, 4), step_mm=2, field_deg=(1, 1))
        valid[gap] = r.valid
        if not r.valid:
            assert any("closer to the scattering surfaces than the analysis' quadrature resolves" in x
                       for x in r.reasons), r.reasons
    assert valid == {1.0: False, 600.0: True}
