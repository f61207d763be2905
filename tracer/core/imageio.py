"""Image files: reading panoramas and textures, writing EXR results and PNG previews, reading a
render's luminance back.

All file access goes through OpenImageIO (https://openimageio.readthedocs.io). Arrays are
indexed ``[row, column, channel]`` with row 0 the TOP row of the image, as files store it.

Colour encoding follows IEC 61966-2-1:1999 (sRGB): integer files (8/16-bit PNG, JPEG,
TIFF...) hold sRGB-encoded values and are decoded to linear on reading; float files (EXR,
Radiance HDR, float TIFF) hold linear values and are returned as stored.
"""

from __future__ import annotations

import contextlib
import numbers
import os
import sys
import threading
import uuid
from pathlib import Path

import numpy as np
import OpenImageIO as oiio

from .errors import ImageReadError, SceneError
from .units import luminance

#: OpenImageIO base types of files whose values are linear (returned as stored by default).
_FLOAT_BASETYPES = (oiio.FLOAT, oiio.HALF, oiio.DOUBLE)

#: Range of an EXR ``int`` header attribute (32-bit signed).
_INT32_MIN, _INT32_MAX = -(2**31), 2**31 - 1


def srgb_decode(v) -> np.ndarray:
    """sRGB-encoded values to linear ones (IEC 61966-2-1:1999, section 5.2).

    ``L = v / 12.92`` for ``v <= 0.04045``, else ``L = ((v + 0.055) / 1.055) ** 2.4``.

    Parameters
    ----------
    v : array_like, any shape
        Encoded values, nominally in [0, 1]; values below 0.04045 (negative ones included)
        follow the linear segment.

    Returns
    -------
    np.ndarray, same shape as ``v``, float64
        Linear values.
    """
    v = np.asarray(v, dtype=np.float64)
    curve = ((np.maximum(v, 0.04045) + 0.055) / 1.055) ** 2.4
    return np.where(v <= 0.04045, v / 12.92, curve)


def srgb_encode(v) -> np.ndarray:
    """Linear values to sRGB-encoded ones (IEC 61966-2-1:1999, section 5.3).

    ``V = 12.92 L`` for ``L <= 0.0031308``, else ``V = 1.055 L ** (1 / 2.4) - 0.055``.

    Parameters
    ----------
    v : array_like, any shape
        Linear values, nominally in [0, 1]; values below 0.0031308 (negative ones included)
        follow the linear segment.

    Returns
    -------
    np.ndarray, same shape as ``v``, float64 (float32 for float32 values, three times as fast)
        Encoded values.
    """
    v = np.asarray(v)
    t = np.float32 if v.dtype == np.float32 else np.float64
    v = v.astype(t, copy=False)
    # in place from here: a 4K preview's temporaries are 100 MB each
    out = np.array(np.maximum(v, t(0.0031308)), dtype=t)
    np.power(out, t(1.0 / 2.4), out=out)
    out *= t(1.055)
    out -= t(0.055)
    low = v <= t(0.0031308)
    out[low] = t(12.92) * v[low]
    return out


_silence_lock = threading.Lock()
_silence_depth = 0
_silence_saved: int | None = None


@contextlib.contextmanager
def _c_stderr_silenced():
    """Send what C libraries write to file descriptor 2 while the block runs to /dev/null: libpng
    prints its errors there, beside the error text OpenImageIO returns (which the caller reports).
    Blocks may overlap in several threads (a render's outputs are checked side by side): the first
    to enter silences, the last to leave restores."""
    global _silence_depth, _silence_saved
    with _silence_lock:
        if _silence_depth == 0:
            try:
                sys.stderr.flush()
                _silence_saved = os.dup(2)
            except (OSError, ValueError):  # no file descriptor 2 (an embedding host): nothing to silence
                _silence_saved = None
            if _silence_saved is not None:
                devnull = os.open(os.devnull, os.O_WRONLY)
                os.dup2(devnull, 2)
                os.close(devnull)
        _silence_depth += 1
    try:
        yield
    finally:
        with _silence_lock:
            _silence_depth -= 1
            if _silence_depth == 0 and _silence_saved is not None:
                os.dup2(_silence_saved, 2)
                os.close(_silence_saved)
                _silence_saved = None


def _read_pixels(path, kind=oiio.FLOAT, rows: tuple[int, int] | None = None) -> tuple[oiio.ImageSpec, np.ndarray]:
    """Read the first subimage of ``path`` as stored, as float32 of shape (H, W, C) (``kind``
    ``oiio.UINT8``: as 8-bit codes, uint8); ``rows`` (begin, end): those rows only, (end - begin, W, C)
    (only the blocks that hold them are read and decoded).

    Colour is not multiplied by alpha (the ``oiio:UnassociatedAlpha`` reader hint). Raises
    :class:`ImageReadError` with OpenImageIO's error text on failure; what the format's C library
    prints on the way is kept off the terminal (a truncated PNG made libpng print two more lines).
    """
    with _c_stderr_silenced():
        return _read_pixels_as_stored(path, kind, rows)


def _read_pixels_as_stored(path, kind, rows) -> tuple[oiio.ImageSpec, np.ndarray]:
    config = oiio.ImageSpec()
    config.attribute("oiio:UnassociatedAlpha", 1)
    inp = oiio.ImageInput.open(str(path), config)
    if inp is None:
        raise ImageReadError(path, oiio.geterror() or "cannot open the file")
    try:
        spec = inp.spec()
        if rows is None:
            pixels = inp.read_image(kind)
        else:
            pixels = inp.read_scanlines(rows[0], rows[1], 0, 0, spec.nchannels, kind)
        if pixels is None:
            what = "the pixels" if rows is None else f"rows {rows[0]} to {rows[1]}"
            raise ImageReadError(path, inp.geterror() or f"cannot read {what}")
    finally:
        inp.close()
    pixels = np.asarray(pixels, dtype=np.uint8 if kind == oiio.UINT8 else np.float32)
    height = spec.height if rows is None else rows[1] - rows[0]
    return spec, pixels.reshape(height, spec.width, spec.nchannels)


def read_codes(path) -> np.ndarray:
    """The pixels of an 8-bit image file (a PNG) as its stored codes, (H, W, C) uint8, row 0 the top
    row: what :func:`write_png` wrote, without decoding. Raises :class:`ImageReadError`."""
    return _read_pixels(path, oiio.UINT8)[1]


def read_image(path, linear: bool | None = None) -> np.ndarray:
    """Read the first subimage of an image file as linear float values.

    Parameters
    ----------
    path : str or os.PathLike
        Any file format OpenImageIO reads (EXR, HDR, PNG, JPEG, TIFF...).
    linear : bool or None
        ``None``: integer formats are sRGB-decoded (:func:`srgb_decode`), float formats are
        returned as stored. ``True``: values are returned as stored whatever the format.
        ``False``: values are sRGB-decoded whatever the format. An alpha channel is never
        decoded, and it is not multiplied into the colour channels (PNG and TIFF
        unassociated alpha stays unassociated).

    Returns
    -------
    np.ndarray, shape (H, W, C), float32
        Row 0 is the top row. C is the file's channel count (1 grey, 3 RGB, 4 RGBA...);
        the alpha channel, if any, is kept. Integer formats are normalised to [0, 1] first.

    Raises
    ------
    ImageReadError
        The file is missing, unreadable or of a format OpenImageIO does not know; the reason
        is OpenImageIO's error text.
    """
    spec, pixels = _read_pixels(path)
    decode = spec.format.basetype not in _FLOAT_BASETYPES if linear is None else not linear
    if decode:
        colour = [c for c in range(spec.nchannels) if c != spec.alpha_channel]
        pixels[..., colour] = srgb_decode(pixels[..., colour])
    return pixels


def _write_atomically(path, format_name: str, spec: oiio.ImageSpec, pixels: np.ndarray) -> None:
    """Write ``pixels`` (H, W, C) in ``format_name`` to a temporary file beside ``path``,
    then move it onto ``path`` with :func:`os.replace`, so that readers never see a partial
    file. Raises ``OSError`` with OpenImageIO's error text if the file cannot be written."""
    path = Path(path)
    tmp = path.with_name(f".{path.name}.{uuid.uuid4().hex}.tmp")
    out = oiio.ImageOutput.create(format_name)
    if out is None:
        raise OSError(f"{path}: {oiio.geterror()}")
    try:
        ok = out.open(str(tmp), spec) and out.write_image(pixels)
        error = out.geterror()
        ok = out.close() and ok
        if not ok:
            raise OSError(f"{path}: {error or out.geterror() or 'cannot write the image'}")
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)


#: The EXR header's DateTime of a scene's texture (:func:`write_exr`'s ``attributes``): OpenImageIO stamps
#: the time of writing otherwise, and a scene exported or written again (F12 after F12) would get another
#: hash (tracer.scene.load.scene_hash) for the same pixels, and lose what is kept by it (tracer.core.kept).
TEXTURE_ATTRIBUTES = {"DateTime": "0000:00:00 00:00:00"}


def write_exr(path, channels: dict[str, np.ndarray], attributes: dict | None = None) -> None:
    """Write named float channels to an OpenEXR file, atomically.

    Parameters
    ----------
    path : str or os.PathLike
        Target file; it is written as OpenEXR whatever its extension.
    channels : dict[str, np.ndarray]
        Channel name -> array of shape (H, W) (row 0 is the top row), all of the same shape;
        stored as 32-bit float in the given order (e.g. ``R, G, B, Y, Y_var``). Note that
        OpenEXR itself keeps channels sorted by name, so a reader may list them in another
        order; :func:`read_exr_channels` returns them by name.
    attributes : dict[str, str | int | float] or None
        Header metadata. ``str`` -> EXR ``string``, ``int`` -> EXR ``int`` (32-bit signed),
        ``float`` -> EXR ``float`` (32-bit: about 7 significant digits survive; store a
        string where an exact value matters). ``bool`` is refused.

    Raises
    ------
    ValueError
        No channels, channels of different or non-2-D shapes, an int attribute outside the
        32-bit range.
    TypeError
        An attribute value that is not str, int or float.
    OSError
        The file cannot be written.
    """
    if not channels:
        raise ValueError("write_exr needs at least one channel")
    names = list(channels)
    planes = [np.asarray(channels[name], dtype=np.float32) for name in names]
    shape = planes[0].shape
    if len(shape) != 2 or any(p.shape != shape for p in planes):
        raise ValueError(
            f"channels must be 2-D arrays of one shape, got {[p.shape for p in planes]}"
        )
    write_exr_pixels(path, names, np.stack(planes, axis=-1), attributes)


def write_exr_pixels(path, names: list[str], pixels: np.ndarray, attributes: dict | None = None) -> None:
    """:func:`write_exr` of channels given interleaved: ``pixels`` (H, W, len(names)) float32, channel
    k named ``names[k]`` (a 4K image built so skips the copy that interleaves its planes)."""
    if pixels.ndim != 3 or pixels.shape[2] != len(names) or pixels.dtype != np.float32:
        raise ValueError(f"pixels must be (H, W, {len(names)}) float32, got {pixels.dtype} {pixels.shape}")
    shape = pixels.shape[:2]
    spec = oiio.ImageSpec(shape[1], shape[0], len(names), oiio.FLOAT)
    spec.channelnames = tuple(names)
    for key, value in (attributes or {}).items():
        if isinstance(value, str):
            spec.attribute(key, value)
        elif isinstance(value, numbers.Integral) and not isinstance(value, bool):
            if not _INT32_MIN <= value <= _INT32_MAX:
                raise ValueError(
                    f"attribute {key!r} = {value} is outside the 32-bit EXR int range; "
                    "store it as a string"
                )
            spec.attribute(key, int(value))
        elif isinstance(value, numbers.Real) and not isinstance(value, bool):
            spec.attribute(key, float(value))
        else:
            raise TypeError(
                f"attribute {key!r} must be str, int or float, got {type(value).__name__}"
            )
    spec.attribute("compression", "zip")
    _write_atomically(path, "openexr", spec, np.ascontiguousarray(pixels))


def read_exr_channels(path) -> tuple[dict[str, np.ndarray], dict]:
    """Read every channel of an image file by name, with its header metadata.

    Parameters
    ----------
    path : str or os.PathLike
        An OpenEXR file (any format OpenImageIO reads works).

    Returns
    -------
    channels : dict[str, np.ndarray]
        Channel name -> array of shape (H, W), float32, as stored (no decoding); row 0 is
        the top row.
    attributes : dict
        Every header attribute OpenImageIO reports, name -> value (those written by
        :func:`write_exr` included, plus format ones such as ``compression``).

    Raises
    ------
    ImageReadError
        The file is missing, unreadable or of an unknown format.
    """
    spec, pixels = _read_pixels(path)
    channels = {name: pixels[..., i].copy() for i, name in enumerate(spec.channelnames)}
    attributes = {a.name: a.value for a in spec.extra_attribs}
    return channels, attributes


def read_exr_rows(path, ybegin: int, yend: int) -> tuple[dict[str, np.ndarray], dict]:
    """Rows ``ybegin`` to ``yend`` (exclusive) of every channel of an image file by name, float32
    (rows, W) views, with its header metadata (:func:`read_exr_channels` of part of the image: only the
    blocks that hold those rows are read and decoded). Raises :class:`ImageReadError`, for instance
    where the file ends before those rows."""
    spec, rows = _read_pixels(path, rows=(ybegin, yend))
    return ({name: rows[..., i] for i, name in enumerate(spec.channelnames)},
            {a.name: a.value for a in spec.extra_attribs})


#: zlib level of the PNGs written (1 fastest, 9 smallest; OpenImageIO's default is 6).
PNG_COMPRESSION_LEVEL = 1


def write_png(path, rgb8: np.ndarray) -> None:
    """Write an 8-bit sRGB-encoded RGB image to a PNG file, atomically.

    Parameters
    ----------
    path : str or os.PathLike
        Target file; it is written as PNG whatever its extension.
    rgb8 : np.ndarray, shape (H, W, 3), uint8
        Encoded pixel values, row 0 the top row (e.g. from
        :func:`tracer.products.tonemap.tonemap_ward`).

    Raises
    ------
    ValueError
        ``rgb8`` is not a (H, W, 3) uint8 array.
    OSError
        The file cannot be written.
    """
    rgb8 = np.asarray(rgb8)
    if rgb8.dtype != np.uint8 or rgb8.ndim != 3 or rgb8.shape[2] != 3:
        raise ValueError(f"rgb8 must be a (H, W, 3) uint8 array, got {rgb8.dtype} {rgb8.shape}")
    spec = oiio.ImageSpec(rgb8.shape[1], rgb8.shape[0], 3, oiio.UINT8)
    spec.attribute("oiio:ColorSpace", "sRGB")
    # zlib's fastest level: a large preview in a third of the time of level 6, files about 10 % larger
    spec.attribute("png:compressionLevel", PNG_COMPRESSION_LEVEL)
    _write_atomically(path, "png", spec, np.ascontiguousarray(rgb8))


#: The first four bytes of every OpenEXR file (the OpenEXR file layout, "magic number").
EXR_MAGIC = bytes((0x76, 0x2F, 0x31, 0x01))


def read_luminance(path) -> np.ndarray:
    """The luminance Y (H, W) cd/m^2 of an image.exr written by the tracer: its Y channel, or
    Y = 0.2126 R + 0.7152 G + 0.0722 B (:func:`tracer.core.units.luminance`) where it has none.

    Raises :class:`~tracer.core.errors.SceneError` naming the file, and the channel where one is at
    fault, for a file that is missing, not an OpenEXR file, without Y nor R, G and B, or holding
    non-finite values; :class:`~tracer.core.errors.ImageReadError` for one OpenImageIO cannot read."""
    p = Path(path)
    if not p.is_file():
        raise SceneError(str(path), "", "no such file" if not p.exists() else "is not a file")
    try:
        with open(p, "rb") as fh:
            magic = fh.read(4)
    except OSError as e:
        raise SceneError(str(path), "", f"cannot be read ({e.strerror or e})") from None
    if magic != EXR_MAGIC:
        raise SceneError(str(path), "", "is not an OpenEXR file (the false-colour view reads the luminance of an "
                                        "image.exr written by hud-trace render)")
    channels, _ = read_exr_channels(p)
    if "Y" in channels:
        name, y = "Y", channels["Y"]
    elif {"R", "G", "B"} <= set(channels):
        name, y = "R, G, B", luminance(np.stack([channels[c] for c in "RGB"], axis=-1))
    else:
        have = ", ".join(sorted(channels)) or "none"
        raise SceneError(str(path), "channels", f"has no Y channel, nor R, G and B to make it from (its channels: "
                                                f"{have})")
    if not np.all(np.isfinite(y)):
        raise SceneError(str(path), name, "holds non-finite values (NaN or Inf)")
    y = np.asarray(y, dtype=np.float64)
    low, high = float(y.min()), float(y.max())
    if low < -1e-6 * max(high, 0.0):  # rounding (a denoiser's, a colour transform's) is tolerated
        raise SceneError(str(path), name, f"holds negative luminance (down to {low:.4g} cd/m^2): not a luminance "
                                          "image")
    return y
