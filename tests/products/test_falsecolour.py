"""The false-colour luminance view (tracer.products.falsecolour): the log scale through the colour map, the
no-light colour, clamping, the colour bar's ticks at the rows that show their values' colours (also
inside a range narrower than a decade), and ``hud-trace false-colour`` with its refusals."""

import math
import subprocess
import sys

import numpy as np
import pytest

from tests.support.paths import ROOT
from tracer.core.errors import SceneError
from tracer.core.imageio import read_image, read_luminance, srgb_decode, write_exr
from tracer.core.units import luminance
from tracer.products.charts import colours, value_label
from tracer.products.falsecolour import NO_LIGHT, false_colour, legend_ticks, luminance_range, save_false_colour


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


def test_the_colour_map_rises_in_luminance_from_end_to_end():
    """Viridis: brighter always reads brighter (its 256 entries' luminance rises, within the 8-bit
    rounding of one channel), from a dark blue to a light yellow ten times as bright."""
    y = colour_luminance(colours(np.linspace(0, 1, 65)))
    assert np.all(np.diff(y) > 0) and y[-1] > 10 * y[0]
    fine = colour_luminance(colours(np.arange(256) / 256))
    assert np.diff(fine).min() > -4e-4
    assert not np.any(np.all(colours(np.linspace(0, 1, 256)) == NO_LIGHT, axis=-1))  # no-light is no map colour


def test_a_ramp_is_coloured_by_log10_of_its_luminance():
    """A ramp from 0.1 to 1e4 cd/m^2 on the range [0.1, 1e4]: pixel i shows the map at
    (log10 Y_i + 1) / 5, brighter pixels never a darker colour."""
    y = ramp(-1, 4)
    rgb, info = false_colour(y, 0.1, 1e4)
    assert (info["lo"], info["hi"], info["decades"]) == (0.1, 1e4, 5.0) and info["colour_map"] == "viridis"
    k = info["upscale"]
    assert k == 4 and rgb.shape[0] >= 400
    img = image_part(rgb, info)
    np.testing.assert_array_equal(img[::k, ::k][0], colours((np.log10(y[0]) + 1) / 5))
    for value, t in ((0.1, 0.0), (10.0, 0.4), (1e4, 1.0)):  # one-pixel images of known luminance
        px, px_info = false_colour(np.array([[value]]), 0.1, 1e4)
        np.testing.assert_array_equal(image_part(px, px_info)[0, 0], colours(t))
    lum = colour_luminance(img[0, ::8 * k])  # 38 steps over the ramp
    assert np.all(np.diff(lum) > 0)


def _bar_column(rgb, info):
    bar = info["legend"]["bar"]
    return rgb[:, (bar["left"] + bar["right"]) // 2].astype(int)


def test_no_light_is_black_and_values_outside_the_range_are_clamped_and_marked():
    y = ramp(0, 2, 60, 40)
    y[:5] = 0.0
    y[5:10] = -3.0  # below zero reads as no light too
    y[10:20, :10] = 0.01  # below lo = 1
    y[20:25, :10] = 1e5  # above hi = 100
    rgb, info = false_colour(y, 1.0, 100.0)
    img = image_part(rgb, info)[::info["upscale"], ::info["upscale"]]
    assert np.all(img[:10] == NO_LIGHT)
    np.testing.assert_array_equal(img[10:20, :10], np.broadcast_to(colours(0.0), (10, 10, 3)))
    np.testing.assert_array_equal(img[20:25, :10], np.broadcast_to(colours(1.0), (5, 10, 3)))
    assert not np.any(np.all(img[10:] == NO_LIGHT, axis=2))  # lit pixels never take the no-light colour
    assert info["no_light"] == pytest.approx(10 / 40) and info["below"] == pytest.approx(100 / 2400)
    assert info["above"] == pytest.approx(50 / 2400)
    # Both ends are marked: the bar continues beyond its box in the end's colour (matplotlib's extension
    # triangles), and only where values were clamped.
    assert info["legend"]["caps"] == ["below", "above"]
    bar, col = info["legend"]["bar"], _bar_column(rgb, info)
    for rows, end in ((range(bar["bottom"] + 2, bar["bottom"] + 6), 0.0), (range(bar["top"] - 6, bar["top"] - 2), 1.0)):
        assert all(np.abs(col[r] - colours(end)).max() <= 2 for r in rows), end
    rgb2, info2 = false_colour(np.clip(y, 1.0, 100.0), 1.0, 100.0)
    assert info2["legend"]["caps"] == [] and info2["below"] == info2["above"] == 0
    bar2, col2 = info2["legend"]["bar"], _bar_column(rgb2, info2)
    assert all(np.all(col2[r] == 255) for r in range(bar2["bottom"] + 2, bar2["bottom"] + 6))  # paper, no cap


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


def test_ticks_let_a_value_be_read_off_the_bar_at_every_span():
    """Decades over three or more; 1, 2, 5 times them over one to three; even steps inside a decade."""
    assert legend_ticks(0.1, 1e4) == [0.1, 1.0, 10.0, 100.0, 1000.0, 1e4]
    assert legend_ticks(10, 1000) == [10, 20, 50, 100, 200, 500, 1000]
    assert legend_ticks(7000, 9000) == [7000, 7500, 8000, 8500, 9000]
    assert legend_ticks(31.2, 38.7) == [32, 34, 36, 38]
    for lo, hi in ((0.1, 1e4), (10, 1000), (7000, 9000), (31.2, 38.7), (1e-3, 4e-3)):
        ticks = legend_ticks(lo, hi)
        assert len(ticks) >= 3 and all(lo <= t <= hi for t in ticks), (lo, hi, ticks)


@pytest.mark.parametrize("shape,lo,hi", [((64, 64), 0.1, 1e4), ((100, 300), 0.1, 1e4), ((4000, 60), 0.1, 1e4),
                                         ((100, 300), 7000.0, 9000.0)])
def test_every_tick_sits_at_the_row_of_the_bar_that_shows_its_value(shape, lo, hi):
    """A tick's row on the bar shows the colour its value is given in the image (to a pixel), a tick
    mark is drawn there just right of the bar, and its label is the value's; the bar's colours run
    from the bottom of the range to its top."""
    h, w = shape
    y = np.tile(np.logspace(math.log10(lo), math.log10(hi), h)[::-1, None], (1, w))
    rgb, info = false_colour(y, lo, hi)
    geo = info["legend"]
    bar, col = geo["bar"], _bar_column(rgb, info)
    assert bar["bottom"] - bar["top"] > 0.5 * rgb.shape[0]
    inner = slice(bar["top"] + 2, bar["bottom"] - 2)  # inside the bar's frame
    np.testing.assert_allclose(col[inner][0], colours(1.0), atol=4)
    np.testing.assert_allclose(col[inner][-1], colours(0.0), atol=4)
    assert [tk["label"] for tk in geo["ticks"]] == [value_label(v) for v in legend_ticks(lo, hi)]
    for tk in geo["ticks"]:
        t = math.log10(tk["value"] / lo) / math.log10(hi / lo)
        if 1e-9 < t < 1 - 1e-9:
            dist = np.abs(col[inner] - colours(t).astype(int)).sum(axis=1)
            match = inner.start + np.flatnonzero(dist == dist.min())
            assert match.min() - 1.5 <= tk["row"] <= match.max() + 1.5, (tk, match)
        else:  # a tick at an end sits on the bar's frame, whose colour is the frame's: within a pixel of it
            assert abs(tk["row"] - (bar["bottom"] if t < 0.5 else bar["top"])) <= 1.0, (tk, bar)
        r = int(round(tk["row"]))
        mark = rgb[r - 1:r + 2, bar["right"] + 1:bar["right"] + 4]
        assert mark.min() < 100, tk  # ink of the tick mark beside the bar


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


@pytest.mark.slow
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


def test_the_view_of_an_image_with_no_lit_pixel_says_so(tmp_path):
    """A second walk-through: an all-black EXR gave exit 0 and "1 to 10 cd/m^2 (1 decades)", a black
    picture with nothing said. It is written, and exit 3 with a warning says no pixel is lit."""
    from tests.support.cli import run_cli
    from tracer import cli

    write_exr(tmp_path / "black.exr", {"Y": np.zeros((8, 12))})
    code, err = run_cli("false-colour", tmp_path / "black.exr", "--out", tmp_path / "view.png")
    assert code == cli.EXIT_NO_LIGHT == 3 and "warning: no pixel of the image is lit" in err, err
    assert (tmp_path / "view.png").is_file()
