"""The environment: what a ray sees when it leaves the scene (the scene.json "environment").

An environment gives the radiance arriving from infinitely far away along a direction, in
linear Rec.709 RGB scaled so that :func:`tracer.core.units.luminance` of it is the luminance in
cd/m^2. World axes: z is up (as in Blender); directions are unit vectors.

Three kinds exist: :class:`NoEnvironment` (black), :class:`UniformEnvironment` (the same
luminance everywhere) and :class:`HdriEnvironment` (an equirectangular panorama, calibrated
to a luminance); :mod:`tracer.scene.environment` builds one from scene.json.

Equirectangular convention (Blender's, so that the Blender add-on shows the same panorama as
Blender's Environment Texture node): a direction d = (x, y, z) maps to

    u = 0.5 - atan2(y, x) / (2 pi),        v = 0.5 + atan2(z, hypot(x, y)) / pi,

with u = 0 at the left edge of the image and v = 1 at its top edge (image row 0). So +x is
at the centre of the image, +y at a quarter of its width, -y at three quarters, -x on the
left/right seam, +z along the top row. This is ``direction_to_equirectangular`` of Cycles
(intern/cycles/kernel/camera/projection.h) and ``node_tex_environment_equirectangular`` of
EEVEE. (Mind the sign: ``-atan2(y, x)``, not ``atan2(y, -x)``, which is half a turn away.)

Directions are (3, n) planes (:mod:`tracer.core.vec`). Every environment can also be sampled for
next-event estimation: ``sample(u)`` draws directions with a density ``pdf(d)`` per steradian;
:class:`HdriEnvironment` draws pixels in proportion to luminance times solid angle (the luminance
times sin(theta) of the continuous panorama), then a uniform direction inside the pixel (Pharr,
Jakob and Humphreys, "Physically Based Rendering", 3rd ed., sec. 14.2.4, "Infinite area lights").

A sun (:class:`tracer.sources.sun.Sun`: a uniform disk of a given illuminance and angular diameter)
can be added to any of them (:class:`tracer.sources.sun.EnvironmentWithSun`); the sum is an environment
like the others, so every method that reads, samples or weighs an environment sees the sun without
knowing of it.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod

import numpy as np

from ..core.sampling import Distribution1D, uniform_sphere
from ..core.units import luminance, normalize_color

#: Calibration modes of :class:`HdriEnvironment`.
CALIBRATION_MODES = ("scale", "mean", "max", "min")


def as_directions(d) -> np.ndarray:
    """``d`` as a float64 array of shape (3, n) of finite values, or ``ValueError``."""
    d = np.asarray(d, dtype=np.float64)
    if d.ndim != 2 or d.shape[0] != 3:
        raise ValueError(f"directions must have shape (3, n), got {d.shape}")
    if not np.all(np.isfinite(d)):
        raise ValueError("directions must be finite")
    return d


def direction_to_equirect(d) -> tuple[np.ndarray, np.ndarray]:
    """Equirectangular coordinates of directions, in Blender's convention (module docstring).

    Parameters
    ----------
    d : array_like, shape (3, n)
        Directions (any non-zero length; z up).

    Returns
    -------
    u : np.ndarray, shape (n,)
        Horizontal coordinate in [0, 1], 0 at the left edge of the image; +x is at 0.5.
    v : np.ndarray, shape (n,)
        Vertical coordinate in [0, 1], 1 at the top edge (image row 0, the +z pole).
    """
    d = as_directions(d)
    u = 0.5 - np.arctan2(d[1], d[0]) / (2.0 * np.pi)
    v = 0.5 + np.arctan2(d[2], np.hypot(d[0], d[1])) / np.pi
    return u, v


def equirect_to_direction(u, v) -> np.ndarray:
    """Unit directions of equirectangular coordinates; the inverse of :func:`direction_to_equirect`.

    Parameters
    ----------
    u, v : array_like, shape (n,)
        Coordinates as in :func:`direction_to_equirect`.

    Returns
    -------
    np.ndarray, shape (3, n), float64
        Unit directions (z up).
    """
    azimuth = np.pi * (1.0 - 2.0 * np.asarray(u, dtype=np.float64))
    latitude = np.pi * (np.asarray(v, dtype=np.float64) - 0.5)
    cos_lat = np.cos(latitude)
    return np.stack([cos_lat * np.cos(azimuth), cos_lat * np.sin(azimuth), np.sin(latitude)])


def _bilinear(image: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Bilinear lookup of ``image`` (H, W, 3) at (u, v) of shape (n,); wraps in u, clamps in v.

    Pixel (row i, column j) has its centre at u = (j + 0.5) / W, v = 1 - (i + 0.5) / H.
    Returns (3, n) float64.
    """
    height, width = image.shape[:2]
    x = u * width - 0.5
    y = (1.0 - v) * height - 0.5
    x0 = np.floor(x)
    y0 = np.floor(y)
    fx = x - x0
    fy = y - y0
    col0 = x0.astype(np.intp) % width
    col1 = (col0 + 1) % width
    row0 = np.clip(y0.astype(np.intp), 0, height - 1)
    row1 = np.clip(y0.astype(np.intp) + 1, 0, height - 1)
    top = image[row0, col0].T * (1.0 - fx) + image[row0, col1].T * fx
    bottom = image[row1, col0].T * (1.0 - fx) + image[row1, col1].T * fx
    return top * (1.0 - fy) + bottom * fy


def row_solid_angle_fractions(height: int) -> np.ndarray:
    """Fraction of the sphere covered by each pixel row of an equirectangular image.

    Row i (0 at the top) spans the latitudes lat_top = pi/2 - pi i / H down to
    lat_bottom = pi/2 - pi (i + 1) / H; each of its W pixels subtends the solid angle
    (2 pi / W) (sin lat_top - sin lat_bottom) sr, so the row covers
    (sin lat_top - sin lat_bottom) / 2 of the sphere (4 pi sr).

    Parameters
    ----------
    height : int
        Number of rows H.

    Returns
    -------
    np.ndarray, shape (H,), float64
        Fractions, summing to 1.
    """
    edges = 0.5 * np.pi - np.pi * np.arange(height + 1) / height
    return 0.5 * (np.sin(edges[:-1]) - np.sin(edges[1:]))


def panorama_rgb(pixels: np.ndarray) -> np.ndarray:
    """The RGB of a panorama file's pixels (H, W, C) as :func:`tracer.core.imageio.read_image` returns them:
    1 channel is grey, 2 grey and alpha, 3 RGB, 4 RGBA; alpha is dropped. Returns (H, W, 3); raises
    ValueError for more than 4 channels."""
    channels = pixels.shape[2]
    if channels > 4:
        raise ValueError(f"has {channels} channels; expected 1 to 4")
    return np.repeat(pixels[..., :1], 3, axis=2) if channels <= 2 else pixels[..., :3]


class Environment(ABC):
    """Radiance arriving from far away along directions leaving the scene."""

    @abstractmethod
    def radiance(self, d) -> np.ndarray:
        """Radiance arriving from directions ``d``.

        Parameters
        ----------
        d : array_like, shape (3, n)
            Unit directions pointing away from the scene (z up).

        Returns
        -------
        np.ndarray, shape (3, n), float64
            Linear Rec.709 RGB whose luminance Y is in cd/m^2.
        """

    def sample(self, u: np.ndarray):
        """Directions toward the environment for next-event estimation: u (2, n) -> (unit directions
        (3, n), radiance arriving from them (3, n), density (n,) per steradian)."""
        raise NotImplementedError("a black environment has nothing to sample")

    def pdf(self, d: np.ndarray) -> np.ndarray:
        """The density of :meth:`sample` at unit directions ``d`` (3, n), per steradian; (n,)."""
        return np.zeros(d.shape[1])

    @property
    @abstractmethod
    def mean_luminance(self) -> float:
        """Solid-angle-weighted mean luminance over the whole sphere, cd/m^2."""

    @property
    @abstractmethod
    def max_luminance(self) -> float:
        """Largest luminance in any direction, cd/m^2."""

    @property
    def is_black(self) -> bool:
        """True when no light comes from any direction."""
        return self.max_luminance == 0.0


class NoEnvironment(Environment):
    """No environment: black in every direction."""

    def radiance(self, d) -> np.ndarray:
        return np.zeros((3, as_directions(d).shape[1]))

    @property
    def mean_luminance(self) -> float:
        return 0.0

    @property
    def max_luminance(self) -> float:
        return 0.0


class UniformEnvironment(Environment):
    """The same luminance and colour in every direction.

    Parameters
    ----------
    luminance_cd_m2 : float
        Luminance L, cd/m^2, finite and >= 0.
    color : array_like, shape (3,)
        Linear Rec.709 colour, normalised to unit luminance (:func:`tracer.core.units.normalize_color`),
        so the radiance is ``L * color / Y(color)``.

    Raises
    ------
    ValueError
        A negative or non-finite luminance, or a colour with a negative component or zero
        luminance.
    """

    def __init__(self, luminance_cd_m2: float, color=(1.0, 1.0, 1.0)):
        if not (math.isfinite(luminance_cd_m2) and luminance_cd_m2 >= 0):
            raise ValueError(f"luminance must be finite and >= 0, got {luminance_cd_m2}")
        self.luminance_cd_m2 = float(luminance_cd_m2)
        self.color = normalize_color(color)
        self._rgb = self.luminance_cd_m2 * self.color

    def radiance(self, d) -> np.ndarray:
        return np.repeat(self._rgb[:, None], as_directions(d).shape[1], axis=1)

    def sample(self, u):
        """Uniform directions on the sphere (density 1 / (4 pi))."""
        d = uniform_sphere(u)
        n = d.shape[1]
        return d, np.repeat(self._rgb[:, None], n, axis=1), np.full(n, 1.0 / (4.0 * np.pi))

    def pdf(self, d):
        return np.full(np.shape(d)[1], 1.0 / (4.0 * np.pi))

    @property
    def mean_luminance(self) -> float:
        return self.luminance_cd_m2

    @property
    def max_luminance(self) -> float:
        return self.luminance_cd_m2


class HdriEnvironment(Environment):
    """An equirectangular panorama (HDRI), calibrated to a luminance.

    Mapping: Blender's equirectangular convention (module docstring, :func:`direction_to_equirect`),
    with bilinear interpolation between pixel centres, wrapping around in u and clamped in v
    (rows beyond the top and bottom pixel centres take the edge row's values).

    Rotation: before the lookup the direction is rotated by ``-rotation_deg`` about +z. So the
    panorama turns by ``+rotation_deg`` counter-clockwise seen from above (from +z looking
    down): what is seen in direction d at rotation 0 is seen in direction R_z(rotation_deg) d,
    e.g. with 90 degrees the image centre moves from +x to +y. In Blender this is a Mapping
    node of type "Texture" with Rotation Z = rotation_deg (equivalently type "Point" with
    Rotation Z = -rotation_deg) between Texture Coordinate > Generated and the Environment
    Texture's Vector.

    Calibration: the radiance is ``k * image`` with one factor k (``scale_factor``):

    - ``"scale"``: k = value;
    - ``"mean"``: k makes the solid-angle-weighted mean luminance of the pixels equal to
      value cd/m^2; pixel row i weighs its exact solid angle (2 pi / W) (sin lat_top -
      sin lat_bottom) per pixel (:func:`row_solid_angle_fractions`), i.e. cos(latitude)
      integrated over the row band;
    - ``"max"``: k makes the largest pixel luminance equal to value cd/m^2 (bilinear
      interpolation never exceeds it, so it is also the largest radiance returned);
    - ``"min"``: k makes the smallest pixel luminance equal to value cd/m^2 (bilinear
      interpolation never falls below it); a panorama with a black pixel cannot be calibrated
      so, whatever k.

    Parameters
    ----------
    image : array_like, shape (H, W, 3)
        Linear Rec.709 RGB, finite and >= 0; row 0 is the top row (the +z pole). Kept as
        float32 if given as float32, else as float64; lookups compute in float64.
    calibration : str
        One of ``"scale"``, ``"mean"``, ``"max"``, ``"min"``.
    value : float
        The calibration value (k for "scale", cd/m^2 otherwise), finite and > 0.
    rotation_deg : float
        Rotation of the panorama about +z, degrees, counter-clockwise seen from above.
    source : str
        Where the image came from (for reports).

    Raises
    ------
    ValueError
        An image of the wrong shape or with negative or non-finite pixels, an unknown
        calibration, a value <= 0 or not finite, a non-finite rotation, an image whose
        luminance is zero everywhere with calibration "mean" or "max", or an image with a pixel of
        zero luminance with calibration "min".
    """

    def __init__(
        self,
        image,
        calibration: str,
        value: float,
        rotation_deg: float = 0.0,
        source: str = "",
    ):
        image = np.asarray(image)
        if image.ndim != 3 or image.shape[2] != 3 or image.shape[0] == 0 or image.shape[1] == 0:
            raise ValueError(f"image must have shape (H, W, 3), got {image.shape}")
        dtype = np.float32 if image.dtype == np.float32 else np.float64
        self._image = np.array(image, dtype=dtype)
        self._image.flags.writeable = False
        if not np.all(np.isfinite(self._image)):
            raise ValueError("image has non-finite pixels")
        if np.any(self._image < 0):
            raise ValueError("image has negative pixels")
        if calibration not in CALIBRATION_MODES:
            raise ValueError(
                f"unknown calibration {calibration!r}; expected one of {CALIBRATION_MODES}"
            )
        if not (math.isfinite(value) and value > 0):
            raise ValueError(f"calibration value must be finite and > 0, got {value}")
        if not math.isfinite(rotation_deg):
            raise ValueError(f"rotation must be finite, got {rotation_deg}")
        Y = luminance(self._image)
        raw_mean = float(row_solid_angle_fractions(Y.shape[0]) @ Y.mean(axis=1))
        raw_max = float(Y.max())
        raw_min = float(Y.min())
        if calibration != "scale" and raw_max == 0.0:
            raise ValueError(
                f"image luminance is zero everywhere; calibration {calibration!r} cannot scale it"
            )
        if calibration == "min" and raw_min == 0.0:
            raise ValueError(
                f"{int(np.count_nonzero(Y == 0.0))} of its {Y.size} pixels are black; calibration 'min' "
                "cannot scale a minimum of zero (use 'scale', 'mean' or 'max')"
            )
        self.calibration = calibration
        self.value = float(value)
        self.rotation_deg = float(rotation_deg)
        self.source = source
        if calibration == "scale":
            self._k = self.value
        elif calibration == "mean":
            self._k = self.value / raw_mean
        elif calibration == "max":
            self._k = self.value / raw_max
        else:
            self._k = self.value / raw_min
        self._mean = self._k * raw_mean
        self._max = self._k * raw_max
        self._min = self._k * raw_min
        angle = math.radians(self.rotation_deg)
        self._cos, self._sin = math.cos(angle), math.sin(angle)
        # Sampling: pixels in proportion to luminance times solid angle (row fractions), built once.
        self._weights = None

    def _distribution(self):
        """(pixel distribution over H * W row-major, the pixels' solid angles (H,) sr), built on first use."""
        if self._weights is None:
            h, w = self._image.shape[:2]
            omega = 4.0 * np.pi * row_solid_angle_fractions(h) / w  # sr per pixel of each row
            weights = luminance(self._image) * omega[:, None]
            self._weights = (Distribution1D(weights.ravel()) if weights.max() > 0 else None, omega)
        return self._weights

    @property
    def scale_factor(self) -> float:
        """k: the factor applied to the image's own linear values (the value itself for
        "scale"; cd/m^2 per unit of image luminance for "mean", "max" and "min")."""
        return self._k

    def _to_image(self, d: np.ndarray) -> np.ndarray:
        """World directions (3, n) to the panorama's frame: rotated by -rotation_deg about +z."""
        x = self._cos * d[0] + self._sin * d[1]
        y = -self._sin * d[0] + self._cos * d[1]
        return np.stack([x, y, d[2]])

    def radiance(self, d) -> np.ndarray:
        u, v = direction_to_equirect(self._to_image(as_directions(d)))
        return self._k * _bilinear(self._image, u, v)

    def sample(self, u):
        """A pixel in proportion to its luminance times its solid angle (u[0]), then a direction
        uniform in solid angle inside it (azimuth and sin(latitude) uniform in the pixel's band)."""
        dist, omega = self._distribution()
        h, w = self._image.shape[:2]
        idx, pmf = dist.invert(u[0])
        row, column = idx // w, idx % w
        # Reuse u[0]'s position inside the chosen pixel's cdf step for the azimuth (stratified).
        lo = np.where(idx > 0, dist.cdf[np.maximum(idx - 1, 0)], 0.0)
        frac = np.clip((u[0] * dist.total - lo) / np.maximum(dist.cdf[idx] - lo, 1e-300), 0.0, 1.0)
        uu = (column + frac) / w
        z_top = np.sin(0.5 * np.pi - np.pi * row / h)
        z_bottom = np.sin(0.5 * np.pi - np.pi * (row + 1) / h)
        z = z_bottom + u[1] * (z_top - z_bottom)
        r = np.sqrt(np.maximum(0.0, 1.0 - z * z))
        azimuth = np.pi * (1.0 - 2.0 * uu)
        local = np.stack([r * np.cos(azimuth), r * np.sin(azimuth), z])
        # Back to the world: rotate by +rotation_deg about +z.
        d = np.stack([self._cos * local[0] - self._sin * local[1], self._sin * local[0] + self._cos * local[1],
                      local[2]])
        return d, self.radiance(d), pmf / omega[row]

    def pdf(self, d):
        dist, omega = self._distribution()
        if dist is None:
            return np.zeros(np.shape(d)[1])
        h, w = self._image.shape[:2]
        u, v = direction_to_equirect(self._to_image(as_directions(d)))
        column = np.clip(np.floor(u * w).astype(np.int64), 0, w - 1)
        row = np.clip(np.floor((1.0 - v) * h).astype(np.int64), 0, h - 1)
        return dist.pmf(row * w + column) / omega[row]

    @property
    def mean_luminance(self) -> float:
        """Solid-angle-weighted mean pixel luminance, cd/m^2 (the measure of the "mean"
        calibration; the mean of the bilinearly interpolated radiance differs from it by far
        less than 1 % for panoramas of useful size)."""
        return self._mean

    @property
    def max_luminance(self) -> float:
        """Largest pixel luminance, cd/m^2."""
        return self._max

    @property
    def min_luminance(self) -> float:
        """Smallest pixel luminance, cd/m^2 (the measure of the "min" calibration; also the
        smallest radiance returned)."""
        return self._min
