"""Tests of tracer.core.imageio: sRGB curves, reading images, writing EXR and PNG atomically."""

from __future__ import annotations

import numpy as np
import OpenImageIO as oiio
import pytest

from tracer.core.errors import ImageReadError
from tracer.core.imageio import (
    read_exr_channels,
    read_image,
    srgb_decode,
    srgb_encode,
    write_exr,
    write_png,
)


def _write_with_oiio(path, pixels: np.ndarray, basetype, unassociated_alpha=False) -> None:
    """Write ``pixels`` (H, W, C) with OpenImageIO directly, bypassing the module under test."""
    spec = oiio.ImageSpec(pixels.shape[1], pixels.shape[0], pixels.shape[2], basetype)
    if unassociated_alpha:
        spec.attribute("oiio:UnassociatedAlpha", 1)
    out = oiio.ImageOutput.create(str(path))
    assert out.open(str(path), spec) and out.write_image(pixels) and out.close()


# --- sRGB curves (IEC 61966-2-1) ---------------------------------------------------------


def test_srgb_decode_known_values():
    # 128/255 -> ((128/255 + 0.055) / 1.055) ** 2.4
    assert srgb_decode(128 / 255) == pytest.approx(0.2158605, abs=1e-7)
    assert srgb_decode(0.0) == 0.0
    assert srgb_decode(1.0) == pytest.approx(1.0, abs=1e-15)
    assert srgb_decode(0.04) == pytest.approx(0.04 / 12.92, rel=1e-15)


def test_srgb_encode_known_values():
    assert srgb_encode(0.2158605001138993) == pytest.approx(128 / 255, rel=1e-12)
    assert srgb_encode(0.002) == pytest.approx(12.92 * 0.002, rel=1e-15)
    assert srgb_encode(1.0) == pytest.approx(1.0, abs=1e-15)


def test_srgb_round_trip_and_continuity():
    v = np.linspace(0.0, 1.0, 10001).reshape(73, 137)
    np.testing.assert_allclose(srgb_encode(srgb_decode(v)), v, atol=1e-12)
    # The two pieces meet (to the rounding of the standard's constants) at the breakpoints.
    assert srgb_decode(0.04045) == pytest.approx(((0.04045 + 0.055) / 1.055) ** 2.4, rel=1e-4)
    assert srgb_encode(0.0031308) == pytest.approx(1.055 * 0.0031308 ** (1 / 2.4) - 0.055, rel=1e-4)


def test_srgb_curves_are_finite_for_negative_values():
    with np.errstate(all="raise"):
        assert srgb_decode(-0.5) == pytest.approx(-0.5 / 12.92)
        assert srgb_encode(-0.5) == pytest.approx(-0.5 * 12.92)


# --- read_image ----------------------------------------------------------------------------


def test_read_png_decodes_srgb_and_keeps_top_row_first(tmp_path):
    rgb8 = np.zeros((2, 3, 3), np.uint8)
    rgb8[0] = 128  # top row
    path = tmp_path / "grey.png"
    write_png(path, rgb8)
    img = read_image(path)
    assert img.dtype == np.float32 and img.shape == (2, 3, 3)
    np.testing.assert_allclose(img[0], 0.2158605, atol=1e-6)
    np.testing.assert_array_equal(img[1], 0.0)
    np.testing.assert_allclose(read_image(path, linear=True)[0], 128 / 255, atol=1e-7)


def test_read_16bit_grey_png(tmp_path):
    path = tmp_path / "grey16.png"
    _write_with_oiio(path, np.full((2, 2, 1), 32768, np.uint16), oiio.UINT16)
    img = read_image(path)
    assert img.shape == (2, 2, 1)
    np.testing.assert_allclose(img, srgb_decode(32768 / 65535), rtol=1e-6)


def test_read_rgba_png_keeps_alpha_linear_and_unassociated(tmp_path):
    path = tmp_path / "rgba.png"
    _write_with_oiio(
        path, np.array([[[128, 128, 128, 51]]], np.uint8), oiio.UINT8, unassociated_alpha=True
    )
    img = read_image(path)
    assert img.shape == (1, 1, 4)
    np.testing.assert_allclose(img[0, 0, :3], 0.2158605, atol=1e-6)  # not multiplied by alpha
    assert img[0, 0, 3] == pytest.approx(0.2, abs=1e-7)  # alpha not decoded


def test_read_float_exr_as_stored_unless_told(tmp_path):
    path = tmp_path / "float.exr"
    pixels = np.array([[[0.5, 2.0, 1000.0]]], np.float32)
    _write_with_oiio(path, pixels, oiio.FLOAT)
    np.testing.assert_array_equal(read_image(path), pixels)
    np.testing.assert_allclose(read_image(path, linear=False), srgb_decode(pixels), rtol=1e-6)


def test_read_missing_file(tmp_path):
    path = tmp_path / "missing.exr"
    with pytest.raises(ImageReadError) as info:
        read_image(path)
    assert info.value.path == str(path)
    assert info.value.reason


def test_read_corrupt_file(tmp_path):
    path = tmp_path / "corrupt.png"
    path.write_bytes(b"this is not a PNG file")
    with pytest.raises(ImageReadError) as info:
        read_image(path)
    assert info.value.path == str(path)
    assert "PNG" in info.value.reason


def test_read_unsupported_format(tmp_path):
    path = tmp_path / "image.unknownformat"
    path.write_bytes(b"\x00" * 64)
    with pytest.raises(ImageReadError) as info:
        read_image(path)
    assert "format" in info.value.reason


# --- write_exr / read_exr_channels ----------------------------------------------------------


def test_exr_round_trip_with_attributes(tmp_path):
    rng = np.random.default_rng(1)
    names = ["R", "G", "B", "Y", "Y_var"]
    channels = {name: rng.random((4, 5)) * 1e4 for name in names}
    attributes = {"hud:method": "forward", "hud:samples": 123456, "hud:seconds": 2.5, "hud:k": 0.1}
    path = tmp_path / "result.exr"
    write_exr(path, channels, attributes)

    read, attrs = read_exr_channels(path)
    assert set(read) == set(names)
    for name in names:
        assert read[name].dtype == np.float32 and read[name].shape == (4, 5)
        np.testing.assert_array_equal(read[name], channels[name].astype(np.float32))
    assert attrs["hud:method"] == "forward"
    assert attrs["hud:samples"] == 123456 and isinstance(attrs["hud:samples"], int)
    assert attrs["hud:seconds"] == 2.5
    assert attrs["hud:k"] == pytest.approx(0.1, rel=1e-7)  # EXR float attributes are 32-bit
    assert attrs["compression"] == "zip"
    assert [p.name for p in tmp_path.iterdir()] == ["result.exr"]  # no temporary file left


def test_exr_overwrites_existing_file(tmp_path):
    path = tmp_path / "result.exr"
    write_exr(path, {"Y": np.zeros((2, 2))})
    write_exr(path, {"Y": np.ones((3, 1))})
    read, _ = read_exr_channels(path)
    np.testing.assert_array_equal(read["Y"], np.ones((3, 1), np.float32))
    assert [p.name for p in tmp_path.iterdir()] == ["result.exr"]


def test_write_exr_rejects_bad_input(tmp_path):
    path = tmp_path / "bad.exr"
    with pytest.raises(ValueError):
        write_exr(path, {})
    with pytest.raises(ValueError):
        write_exr(path, {"R": np.zeros((2, 2)), "G": np.zeros((2, 3))})
    with pytest.raises(ValueError):
        write_exr(path, {"R": np.zeros(4)})
    with pytest.raises(TypeError):
        write_exr(path, {"R": np.zeros((2, 2))}, {"flag": True})
    with pytest.raises(TypeError):
        write_exr(path, {"R": np.zeros((2, 2))}, {"list": [1, 2]})
    with pytest.raises(ValueError):
        write_exr(path, {"R": np.zeros((2, 2))}, {"seed": 2**40})
    assert list(tmp_path.iterdir()) == []


def test_write_into_missing_folder_raises_and_leaves_nothing(tmp_path):
    with pytest.raises(OSError):
        write_exr(tmp_path / "no" / "such" / "folder.exr", {"Y": np.zeros((2, 2))})
    with pytest.raises(OSError):
        write_png(tmp_path / "no" / "preview.png", np.zeros((2, 2, 3), np.uint8))
    assert list(tmp_path.iterdir()) == []


# --- write_png ------------------------------------------------------------------------------


def test_png_round_trip(tmp_path):
    rgb8 = np.random.default_rng(2).integers(0, 256, size=(5, 7, 3), dtype=np.uint8)
    path = tmp_path / "preview.png"
    write_png(path, rgb8)
    np.testing.assert_array_equal(np.rint(read_image(path, linear=True) * 255), rgb8)
    assert [p.name for p in tmp_path.iterdir()] == ["preview.png"]


def test_write_png_rejects_bad_arrays(tmp_path):
    with pytest.raises(ValueError):
        write_png(tmp_path / "a.png", np.zeros((2, 2, 3), np.float32))
    with pytest.raises(ValueError):
        write_png(tmp_path / "a.png", np.zeros((2, 2, 4), np.uint8))
    assert list(tmp_path.iterdir()) == []


def test_a_texture_written_again_later_is_the_same_file(tmp_path):
    """Scene textures (Blender's export, the presets' panoramas) carry TEXTURE_ATTRIBUTES' fixed DateTime,
    not the time of writing, so that a scene exported again a second later has the same hash and finds
    what was kept by it (tracer.core.kept); without it the two files differ."""
    import time

    from tracer.core.imageio import TEXTURE_ATTRIBUTES, write_exr

    rgb = {c: np.full((3, 4), v, np.float32) for c, v in zip("RGB", (0.25, 0.5, 1.0), strict=True)}
    write_exr(tmp_path / "a.exr", rgb, TEXTURE_ATTRIBUTES)
    write_exr(tmp_path / "plain_a.exr", rgb)
    time.sleep(1.05)  # the DateTime's resolution is one second
    write_exr(tmp_path / "b.exr", rgb, TEXTURE_ATTRIBUTES)
    write_exr(tmp_path / "plain_b.exr", rgb)
    assert (tmp_path / "a.exr").read_bytes() == (tmp_path / "b.exr").read_bytes()
    assert (tmp_path / "plain_a.exr").read_bytes() != (tmp_path / "plain_b.exr").read_bytes()
    _, attrs = read_exr_channels(tmp_path / "a.exr")
    assert attrs["DateTime"] == TEXTURE_ATTRIBUTES["DateTime"]
