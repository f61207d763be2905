"""The false-colour luminance view (tracer.products.falsecolour): the log scale through the colour map, the
no-light colour, clamping, the legend's ticks and labels read back from the pixels, and
``hud-trace false-colour`` with its refusals."""

import math
import subprocess
import sys

import numpy as np
import pytest
from conftest import ROOT

from tracer.core.errors import SceneError
from tracer.core.imageio import read_image, srgb_decode, write_exr
from tracer.core.units import luminance
from tracer.products.falsecolour import (
    ADVANCE,
    FONT,
    GLYPH_DESCENT,
    GLYPH_H,
    GLYPH_W,
    NO_LIGHT,
    PAPER,
    VIRIDIS,
    colour_map,
    decade_label,
    false_colour,
    luminance_range,
    read_luminance,
    save_false_colour,
    text_bitmap,
)


def hud_trace(*args):
    return subprocess.run([sys.executable, "-m", "tracer.cli", *map(str, args)], cwd=ROOT, capture_output=True,
                          text=True, timeout=600)


def colour_luminance(rgb8) -> np.ndarray:
    """Rec.709 luminance of sRGB-encoded 8-bit colours (..., 3), relative to white."""
    return luminance(srgb_decode(np.asarray(rgb8, dtype=np.float64) / 255.0))


def ramp(lo_exp: float, hi_exp: float, width: int = 300, height: int = 100) -> np.ndarray:
    return np.tile(np.logspace(lo_exp, hi_exp, width), (height, 1))


def image_part(rgb, info):
    im = info["image"]
    return rgb[im["top"]:im["top"] + im["height"], im["left"]:im["left"] + im["width"]]


def read_text(rgb: np.ndarray, box, scale: int) -> str:
    """Decode the text in ``box`` (top, left, height, width) of ``rgb`` by matching every glyph cell,
    sampled every ``scale`` pixels, against the font's own bitmaps; "?" where none matches."""
    top, left, h, w = box
    ink = np.all(rgb[top:top + h, left:left + w] == 0, axis=2)[::scale, ::scale]
    n = (ink.shape[1] + 1) // ADVANCE
    out = ""
    for i in range(n):
        cell = ink[:, i * ADVANCE:i * ADVANCE + GLYPH_W]
        out += next((ch for ch, bm in FONT.items() if np.array_equal(bm, cell)), "?")
    return out


def test_the_colour_map_rises_in_luminance_and_passes_its_control_points():
    # Strictly rising over 64 steps; over 2000 the 8-bit rounding of one channel (R falls while G
    # and B round to the same level) may take back at most one level's worth, 4e-4 of white.
    y = colour_luminance(colour_map(np.linspace(0, 1, 65)))
    assert np.all(np.diff(y) > 0) and y[-1] > 10 * y[0]
    fine = colour_luminance(colour_map(np.linspace(0, 1, 2001)))
    assert np.diff(fine).min() > -4e-4
    ctrl = colour_luminance(np.rint(VIRIDIS[:, 1:] * 255))
    assert np.all(np.diff(ctrl) > 0)  # strictly, from one control point to the next
    # At each control point the map is the table's entry; halfway between two, their mean (linear).
    x = VIRIDIS[:, 0] / 255
    np.testing.assert_array_equal(colour_map(x), np.rint(VIRIDIS[:, 1:] * 255).astype(np.uint8))
    mid = np.rint(0.5 * (VIRIDIS[1:, 1:] + VIRIDIS[:-1, 1:]) * 255)
    assert np.abs(colour_map(0.5 * (x[1:] + x[:-1])).astype(int) - mid).max() <= 1


def test_a_ramp_is_coloured_by_log10_of_its_luminance():
    """A ramp from 0.1 to 1e4 cd/m^2 on the range [0.1, 1e4]: pixel i shows the map at
    (log10 Y_i + 1) / 5; at Y = 10^(-1 + 5 x_k), x_k a control point, the table's own colour."""
    y = ramp(-1, 4)
    rgb, info = false_colour(y, 0.1, 1e4)
    assert (info["lo"], info["hi"], info["decades"]) == (0.1, 1e4, 5.0) and info["colour_map"] == "viridis"
    k = info["upscale"]
    assert k == 4 and rgb.shape[0] == 400
    img = image_part(rgb, info)
    np.testing.assert_array_equal(img[::k, ::k][0], colour_map((np.log10(y[0]) + 1) / 5))
    # Control points, through the public function alone: a one-pixel image per known luminance.
    x = VIRIDIS[:, 0] / 255
    for xk, entry in zip(x, VIRIDIS[:, 1:], strict=True):
        px, px_info = false_colour(np.array([[10 ** (-1 + 5 * xk)]]), 0.1, 1e4)
        assert np.abs(image_part(px, px_info)[0, 0].astype(int) - np.rint(entry * 255)).max() <= 1
    # Monotonic in Y: brighter pixels never show a darker colour.
    lum = colour_luminance(img[0, ::8 * k])  # 38 steps over the ramp
    assert np.all(np.diff(lum) > 0)


def test_no_light_is_black_and_values_outside_the_range_are_clamped_and_marked():
    y = ramp(0, 2, 60, 40)
    y[:5] = 0.0
    y[5:10] = -3.0  # below zero reads as no light too
    y[10:20, :10] = 0.01  # below lo = 1
    y[20:25, :10] = 1e5  # above hi = 100
    rgb, info = false_colour(y, 1.0, 100.0)
    img = image_part(rgb, info)[::info["upscale"], ::info["upscale"]]
    assert np.all(img[:10] == NO_LIGHT)
    np.testing.assert_array_equal(img[10:20, :10], np.broadcast_to(colour_map(0.0), (10, 10, 3)))
    np.testing.assert_array_equal(img[20:25, :10], np.broadcast_to(colour_map(1.0), (5, 10, 3)))
    assert not np.any(np.all(img[10:] == NO_LIGHT, axis=2))  # lit pixels never take the no-light colour
    assert info["no_light"] == pytest.approx(10 / 40) and info["below"] == pytest.approx(100 / 2400)
    assert info["above"] == pytest.approx(50 / 2400)
    # The legend marks both ends with a cap in the end's colour, and only the ends that were clamped.
    bar = info["legend"]["bar"]
    centre = (bar["left"] + bar["right"]) // 2
    caps = info["legend"]["caps"]
    assert set(caps) == {"below", "above"}
    for end, colour in (("below", colour_map(0.0)), ("above", colour_map(1.0))):
        cap = rgb[caps[end]["top"]:caps[end]["bottom"], bar["left"]:bar["right"]]
        filled = np.all(cap == colour, axis=2)
        assert np.all(filled | np.all(cap == PAPER, axis=2))  # the end's colour on paper, nothing else
        assert filled[:, (bar["right"] - bar["left"]) // 2].sum() >= len(cap) // 2
        widths = filled.sum(axis=1)
        assert np.all(np.diff(widths if end == "below" else widths[::-1]) <= 0)  # narrowing away from the bar
    rgb2, info2 = false_colour(np.clip(y, 1.0, 100.0), 1.0, 100.0)
    assert info2["legend"]["caps"] == {} and info2["below"] == info2["above"] == 0
    assert np.all(rgb2[bar["bottom"]:bar["bottom"] + 4, centre] == PAPER)


def test_the_default_range_runs_from_decade_to_decade_at_most_eight():
    y = ramp(np.log10(3.0), np.log10(4000.0))  # 3 to 4000 cd/m^2: p1 about 3.3
    assert luminance_range(y)[:2] == (1.0, 1e4)
    y[0, 0] = 0.0  # unlit pixels do not count
    assert luminance_range(y)[:2] == (1.0, 1e4)
    wide = ramp(-6, 6)  # 12 decades: the top 8 are kept
    lo, hi, how = luminance_range(wide)
    assert (lo, hi) == (pytest.approx(1e-2), 1e6) and "8 decades" in how
    assert luminance_range(np.full((4, 4), 100.0))[:2] == (10.0, 100.0)
    lo, hi, how = luminance_range(np.zeros((4, 4)))
    assert (lo, hi) == (1.0, 10.0) and "no pixel is lit" in how
    with pytest.raises(ValueError, match="lo"):
        luminance_range(y, lo=1e5)
    with pytest.raises(ValueError, match="hi"):
        luminance_range(y, hi=-1.0)


@pytest.mark.parametrize("shape", [(64, 64), (100, 300), (4000, 60)])
def test_every_decade_tick_sits_at_its_row_of_the_bar_and_reads_as_its_label(shape):
    """Ticks found in the pixels (ink right of the bar) lie within one pixel of the row where the
    log scale puts their decade, which is also (within a pixel) where the bar shows that decade's
    colour; their labels, read back glyph by glyph against the font, are the decades'."""
    h, w = shape
    y = np.tile(np.logspace(-1, 4, h)[::-1, None], (1, w))
    rgb, info = false_colour(y, 0.1, 1e4)
    geo = info["legend"]
    s = geo["scale"]
    bar = geo["bar"]
    # The bar's extent, from its pixels (its first column has no caps).
    coloured = np.any(rgb[:, bar["left"]] != PAPER, axis=1)
    top = int(np.argmax(coloured))
    bottom = top + int(np.argmin(coloured[top:]))  # the first run of colour (the no-light swatch lies below)
    assert (top, bottom) == (bar["top"], bar["bottom"]) and bottom - top > 0.5 * rgb.shape[0]
    # Tick marks: runs of ink just right of the bar.
    ink = np.zeros(rgb.shape[0], bool)  # over the bar's rows and a font pixel beyond (the title is further)
    ink[top - s:bottom + s] = np.all(rgb[top - s:bottom + s, bar["right"]] == 0, axis=1)
    starts = np.flatnonzero(ink & ~np.r_[False, ink[:-1]])
    ends = np.flatnonzero(ink & ~np.r_[ink[1:], False])
    centres = 0.5 * (starts + ends)
    assert len(centres) == 6  # 0.1, 1, 10, 100, 1000, 1e4
    for e, c in zip(range(4, -2, -1), centres, strict=True):
        t = (e + 1) / 5
        assert abs(c - (bottom - t * (bottom - top) - 0.5)) <= 1.0
        bar_col = rgb[top:bottom, (bar["left"] + bar["right"]) // 2].astype(int)
        dist = np.abs(bar_col - colour_map(t).astype(int)).sum(axis=1)
        match = top + np.flatnonzero(dist == dist.min())
        assert match.min() - 1 <= c <= match.max() + 1
    labelled = [tk for tk in geo["ticks"] if tk["labelled"]]
    assert [tk["label"] for tk in labelled] == ["1e4", "1000", "100", "10", "1", "0.1"]
    for tk in labelled:
        assert read_text(rgb, tk["label_box"], s) == tk["label"]
    assert read_text(rgb, geo["title_box"], s) == "cd/m²"
    # Text grows with the image: about 4 % of its height.
    assert 0.02 < GLYPH_H * s / rgb.shape[0] < 0.06 or s == 2


def test_labels_and_the_font():
    assert [decade_label(e) for e in range(-5, 7)] == ["1e-5", "1e-4", "0.001", "0.01", "0.1", "1", "10", "100",
                                                       "1000", "1e4", "1e5", "1e6"]
    bitmaps = [bm.tobytes() for bm in FONT.values()]
    assert len(set(bitmaps)) == len(bitmaps)  # every glyph tells itself apart
    bm = text_bitmap("10", 3)
    assert bm.shape == (3 * (GLYPH_H + GLYPH_DESCENT), 3 * (2 * ADVANCE - 1))
    np.testing.assert_array_equal(bm[::3, :3 * GLYPH_W:3], FONT["1"])
    np.testing.assert_array_equal(bm[::3, 3 * ADVANCE::3], FONT["0"])
    with pytest.raises(ValueError, match="glyph"):
        text_bitmap("Ω")


def test_small_images_are_enlarged_pixel_for_pixel_and_large_ones_are_not():
    y = ramp(0, 3, 300, 100)
    rgb, info = false_colour(y)
    k = info["upscale"]
    img = image_part(rgb, info)
    assert k == 4 and img.shape == (400, 1200, 3)
    blocks = img.reshape(100, k, 300, k, 3)
    assert np.all(blocks == blocks[:, :1, :, :1])  # every block one colour: nearest-neighbour
    for shape, expect in (((4000, 30), 1), ((50, 5000), 1), ((64, 64), 7)):
        assert false_colour(np.ones(shape))[1]["upscale"] == expect


def test_bad_luminance_arrays_are_refused():
    for bad in (np.ones(5), np.ones((0, 4)), np.array([[1.0, np.nan]]), np.array([[1.0, np.inf]])):
        with pytest.raises(ValueError):
            false_colour(bad)


def test_save_writes_the_png_as_a_set(tmp_path):
    y = ramp(-1, 3, 90, 30)
    out = tmp_path / "sub" / "fc.png"
    info = save_false_colour(out, y)
    back = np.rint(read_image(out, linear=True) * 255).astype(np.uint8)
    np.testing.assert_array_equal(back, false_colour(y)[0])
    assert info["lo"] == 0.1 and info["hi"] == 1000.0
    assert sorted(p.name for p in out.parent.iterdir()) == ["fc.png"]  # no staging left behind


def test_luminance_comes_from_y_or_from_rgb(tmp_path):
    rgb = np.random.default_rng(1).random((6, 8, 3)) * 100
    write_exr(tmp_path / "rgb.exr", {"R": rgb[..., 0], "G": rgb[..., 1], "B": rgb[..., 2]})
    np.testing.assert_allclose(read_luminance(tmp_path / "rgb.exr"), luminance(rgb.astype(np.float32)), rtol=1e-6)
    write_exr(tmp_path / "y.exr", {"Y": rgb[..., 0], "R": rgb[..., 1], "G": rgb[..., 1], "B": rgb[..., 1]})
    np.testing.assert_array_equal(read_luminance(tmp_path / "y.exr"), rgb[..., 0].astype(np.float32))
    # a negative luminance is no luminance (an image of -5 cd/m^2 was coloured as if it were dark); the
    # rounding of a denoiser or a colour transform, a millionth of the brightest pixel, is tolerated
    for low, refused in ((-5.0, True), (-1e-5, False)):
        y = rgb[..., 0].copy()
        y[0, 0] = low
        write_exr(tmp_path / "neg.exr", {"Y": y})
        if refused:
            with pytest.raises(SceneError, match="neg.exr.*Y.*negative luminance"):
                read_luminance(tmp_path / "neg.exr")
        else:
            assert read_luminance(tmp_path / "neg.exr")[0, 0] == np.float32(low)


def test_command_line_on_a_render_and_its_refusals(tmp_path):
    render = tmp_path / "r"
    res = hud_trace("render", "analytic-mirror", "--rays", 300_000, "--out", render, "--quiet")
    assert res.returncode == 0, res.stderr
    out = tmp_path / "fc" / "view.png"
    res = hud_trace("false-colour", render / "image.exr", "--out", out)
    assert res.returncode == 0, res.stderr
    y = read_luminance(render / "image.exr")
    expected, info = false_colour(y)
    back = np.rint(read_image(out, linear=True) * 255).astype(np.uint8)
    np.testing.assert_array_equal(back, expected)
    # analytic-mirror reads L R = 850 cd/m^2 where the panel is seen: the top of the range is 1000.
    assert info["hi"] == 1000.0 and math.isclose(y.max(), 850, rel_tol=0.02)
    assert f"{info['lo']:g} to 1000 cd/m^2" in res.stderr

    write_exr(tmp_path / "z.exr", {"Z": np.ones((4, 4)), "A": np.ones((4, 4))})
    (tmp_path / "text.exr").write_text("not an image")
    refused = tmp_path / "refused.png"
    cases = {
        "missing file": ((tmp_path / "nope.exr", "--out", refused), "nope.exr: no such file"),
        "no Y nor RGB": ((tmp_path / "z.exr", "--out", refused), "z.exr: channels: has no Y channel"),
        "not an EXR": ((render / "preview.png", "--out", refused), "preview.png: is not an OpenEXR file"),
        "text file": ((tmp_path / "text.exr", "--out", refused), "text.exr: is not an OpenEXR file"),
        "min >= max": ((render / "image.exr", "--out", refused, "--min", 100, "--max", 100), "--min: 100 cd/m^2"),
        "min above the image": ((render / "image.exr", "--out", refused, "--min", 1e5),
                                "--min: 100000 cd/m^2 is not below"),
        "negative max": ((render / "image.exr", "--out", refused, "--max", -1), "--max: must be"),
        "not a png": ((render / "image.exr", "--out", tmp_path / "x.jpg"), "--out: must name a .png"),
        "out is a folder": ((render / "image.exr", "--out", tmp_path / "dir.png"), "dir.png: exists and is not a file"),
    }
    (tmp_path / "dir.png").mkdir()
    before = sorted(p.name for p in tmp_path.iterdir())
    for case, (args, message) in cases.items():
        res = hud_trace("false-colour", *args)
        assert res.returncode == 2, (case, res.stderr)
        lines = res.stderr.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith("error: ") and message in lines[0], (case, res.stderr)
    assert sorted(p.name for p in tmp_path.iterdir()) == before and not any((tmp_path / "dir.png").iterdir())
