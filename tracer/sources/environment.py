"""The environment: what a ray sees when it leaves the scene (the scene.json "environment").

An environment gives the radiance arriving from infinitely far away along a direction, in
linear Rec.709 RGB scaled so that :func:`tracer.core.units.luminance` of it is the luminance in
cd/m^2. World axes: z is up (as in Blender); directions are unit vectors.

Three kinds exist: :class:`NoEnvironment` (black), :class:`UniformEnvironment` (the same
luminance everywhere) and :class:`HdriEnvironment` (an equirectangular panorama, calibrated
to a luminance). :func:`environment_from_spec` builds one from scene.json.

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

A sun (:class:`Sun`: a uniform disk of a given illuminance and angular diameter) can be added to any of
them (:class:`EnvironmentWithSun`); the sum is an environment like the others, so every method that
reads, samples or weighs an environment sees the sun without knowing of it.
"""

from __future__ import annotations

import json
import math
from abc import ABC, abstractmethod
from pathlib import Path

import numpy as np

from ..core.errors import ImageReadError, SceneError
from ..core.imageio import read_image
from ..core.sampling import Distribution1D, frame_from_normal, to_world, uniform_sphere
from ..core.units import Y_WEIGHTS, luminance, normalize_color
from ..core.validate import MAX_ABS, MAX_LUMINANCE, MIN_LUMINANCE, FieldChecker
from ..core.vec import dot, norm

#: Calibration modes of :class:`HdriEnvironment`.
CALIBRATION_MODES = ("scale", "mean", "max", "min")

#: The sun's defaults: illuminance on a surface facing it, lx (a clear summer noon at sea level is
#: about 1e5 lx); angular diameter, deg (the solar disk seen from the Earth: 0.524 to 0.542 over the
#: year).
SUN_ILLUMINANCE_LX = 100_000.0
SUN_ANGULAR_DIAMETER_DEG = 0.53
#: Largest angular diameter of a sun, deg (a disk beyond this is no longer a sun but a patch of sky).
SUN_MAX_ANGULAR_DIAMETER_DEG = 20.0


def _as_directions(d) -> np.ndarray:
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
    d = _as_directions(d)
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
        return np.zeros((3, _as_directions(d).shape[1]))

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
        return np.repeat(self._rgb[:, None], _as_directions(d).shape[1], axis=1)

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
        u, v = direction_to_equirect(self._to_image(_as_directions(d)))
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
        u, v = direction_to_equirect(self._to_image(_as_directions(d)))
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


class Sun(Environment):
    """The sun: a disk of uniform luminance, infinitely far, of a given illuminance and size.

    A disk of angular radius delta and luminance L lights a surface that faces it with the
    illuminance E = integral over the cone of L cos(theta) d omega = 2 pi L integral_0^delta
    cos(theta) sin(theta) d theta = pi L sin^2(delta) (the view factor sin^2(delta) of a coaxial
    disk from a point: Howell, "A Catalog of Radiation Heat Transfer Configuration Factors", factor
    B-13; Modest, "Radiative Heat Transfer", 3rd ed., doi:10.1016/C2010-0-65874-3, app. D), so the
    disk's luminance is ``L = E / (pi sin^2 delta)``: 1.49e9 cd/m^2 for 100,000 lx at 0.53 deg. The
    integral of the direction over the cone is parallel to its axis, so a surface whose normal makes
    the angle i with the sun's direction receives exactly E cos(i) while the whole disk lies above its
    horizon.

    Sampling: directions uniform in solid angle over the disk's cone (cos(theta) uniform in
    [cos(delta), 1]; Pharr, Jakob and Humphreys, "Physically Based Rendering", 3rd ed., sec. 13.6.4),
    density 1 / (2 pi (1 - cos delta)) per steradian. 1 - cos is computed as 2 sin^2(delta / 2), and a
    direction's 1 - cos(theta) from its dot product with the axis in float64, so that a 0.5 deg disk
    keeps its exact size for float32 directions.

    Parameters
    ----------
    direction : array_like, shape (3,)
        Toward the sun's centre, world axes (z up); any non-zero length (normalised here).
    illuminance_lux : float
        E, lx, on a surface facing the sun; finite and >= 0.
    angular_diameter_deg : float
        2 delta, degrees, in (0, :data:`SUN_MAX_ANGULAR_DIAMETER_DEG`].
    color : array_like, shape (3,)
        Linear Rec.709, normalised to unit luminance (:func:`tracer.core.units.normalize_color`).

    Raises
    ------
    ValueError
        A zero or non-finite direction, a negative or non-finite illuminance, an angular diameter
        outside its range, a colour with a negative component or zero luminance.
    """

    def __init__(self, direction, illuminance_lux: float = SUN_ILLUMINANCE_LX,
                 angular_diameter_deg: float = SUN_ANGULAR_DIAMETER_DEG, color=(1.0, 1.0, 1.0)):
        d = np.asarray(direction, dtype=np.float64).reshape(3)
        length = float(np.linalg.norm(d))
        if not (math.isfinite(length) and length > 0):
            raise ValueError(f"the sun's direction must be finite and non-zero, got {d.tolist()}")
        if not (math.isfinite(illuminance_lux) and illuminance_lux >= 0):
            raise ValueError(f"the sun's illuminance must be finite and >= 0 lx, got {illuminance_lux}")
        if not (0 < angular_diameter_deg <= SUN_MAX_ANGULAR_DIAMETER_DEG):
            raise ValueError(f"the sun's angular diameter must lie in (0, {SUN_MAX_ANGULAR_DIAMETER_DEG:g}] deg, "
                             f"got {angular_diameter_deg}")
        self.direction = d / length
        self.illuminance_lux = float(illuminance_lux)
        self.angular_diameter_deg = float(angular_diameter_deg)
        self.color = normalize_color(color)
        delta = math.radians(self.angular_diameter_deg) / 2
        #: 1 - cos(delta), without cancellation.
        self.one_minus_cos = 2.0 * math.sin(delta / 2) ** 2
        #: The disk's solid angle, sr.
        self.solid_angle_sr = 2.0 * math.pi * self.one_minus_cos
        #: The disk's luminance, cd/m^2: E / (pi sin^2 delta).
        self.luminance_cd_m2 = self.illuminance_lux / (math.pi * math.sin(delta) ** 2)
        self._rgb = self.luminance_cd_m2 * self.color
        self._frame = frame_from_normal(self.direction.reshape(3, 1))

    def _inside(self, d: np.ndarray) -> np.ndarray:
        """Whether directions (3, n) float64 of any non-zero length point into the disk."""
        return 1.0 - dot(d, self.direction) / norm(d) <= self.one_minus_cos

    def radiance(self, d) -> np.ndarray:
        inside = self._inside(_as_directions(d))
        return np.where(inside, self._rgb[:, None], 0.0)

    def sample(self, u):
        """Directions uniform over the disk (u (2, n) -> unit directions (3, n), radiance, density)."""
        u = np.asarray(u, dtype=np.float64)
        x = u[0] * self.one_minus_cos  # 1 - cos(theta), uniform in [0, 1 - cos(delta)]
        sin = np.sqrt(x * (2.0 - x))
        phi = 2.0 * np.pi * u[1]
        local = np.stack([sin * np.cos(phi), sin * np.sin(phi), 1.0 - x])
        d = to_world(local, *self._frame)
        n = d.shape[1]
        return d, np.repeat(self._rgb[:, None], n, axis=1), np.full(n, 1.0 / self.solid_angle_sr)

    def pdf(self, d):
        return np.where(self._inside(_as_directions(d)), 1.0 / self.solid_angle_sr, 0.0)

    @property
    def power(self) -> float:
        """The integral of the luminance over the sphere, cd/m^2 sr: L times the disk's solid angle
        (2 E / (1 + cos delta), a little less than E)."""
        return self.luminance_cd_m2 * self.solid_angle_sr

    @property
    def mean_luminance(self) -> float:
        return self.power / (4.0 * math.pi)

    @property
    def max_luminance(self) -> float:
        return self.luminance_cd_m2


class EnvironmentWithSun(Environment):
    """An environment (``base``: none, uniform or an HDRI) with a :class:`Sun` added to it.

    - ``radiance(d)``: the base's plus the sun disk's;
    - ``sample(u)``: one-sample mixture (Veach 1997, sec. 9.2.4, doi:10.5555/927297): the sun with
      probability ``sun_share`` = its power over the sum of both powers (a part's power is the
      integral of its luminance over the sphere, 4 pi times its mean luminance), else the base's own
      importance sampling; ``u[0]`` is rescaled into the chosen part, so the base keeps its
      stratification; the radiance and density returned are the sum's and the mixture's at the
      directions drawn;
    - ``pdf(d)``: the mixture's density, (1 - share) p_base(d) + share p_sun(d), per steradian;
    - ``mean_luminance``: the base's plus the sun's power / (4 pi);
    - ``max_luminance``: the base's largest plus the sun's luminance: a bound of the luminance in
      any direction (what the roulette and the analysis need), reached where the base's brightest
      direction lies inside the disk.

    The calibration of an HDRI base applies to the panorama alone: its ``mean``, ``max`` or ``min``
    is the panorama's, before the sun is added.
    """

    def __init__(self, base: Environment, sun: Sun):
        self.base, self.sun = base, sun
        base_power = 4.0 * math.pi * base.mean_luminance
        total = base_power + sun.power
        #: Probability that :meth:`sample` draws from the sun.
        self.sun_share = sun.power / total if total > 0 else 0.0

    def radiance(self, d) -> np.ndarray:
        d = _as_directions(d)
        return self.base.radiance(d) + self.sun.radiance(d)

    def sample(self, u):
        u = np.asarray(u, dtype=np.float64)
        share = self.sun_share
        from_sun = u[0] < share
        d = np.empty((3, u.shape[1]))
        k = np.flatnonzero(from_sun)
        if len(k):
            d[:, k] = self.sun.sample(np.stack([u[0, k] / share, u[1, k]]))[0]
        k = np.flatnonzero(~from_sun)
        if len(k):
            rest = np.minimum((u[0, k] - share) / (1.0 - share), np.nextafter(1.0, 0.0))
            d[:, k] = self.base.sample(np.stack([rest, u[1, k]]))[0]
        return d, self.radiance(d), self.pdf(d)

    def pdf(self, d):
        d = _as_directions(d)
        p = self.sun_share * self.sun.pdf(d)
        if self.sun_share < 1.0:
            p = p + (1.0 - self.sun_share) * self.base.pdf(d)
        return p

    @property
    def mean_luminance(self) -> float:
        return self.base.mean_luminance + self.sun.mean_luminance

    @property
    def max_luminance(self) -> float:
        return self.base.max_luminance + self.sun.max_luminance


# Fields each environment type accepts in scene.json.
_FIELDS = {
    "none": {"sun"},
    "uniform": {"luminance", "color", "sun"},
    "hdri": {"file", "calibration", "rotation_deg", "sun"},
}
_REQUIRED = {"none": set(), "uniform": {"luminance"}, "hdri": {"file", "calibration"}}
#: Fields of the "sun" block (all but the direction optional).
_SUN_FIELDS = {"illuminance_lux", "angular_diameter_deg", "color"}


def _check_luminous(ck, rgb: np.ndarray, fld: str):
    """Refuse a colour whose luminance is not positive (black, or so dark that it is 0 in floating
    point): it is normalised to unit luminance (tracer.core.units.normalize_color)."""
    if not float(rgb @ Y_WEIGHTS) > 0.0:
        ck.fail(fld, "must have a positive luminance (0.2126 R + 0.7152 G + 0.0722 B): it is black, or so dark that "
                     "its luminance is 0 in floating point")


def _sun_from_spec(ck: FieldChecker, spec) -> Sun:
    """The :class:`Sun` of an environment's "sun" block, validated field by field."""
    ck.obj(spec, "environment.sun")
    ck.keys(spec, "environment.sun", {"direction"}, _SUN_FIELDS)
    direction = ck.unit_vector(spec["direction"], "environment.sun.direction")
    e = ck.number(spec.get("illuminance_lux", SUN_ILLUMINANCE_LX), "environment.sun.illuminance_lux",
                  min_value=0.0, max_value=MAX_LUMINANCE)
    diameter = ck.number(spec.get("angular_diameter_deg", SUN_ANGULAR_DIAMETER_DEG),
                         "environment.sun.angular_diameter_deg", min_value=0.0, min_exclusive=True,
                         max_value=SUN_MAX_ANGULAR_DIAMETER_DEG)
    rgb = ck.rgb(spec.get("color", [1.0, 1.0, 1.0]), "environment.sun.color", max_value=None)
    _check_luminous(ck, rgb, "environment.sun.color")
    sun = Sun(direction, e, diameter, rgb)
    if not sun.luminance_cd_m2 <= MAX_LUMINANCE:
        ck.fail("environment.sun", f"illuminance_lux {e:g} over a disk of {diameter:g} deg gives it a luminance of "
                                   f"{sun.luminance_cd_m2:.3g} cd/m^2 (E / (pi sin^2(diameter / 2))), above "
                                   f"{MAX_LUMINANCE:g}: give a larger angular_diameter_deg or a smaller illuminance")
    if 0 < sun.luminance_cd_m2 < MIN_LUMINANCE:
        ck.fail("environment.sun.illuminance_lux", f"{e:.3g} lx gives the sun's disk a luminance of "
                                                   f"{sun.luminance_cd_m2:.3g} cd/m^2, below {MIN_LUMINANCE:g} "
                                                   "(give 0 for no sun)")
    return sun


def environment_from_spec(spec: dict, scene_dir: Path, file: str = "scene.json",
                          allow_external: bool = False) -> Environment:
    """Build the environment described by the "environment" block of scene.json.

    Accepted blocks (no other fields)::

        {"type": "none"}
        {"type": "uniform", "luminance": L, "color": [r, g, b]}
        {"type": "hdri", "file": "relative/path.exr",
         "calibration": {"mode": "scale" | "mean" | "max" | "min", "value": v},
         "rotation_deg": 0}

    each with an optional sun (:class:`Sun`, added by :class:`EnvironmentWithSun`)::

        "sun": {"direction": [x, y, z], "illuminance_lux": 100000, "angular_diameter_deg": 0.53,
                "color": [r, g, b]}

    with L >= 0 cd/m^2, ``color`` optional (white; linear Rec.709, normalised to unit
    luminance), v > 0 (:class:`HdriEnvironment`), ``rotation_deg`` optional (0); the sun's
    ``direction`` toward it (world axes, z up; normalised), ``illuminance_lux`` >= 0 on a surface
    facing it, ``angular_diameter_deg`` in (0, 20], each but the direction optional (defaults
    above), and its disk's luminance E / (pi sin^2(diameter / 2)) at most 1e12 cd/m^2. The image
    file is relative to ``scene_dir`` and read with :func:`tracer.core.imageio.read_image` (float
    files as stored, integer files sRGB-decoded); 1 channel: grey; 2: grey and alpha;
    3: RGB; 4: RGBA; alpha is dropped.

    Parameters
    ----------
    spec : dict
        The parsed "environment" block.
    scene_dir : pathlib.Path
        The scene folder, against which the image path is resolved.
    file : str
        The scene file's name, for error messages.

    Returns
    -------
    Environment

    Raises
    ------
    SceneError
        With field ``environment.<field>`` for an unknown type, an unknown, missing,
        negative or non-numeric field, a black colour (``environment.sun.<field>`` for those of
        the sun; ``environment.sun`` for a disk brighter than 1e12 cd/m^2); with field
        ``environment.file`` for an image that is missing, unreadable, with more than 4 channels,
        with negative or non-finite pixels, black with calibration "mean" or "max", or with a
        black pixel with calibration "min".
    """
    ck = FieldChecker(file, allow_external)
    ck.obj(spec, "environment")
    if "type" not in spec:
        ck.fail("environment.type", "missing required field")
    kind = spec["type"]
    if not isinstance(kind, str) or kind not in _FIELDS:
        ck.fail("environment.type", f"unknown type {json.dumps(kind)[:40]} (known: {', '.join(_FIELDS)})")
    ck.keys(spec, "environment", _REQUIRED[kind] | {"type"}, _FIELDS[kind] - _REQUIRED[kind])
    sun = _sun_from_spec(ck, spec["sun"]) if "sun" in spec else None
    base = _base_from_spec(ck, kind, spec, scene_dir, file)
    return base if sun is None else EnvironmentWithSun(base, sun)


def _base_from_spec(ck: FieldChecker, kind: str, spec: dict, scene_dir: Path, file: str) -> Environment:
    """The environment of a block whose fields are known to be those of ``kind``, without its sun."""
    if kind == "none":
        return NoEnvironment()

    if kind == "uniform":
        L = ck.number(spec["luminance"], "environment.luminance", min_value=0.0, max_value=MAX_LUMINANCE)
        if 0 < L < MIN_LUMINANCE:
            ck.fail("environment.luminance", f"{L:.3g} cd/m^2 is below {MIN_LUMINANCE:g} (give 0 for no light)")
        rgb = ck.rgb(spec.get("color", [1.0, 1.0, 1.0]), "environment.color", max_value=None)
        _check_luminous(ck, rgb, "environment.color")
        return UniformEnvironment(L, rgb)

    image_file = ck.string(spec["file"], "environment.file")
    cal = ck.obj(spec["calibration"], "environment.calibration")
    ck.keys(cal, "environment.calibration", {"mode", "value"}, set())
    mode = cal["mode"]
    if not isinstance(mode, str) or mode not in CALIBRATION_MODES:
        ck.fail("environment.calibration.mode", f"unknown mode {json.dumps(mode)[:40]} (known: "
                                                f"{', '.join(CALIBRATION_MODES)})")
    limit = MAX_ABS if mode == "scale" else MAX_LUMINANCE
    value = ck.number(cal["value"], "environment.calibration.value", min_value=0.0, min_exclusive=True,
                      max_value=limit)
    rotation = ck.number(spec.get("rotation_deg", 0.0), "environment.rotation_deg", min_value=-1e6, max_value=1e6)

    try:
        pixels = read_image(ck.path(scene_dir, image_file, "environment.file"))
    except ImageReadError as exc:
        raise SceneError(file, "environment.file", f"cannot read {image_file!r}: {exc.reason}") from exc
    try:
        env = HdriEnvironment(panorama_rgb(pixels), mode, value, rotation, source=image_file)
    except ValueError as exc:
        raise SceneError(file, "environment.file", f"{image_file!r}: {exc}") from exc
    if not env.max_luminance <= MAX_LUMINANCE:
        ck.fail("environment.calibration.value", f"makes the panorama's brightest pixel {env.max_luminance!r} "
                                                 f"cd/m^2, above {MAX_LUMINANCE:g}")
    if 0 < env.max_luminance < MIN_LUMINANCE:
        ck.fail("environment.calibration.value", f"makes the panorama's brightest pixel {env.max_luminance:.3g} "
                                                 f"cd/m^2, below {MIN_LUMINANCE:g}")
    return env
