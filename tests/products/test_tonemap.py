"""Tests of tracer.products.tonemap: the adaptation luminance, log-average luminance, Ward's scale factor,
the 8-bit preview."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tracer.core.imageio import srgb_decode
from tracer.core.units import luminance
from tracer.products.tonemap import adaptation_luminance, log_average_luminance, tonemap_ward, ward_scale_factor


def test_adaptation_luminance_is_the_log_average_or_the_mean_of_the_lit_pixels():
    y = np.array([[0.0, 10.0], [100.0, 1000.0]])
    assert adaptation_luminance(y, "mean") == pytest.approx(370.0)
    assert adaptation_luminance(y, "log_average") == pytest.approx(100.0, rel=1e-5)  # exp(mean(ln L))
    assert math.isclose(adaptation_luminance(np.zeros((2, 2)), "mean"), 0.0)


def _grey(Y) -> np.ndarray:
    """Neutral RGB (H, W, 3) whose luminance is ``Y`` (H, W) cd/m^2 (R = G = B = Y)."""
    return np.repeat(np.asarray(Y, dtype=np.float64)[..., None], 3, axis=-1)


def test_log_average_luminance_values():
    delta = 1e-4
    expected = math.exp((math.log(delta + 1.0) + math.log(delta + 100.0)) / 2)
    assert log_average_luminance(np.array([[1.0, 100.0]])) == pytest.approx(expected, rel=1e-14)
    assert log_average_luminance(np.full((3, 4), 42.0)) == pytest.approx(42.0 + delta, rel=1e-14)


def test_log_average_luminance_of_black_image_is_delta():
    assert log_average_luminance(np.zeros((4, 4))) == pytest.approx(1e-4, rel=1e-14)
    assert log_average_luminance(np.zeros((4, 4)), delta=0.5) == pytest.approx(0.5, rel=1e-14)


def test_log_average_luminance_ignores_non_finite_values():
    Y = np.array([[1.0, np.nan], [np.inf, -np.inf]])
    assert log_average_luminance(Y) == pytest.approx(1.0 + 1e-4, rel=1e-14)
    assert log_average_luminance(np.full((2, 2), np.nan)) == pytest.approx(1e-4)


def test_log_average_luminance_rejects_bad_input():
    with pytest.raises(ValueError):
        log_average_luminance(np.array([[1.0, -1.0]]))
    with pytest.raises(ValueError):
        log_average_luminance(np.ones((2, 2)), delta=0.0)


def test_ward_scale_factor_hand_computed():
    # L_wa = 1 cd/m^2, L_dmax = 100 cd/m^2, so L_da = 50: 1 ** 0.4 = 1, 50 ** 0.4 = 4.781762,
    # m = ((1.219 + 4.781762) / (1.219 + 1)) ** 2.5 = 2.704264 ** 2.5 = 12.02605.
    assert ward_scale_factor(1.0) == pytest.approx(12.02605, rel=1e-6)
    # L_wa = L_da: the eye is adapted as the display's viewer is, m = 1.
    assert ward_scale_factor(50.0) == pytest.approx(1.0, rel=1e-15)
    assert ward_scale_factor(250.0, L_dmax=500.0) == pytest.approx(1.0, rel=1e-15)


def test_ward_scale_factor_rejects_bad_input():
    for L_wa, L_dmax in [(-1.0, 100.0), (math.nan, 100.0), (1.0, 0.0), (1.0, math.inf)]:
        with pytest.raises(ValueError):
            ward_scale_factor(L_wa, L_dmax)


def test_tonemap_uses_log_average_and_ward_factor():
    rgb = _grey(np.array([[1.0, 10.0], [100.0, 5.0]]))
    png, info = tonemap_ward(rgb)
    L_wa = log_average_luminance(luminance(rgb))
    assert info["adaptation_luminance"] == pytest.approx(L_wa, rel=1e-15)
    assert info["scale_factor"] == pytest.approx(ward_scale_factor(L_wa), rel=1e-15)
    assert info["display_max_luminance"] == 100.0
    display = np.minimum(rgb * info["scale_factor"] / 100.0, 1.0)
    expected = np.rint(255 * np.where(display <= 0.0031308, 12.92 * display,
                                      1.055 * display ** (1 / 2.4) - 0.055))
    np.testing.assert_array_equal(png, expected.astype(np.uint8))


def test_tonemap_given_adaptation_luminance():
    rgb = _grey(np.full((2, 2), 20.0))
    png, info = tonemap_ward(rgb, adaptation_luminance=50.0)  # m = 1: display value 0.2
    assert info["adaptation_luminance"] == 50.0
    assert info["scale_factor"] == pytest.approx(1.0)
    assert np.all(png == round(255 * (1.055 * 0.2 ** (1 / 2.4) - 0.055)))


def test_tonemap_clipping_report():
    Y = np.full((10, 10), 1.0)
    Y[0, :3] = 1e6  # three very bright pixels
    rgb = _grey(Y)
    rgb[1, 0] = [1e6, 0.0, 0.0]  # one saturated red pixel: only R is over white
    png, info = tonemap_ward(rgb)
    assert info["clipped_fraction"] == pytest.approx(4 / 100)
    assert "clipped at display white" in info["clipping"]
    assert "L_dmax = 100 cd/m^2" in info["clipping"]
    assert np.all(png[0, :3] == 255)
    assert png[1, 0, 0] == 255 and png[1, 0, 1] == 0 and png[1, 0, 2] == 0


def test_tonemap_is_deterministic():
    rgb = np.random.default_rng(3).random((16, 16, 3)) * 300.0
    png1, info1 = tonemap_ward(rgb)
    png2, info2 = tonemap_ward(rgb.copy())
    np.testing.assert_array_equal(png1, png2)
    assert info1 == info2


def test_tonemap_preserves_ratios_below_white():
    # With L_wa = 50 (m = 1), 20 and 60 cd/m^2 show as display values 0.2 and 0.6 (ratio 3).
    rgb = _grey(np.array([[20.0, 60.0]]))
    png, info = tonemap_ward(rgb, adaptation_luminance=50.0)
    assert info["clipped_fraction"] == 0.0
    shown = srgb_decode(png[0, :, 1] / 255.0)
    # Half an 8-bit code is about 1 % of 0.2 after sRGB decoding: the only error is rounding.
    assert shown[1] / shown[0] == pytest.approx(3.0, rel=0.02)
    # The same holds with the default (log-average) adaptation for any ratio below white.
    rgb = _grey(np.array([[1.0, 4.0, 0.5]]))
    png, info = tonemap_ward(rgb)
    display = 1.0 * info["scale_factor"] / 100.0
    assert info["clipped_fraction"] == 0.0 and 4 * display < 1.0
    shown = srgb_decode(png[0, :, 1] / 255.0)
    assert shown[1] / shown[0] == pytest.approx(4.0, rel=0.02)
    assert shown[0] / shown[2] == pytest.approx(2.0, rel=0.02)


def test_tonemap_black_image():
    png, info = tonemap_ward(np.zeros((3, 3, 3)))
    assert png.dtype == np.uint8 and np.all(png == 0)
    assert info["adaptation_luminance"] == pytest.approx(1e-4)
    assert all(np.isfinite(v) for k, v in info.items() if k != "clipping")


def test_tonemap_rejects_non_finite_and_negative_input():
    for bad in [np.nan, np.inf, -np.inf, -1.0]:
        rgb = np.ones((2, 2, 3))
        rgb[1, 1, 2] = bad
        with pytest.raises(ValueError):
            tonemap_ward(rgb)
    with pytest.raises(ValueError):
        tonemap_ward(np.ones((2, 2)))
