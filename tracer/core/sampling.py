"""Random-number streams and the sample warps used by the integrators.

Conventions
-----------
- Every routine takes its uniform random numbers ``u`` in [0, 1) as an argument, so that the
  caller controls the streams (see :func:`make_rng`) and a warp is a pure function of ``u``.
- Structure of arrays: ``u`` is (k, n) (one plane per dimension), points and directions are (3, n)
  planes (see :mod:`tracer.core.vec`). Directions are unit vectors. In a local frame the z axis is the
  surface normal or the lobe axis; :func:`frame_from_normal`, :func:`to_world` and :func:`to_local`
  convert.
- Densities of directions are per steradian (sr^-1), densities of points per unit area of the
  surface in the length unit of the inputs (mm^-2 in the tracer, see :mod:`.units`).
- Warps compute in the precision of their random numbers ``u``: the tracer passes float32 (its
  directions are float32, tracer.core.vec); float64 ``u`` give float64 results, with angles still
  evaluated in float32 (numpy's SIMD sin/cos: 0.6 ns against 9 ns in float64) and the densities
  computed from the warped points, so sampler and pdf stay consistent.
- Discrete choices (:class:`Distribution1D`) always take float64 ``u``: a float32 number resolves
  only 2^-24, and a choice among millions of HDRI pixels needs more.
"""

from __future__ import annotations

import numpy as np

from .vec import cross, dot, norm, take

#: |cos| between a sampled direction and an aperture's normal below which the direction is
#: treated as grazing the aperture plane: its solid-angle density would be unbounded, so both
#: :func:`sample_disk_aperture` and :func:`disk_aperture_pdf` report a density of 0 there.
GRAZING_COS = 1e-12

TWO_PI = 2.0 * np.pi


def make_rng(seed: int, *stream: int) -> np.random.Generator:
    """A random generator addressed by a seed and a stream path.

    The same ``(seed, *stream)`` always gives the same numbers, and different paths give
    statistically independent streams, so that work split into batches (``stream = (batch,)``)
    is reproducible whatever the order or the number of workers.

    Returns ``Generator(SFC64(SeedSequence([seed, *stream])))``: Doty-Humphrey's Small Fast Chaotic
    generator (passes PractRand and TestU01's BigCrush; 1.9 ns per double here against 3.2 ns for
    PCG64), seeded through NumPy's ``SeedSequence`` hash, which decorrelates nearby seeds
    (https://numpy.org/doc/stable/reference/random/parallel.html).
    """
    return np.random.Generator(np.random.SFC64(np.random.SeedSequence([seed, *stream])))


def _cos_sin(angle: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """cos and sin of angles (radians) through float32 SIMD kernels, in the angles' precision."""
    a = angle.astype(np.float32, copy=False)
    return np.cos(a).astype(angle.dtype, copy=False), np.sin(a).astype(angle.dtype, copy=False)


def uniform_disk_concentric(u: np.ndarray) -> np.ndarray:
    """Uniform points on the unit disk by the concentric square-to-disk map.

    Parameters
    ----------
    u : (2, n) uniform numbers in [0, 1).

    Returns
    -------
    (2, n) points (x, y) with x^2 + y^2 <= 1; density 1/pi per unit area.

    References
    ----------
    P. Shirley and K. Chiu, "A low distortion map between disk and square", Journal of Graphics
    Tools 2(3), 45-52 (1997), doi:10.1080/10867651.1997.10487479.
    """
    a = 2.0 * u[0] - 1.0
    b = 2.0 * u[1] - 1.0
    # Square [-1, 1]^2 -> disk: each point keeps its "square radius" max(|a|, |b|) and is
    # mapped to an angle proportional to its position along that square's side.
    first = np.abs(a) > np.abs(b)
    r = np.where(first, a, b)
    ratio_ab = np.divide(b, a, out=np.zeros_like(a), where=first)
    ratio_ba = np.divide(a, b, out=np.zeros_like(b), where=~first & (b != 0.0))
    quarter = a.dtype.type(0.25 * np.pi)
    phi = np.where(first, quarter * ratio_ab, 2 * quarter - quarter * ratio_ba)
    c, s = _cos_sin(phi)
    return np.stack([r * c, r * s])


def cosine_hemisphere(u: np.ndarray) -> np.ndarray:
    """Cosine-weighted directions on the hemisphere z >= 0 (Malley's method): a uniform point of
    the unit disk (:func:`uniform_disk_concentric`) lifted onto the hemisphere.

    Parameters
    ----------
    u : (2, n) uniform numbers in [0, 1).

    Returns
    -------
    (3, n) unit directions in the local frame; density :func:`cosine_hemisphere_pdf`.

    References
    ----------
    M. Pharr, W. Jakob and G. Humphreys, "Physically Based Rendering", 3rd ed., section 13.6.3.
    """
    xy = uniform_disk_concentric(u)
    z = np.sqrt(np.maximum(0, 1 - xy[0] * xy[0] - xy[1] * xy[1]))
    return np.concatenate([xy, z[None]])


def cosine_hemisphere_pdf(d: np.ndarray) -> np.ndarray:
    """Density of :func:`cosine_hemisphere`: max(d_z, 0) / pi per steradian; ``d`` (3, n) local."""
    return np.maximum(d[2], 0) * (1 / np.pi)


def uniform_sphere(u: np.ndarray) -> np.ndarray:
    """Uniform directions on the unit sphere, (3, n) from u (2, n); density 1/(4 pi) per steradian.

    z = 1 - 2 u_0 is uniform in [-1, 1] (Archimedes' hat-box theorem) and the azimuth is 2 pi u_1
    (Pharr, Jakob and Humphreys, "Physically Based Rendering", 3rd ed., section 13.6.1).
    """
    z = 1 - 2 * u[0]
    r = np.sqrt(np.maximum(0, 1 - z * z))
    c, s = _cos_sin(TWO_PI * u[1])
    return np.stack([r * c, r * s, z])


def uniform_triangle(u: np.ndarray) -> np.ndarray:
    """Barycentric coordinates (b1, b2), (2, n), of uniform points in a triangle.

    With s = sqrt(u_0): b0 = 1 - s, b1 = s (1 - u_1), b2 = s u_1, i.e. the point
    b0 A + b1 B + b2 C is uniform over triangle ABC (density 1/area) for any A, B, C (G. Turk,
    "Generating random points in triangles", Graphics Gems (1990); Osada et al., ACM TOG 21(4) 2002,
    doi:10.1145/571647.571648).
    """
    s = np.sqrt(u[0])
    return np.stack([s * (1 - u[1]), s * u[1]])


def frame_from_normal(n: np.ndarray, tangent_hint: np.ndarray | None = None):
    """Right-handed orthonormal frames (t, b, n) with t x b = n, each (3, n).

    Without a hint the branch-free construction of Duff et al. is used. With a hint ((3,) or
    (3, n)), t is the hint's component perpendicular to n (to keep anisotropic lobes aligned with a
    surface direction); where the hint is (nearly) parallel to n (that component is shorter than
    1e-6 |hint|), the Duff frame is used instead. ``n`` is normalised here.

    References
    ----------
    T. Duff, J. Burgess, P. Christensen, C. Hery, A. Kensler, M. Liani and R. Villemin,
    "Building an orthonormal basis, revisited", JCGT 6(1), 1-8 (2017), http://jcgt.org/published/0006/01/01/.
    """
    n = n * (1 / norm(n))
    x, y, z = n[0], n[1], n[2]
    sign = np.copysign(n.dtype.type(1), z)
    a = -1 / (sign + z)
    c = x * y * a
    t = np.stack([1 + sign * x * x * a, sign * c, -sign * x])
    b = np.stack([c, sign + y * y * a, -y])
    if tangent_hint is None:
        return t, b, n
    hint = np.asarray(tangent_hint, dtype=n.dtype)
    if hint.ndim == 1:
        hint = hint[:, None]
    t_hint = hint - dot(hint, n) * n
    length = norm(t_hint)
    usable = length > 1e-6 * norm(hint)
    t = np.where(usable, t_hint / np.where(usable, length, 1), t)
    b = np.where(usable, cross(n, t), b)
    return t, b, n


def to_world(v: np.ndarray, t: np.ndarray, b: np.ndarray, n: np.ndarray) -> np.ndarray:
    """Local (t, b, n) components (3, n) to world vectors x t + y b + z n (summed in this order)."""
    return v[0] * t + v[1] * b + v[2] * n


def to_local(v: np.ndarray, t: np.ndarray, b: np.ndarray, n: np.ndarray) -> np.ndarray:
    """World vectors (3, n) to their components (v.t, v.b, v.n) in an orthonormal frame."""
    return np.stack([dot(v, t), dot(v, b), dot(v, n)])


def gaussian_lobe(u: np.ndarray, beta0: np.ndarray, sigma: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Directions from a Gaussian scatter lobe in direction-cosine space (ABg-style).

    The projection beta = (d_x, d_y) of the direction onto the local tangent plane is drawn as
    beta = beta0 + sigma * z with z ~ N(0, I_2), from a Box-Muller transform of ``u`` (z_x from
    the cosine, z_y from the sine branch). Samples with |beta| >= 1 are evanescent: they are
    flagged invalid and the caller absorbs them, so the scattered fraction P(|beta| < 1) <= 1
    and energy is conserved.

    Parameters
    ----------
    u : (2, n) uniform numbers in [0, 1).
    beta0 : (2, n) lobe centre in direction cosines (the undeviated direction's tangent components).
    sigma : (2,) or (2, n) standard deviations of beta_x and beta_y (direction cosines, > 0).

    Returns
    -------
    d : (3, n) unit directions in the local frame, (beta_x, beta_y, sqrt(1 - |beta|^2)); (0, 0, 1)
        where invalid.
    valid : (n,) bool, |beta| < 1.

    References
    ----------
    J. E. Harvey, "Light-scattering characteristics of optical surfaces", PhD thesis, University of
    Arizona (1976); J. C. Stover, "Optical Scattering", 3rd ed., SPIE Press (2012),
    doi:10.1117/3.975276; G. E. P. Box and M. E. Muller, Ann. Math. Statist. 29(2), 610-611 (1958),
    doi:10.1214/aoms/1177706645.
    """
    radius = np.sqrt(-2 * np.log(1 - u[0]))
    c, s = _cos_sin(TWO_PI * u[1])
    sigma = np.asarray(sigma, dtype=u.dtype)
    if sigma.ndim == 1:
        sigma = sigma[:, None]
    bx = beta0[0] + sigma[0] * (radius * c)
    by = beta0[1] + sigma[1] * (radius * s)
    beta_sq = bx * bx + by * by
    valid = beta_sq < 1
    z = np.sqrt(np.maximum(0, 1 - beta_sq))
    zero = bx.dtype.type(0)
    d = np.stack([np.where(valid, bx, zero), np.where(valid, by, zero), np.where(valid, z, zero + 1)])
    return d, valid


def gaussian_lobe_pdf(d: np.ndarray, beta0: np.ndarray, sigma: np.ndarray) -> np.ndarray:
    """Density of :func:`gaussian_lobe` per steradian, (n,).

    pdf(d) = g2(beta - beta0; sigma) * d_z for d_z > 0 and 0 otherwise, with beta = (d_x, d_y) and
    g2 the axis-aligned bivariate normal density; the factor d_z is the Jacobian
    d beta_x d beta_y = d_z d omega. Its integral over the hemisphere is P(|beta| < 1) <= 1.
    ``d`` (3, n) local, ``beta0`` (2, n), ``sigma`` (2,) or (2, n).
    """
    sigma = np.asarray(sigma, dtype=d.dtype)
    if sigma.ndim == 1:
        sigma = sigma[:, None]
    zx = (d[0] - beta0[0]) * (1 / sigma[0])
    zy = (d[1] - beta0[1]) * (1 / sigma[1])
    g2 = np.exp(-0.5 * (zx * zx + zy * zy)) * (1 / (TWO_PI * sigma[0] * sigma[1]))
    return np.where(d[2] > 0, g2 * d[2], d.dtype.type(0))


def sample_disk_aperture(origins: np.ndarray, center: np.ndarray, normal: np.ndarray, radius: float,
                         u: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Directions from points toward uniform points of a disk (an eye pupil, a virtual aperture).

    A point is drawn uniformly on the disk (:func:`uniform_disk_concentric` in the frame
    :func:`frame_from_normal` of ``normal``) and the area density 1/(pi radius^2) is converted to
    solid angle at the origin: pdf = dist^2 / (area |cos|), cos = d . normal. Where the direction
    grazes the disk plane (|cos| <= :data:`GRAZING_COS`) or the origin coincides with the sampled
    point, the density is unbounded; there ``pdf`` is 0 and ``d`` is ``normal``: the caller must
    treat pdf == 0 as "no sample".

    Parameters
    ----------
    origins : (3, n) mm. center : (3,) mm. normal : (3,) (sign irrelevant). radius : mm, > 0.
    u : (2, n) uniform numbers.

    Returns
    -------
    d : (3, n) unit directions; dist : (n,) mm; pdf : (n,) sr^-1 (0 where no sample could be made).

    References
    ----------
    Pharr, Jakob and Humphreys, "Physically Based Rendering", 3rd ed., section 14.2.2 (area to solid
    angle); Shirley and Chiu (1997), see :func:`uniform_disk_concentric`.
    """
    nn = np.asarray(normal, dtype=np.float64).reshape(3, 1)
    t, b, nn = frame_from_normal(nn)
    xy = radius * uniform_disk_concentric(u)
    v = np.asarray(center, dtype=np.float64).reshape(3, 1) + xy[0] * t + xy[1] * b - origins
    dist = norm(v)
    safe = np.where(dist > 0.0, dist, 1.0)
    d = v / safe
    cos = np.abs(dot(d, nn))
    ok = (cos > GRAZING_COS) & (dist > 0.0)
    d = np.where(ok, d, nn)
    pdf = np.where(ok, dist * dist / (np.pi * radius * radius * np.where(ok, cos, 1.0)), 0.0)
    return d, dist, pdf


def disk_aperture_pdf(origins: np.ndarray, d: np.ndarray, center: np.ndarray, normal: np.ndarray,
                      radius: float) -> np.ndarray:
    """Solid-angle density that :func:`sample_disk_aperture` assigns to directions ``d`` (3, n) from
    ``origins`` (3, n): dist^2 / (pi radius^2 |cos|) where the ray crosses the disk at distance dist,
    0 where it misses the disk or grazes its plane. (n,) sr^-1."""
    c = np.asarray(center, dtype=np.float64).reshape(3, 1)
    nn = np.asarray(normal, dtype=np.float64).reshape(3, 1)
    nn = nn / np.linalg.norm(nn)
    cos = dot(d, nn)
    grazing = np.abs(cos) <= GRAZING_COS
    dist = np.where(grazing, 0.0, dot(c - origins, nn) / np.where(grazing, 1.0, cos))
    off = origins + dist * d - c
    hit = ~grazing & (dist > 0.0) & (dot(off, off) <= radius * radius)
    return np.where(hit, dist * dist / (np.pi * radius * radius * np.where(hit, np.abs(cos), 1.0)), 0.0)


class Distribution1D:
    """A discrete distribution proportional to non-negative weights.

    :meth:`sample` uses Walker's alias table (built by Vose's method: M. D. Vose, "A linear algorithm
    for generating random numbers with a given distribution", IEEE TSE 17(9), 972-975 (1991),
    doi:10.1109/32.92917): one comparison per sample whatever the number of weights. :meth:`invert` is
    the inverse of the cumulative distribution (L. Devroye, "Non-Uniform Random Variate Generation",
    Springer 1986, section III.2), for callers that reuse the position of ``u`` inside the chosen
    interval. Raises ValueError if a weight is negative or not finite, or all weights are zero; an
    index of weight 0 is never returned.
    """

    def __init__(self, weights):
        w = np.asarray(weights, dtype=np.float64).reshape(-1)
        if not (np.all(np.isfinite(w)) and np.all(w >= 0.0) and np.any(w > 0.0)):
            raise ValueError("weights must be finite, >= 0 and not all zero")
        self.cdf = np.cumsum(w)
        self.total = float(self.cdf[-1])
        self.pmf_table = w / self.total
        k = len(w)
        scaled = self.pmf_table * k
        self.prob = np.ones(k)
        self.alias = np.arange(k)
        small = [i for i in range(k) if scaled[i] < 1.0]
        large = [i for i in range(k) if scaled[i] >= 1.0]
        while small and large:
            s, g = small.pop(), large.pop()
            self.prob[s], self.alias[s] = scaled[s], g
            scaled[g] -= 1.0 - scaled[s]
            (small if scaled[g] < 1.0 else large).append(g)
        for i in small:  # left over by rounding: they keep themselves, unless they weigh nothing
            if w[i] == 0.0:
                self.prob[i], self.alias[i] = 0.0, int(np.argmax(w))

    def sample(self, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(indices (n,), their probabilities (n,)) for uniform ``u`` (n,), by the alias table."""
        x = np.asarray(u, dtype=np.float64) * len(self.prob)
        i = np.minimum(x.astype(np.int64), len(self.prob) - 1)
        idx = np.where(x - i < self.prob[i], i, self.alias[i])
        return idx, self.pmf_table[idx]

    def invert(self, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(indices, probabilities) by inverting the cumulative distribution: the first index whose
        cumulative weight exceeds u * total (zero weights repeat their predecessor's and are skipped)."""
        idx = np.searchsorted(self.cdf, np.asarray(u, dtype=np.float64) * self.total, side="right")
        idx = np.minimum(idx, len(self.cdf) - 1)  # u rounded up to 1 stays in range
        return idx, self.pmf_table[idx]

    def pmf(self, idx: np.ndarray) -> np.ndarray:
        return self.pmf_table[idx]


class TriangleSet:
    """Triangles (world mm) as planes for sampling: corner v0, edges e1 = v1 - v0, e2 = v2 - v0 and
    unit normals (e1 x e2), each (3, m); areas (m,) mm^2."""

    def __init__(self, tris: np.ndarray):
        tris = np.asarray(tris, dtype=np.float64)
        self.v0 = np.ascontiguousarray(tris[:, 0].T)
        self.e1 = np.ascontiguousarray((tris[:, 1] - tris[:, 0]).T)
        self.e2 = np.ascontiguousarray((tris[:, 2] - tris[:, 0]).T)
        c = cross(self.e1, self.e2)
        length = norm(c)
        self.area = 0.5 * length
        self.normal = c / np.where(length > 0, length, 1.0)

    def __len__(self) -> int:
        return len(self.area)

    def point(self, tri: np.ndarray, u: np.ndarray) -> np.ndarray:
        """Uniform points (3, n) on triangles ``tri`` (n,) from u (2, n) (:func:`uniform_triangle`)."""
        b = uniform_triangle(u)
        return (take(self.v0, tri) + b[0] * take(self.e1, tri)
                + b[1] * take(self.e2, tri))


