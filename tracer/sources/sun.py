"""The sun: a uniform disk of a given illuminance and angular diameter, added to any environment.

The sum (:class:`EnvironmentWithSun`) is an environment like the others, so every method that reads,
samples or weighs an environment sees the sun without knowing of it.
"""

from __future__ import annotations

import math

import numpy as np

from ..core.sampling import frame_from_normal, to_world
from ..core.units import normalize_color
from ..core.vec import dot, norm
from .environment import Environment, as_directions

#: The sun's defaults: illuminance on a surface facing it, lx (a clear summer noon at sea level is
#: about 1e5 lx); angular diameter, deg (the solar disk seen from the Earth: 0.524 to 0.542 over the
#: year).
SUN_ILLUMINANCE_LX = 100_000.0
SUN_ANGULAR_DIAMETER_DEG = 0.53
#: Largest angular diameter of a sun, deg (a disk beyond this is no longer a sun but a patch of sky).
SUN_MAX_ANGULAR_DIAMETER_DEG = 20.0


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
        inside = self._inside(as_directions(d))
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
        return np.where(self._inside(as_directions(d)), 1.0 / self.solid_angle_sr, 0.0)

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
        d = as_directions(d)
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
        d = as_directions(d)
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
