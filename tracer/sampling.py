"""Random-number streams and the sample warps used by the integrators.

Conventions
-----------
- Every routine takes its uniform random numbers ``u`` in [0, 1) as an argument, so that the
  caller controls the streams (see :func:`make_rng`) and a warp is a pure function of ``u``.
- Directions are unit vectors. In a local frame the z axis is the surface normal or the lobe
  axis; :func:`frame_from_normal`, :func:`to_world` and :func:`to_local` convert.
- Densities of directions are per steradian (sr^-1), densities of points per unit area of the
  surface in the length unit of the inputs (mm^-2 in the tracer, see :mod:`.units`).
- Everything is vectorised over the leading sample axis and computed in float64.
"""

from __future__ import annotations

import numpy as np

from .vec import axpy, dot, norm, scale

#: |cos| between a sampled direction and an aperture's normal below which the direction is
#: treated as grazing the aperture plane: its solid-angle density would be unbounded, so both
#: :func:`sample_disk_aperture` and :func:`disk_aperture_pdf` report a density of 0 there.
GRAZING_COS = 1e-12


def make_rng(seed: int, *stream: int) -> np.random.Generator:
    """A PCG64 generator addressed by a seed and a stream path.

    The same ``(seed, *stream)`` always gives the same numbers, and different paths give
    statistically independent streams, so that work split into batches (``stream = (batch,)``)
    is reproducible whatever the order or the number of workers.

    Parameters
    ----------
    seed : int
        The user's seed (non-negative).
    *stream : int
        Non-negative integers naming the sub-stream, e.g. the batch index.

    Returns
    -------
    numpy.random.Generator
        ``Generator(PCG64(SeedSequence([seed, *stream])))``.

    References
    ----------
    M. E. O'Neill, "PCG: A family of simple fast space-efficient statistically good algorithms
    for random number generation", Harvey Mudd College, HMC-CS-2014-0905 (2014); NumPy's
    ``SeedSequence`` (https://numpy.org/doc/stable/reference/random/parallel.html).
    """
    return np.random.Generator(np.random.PCG64(np.random.SeedSequence([seed, *stream])))


def uniform_disk_concentric(u: np.ndarray) -> np.ndarray:
    """Uniform points on the unit disk by the concentric square-to-disk map.

    Parameters
    ----------
    u : ndarray, shape (n, 2)
        Uniform numbers in [0, 1).

    Returns
    -------
    ndarray, shape (n, 2)
        Points (x, y) with x^2 + y^2 <= 1; density 1/pi per unit area.

    References
    ----------
    P. Shirley and K. Chiu, "A low distortion map between disk and square", Journal of Graphics
    Tools 2(3), 45-52 (1997), doi:10.1080/10867651.1997.10487479.
    """
    u = np.asarray(u, dtype=np.float64)
    a = 2.0 * u[:, 0] - 1.0
    b = 2.0 * u[:, 1] - 1.0
    # Square [-1, 1]^2 -> disk: each point keeps its "square radius" max(|a|, |b|) and is
    # mapped to an angle proportional to its position along that square's side.
    first = np.abs(a) > np.abs(b)
    r = np.where(first, a, b)
    ratio_ab = np.divide(b, a, out=np.zeros_like(a), where=first)
    ratio_ba = np.divide(a, b, out=np.zeros_like(b), where=~first & (b != 0.0))
    phi = np.where(first, 0.25 * np.pi * ratio_ab, 0.5 * np.pi - 0.25 * np.pi * ratio_ba)
    return np.stack([r * np.cos(phi), r * np.sin(phi)], axis=-1)


def cosine_hemisphere(u: np.ndarray) -> np.ndarray:
    """Cosine-weighted directions on the hemisphere z >= 0 (Malley's method).

    A uniform point on the unit disk (:func:`uniform_disk_concentric`) is lifted vertically onto
    the hemisphere.

    Parameters
    ----------
    u : ndarray, shape (n, 2)
        Uniform numbers in [0, 1).

    Returns
    -------
    ndarray, shape (n, 3)
        Unit directions in the local frame; density :func:`cosine_hemisphere_pdf`.

    References
    ----------
    M. Pharr, W. Jakob and G. Humphreys, "Physically Based Rendering", 3rd ed., section 13.6.3
    "Cosine-weighted hemisphere sampling" (https://pbr-book.org/3ed-2018/Monte_Carlo_Integration/
    2D_Sampling_with_Multidimensional_Transformations).
    """
    xy = uniform_disk_concentric(u)
    z = np.sqrt(np.maximum(0.0, 1.0 - dot(xy, xy)))
    return np.concatenate([xy, z[:, None]], axis=-1)


def cosine_hemisphere_pdf(d: np.ndarray) -> np.ndarray:
    """Density of :func:`cosine_hemisphere`: max(d_z, 0) / pi per steradian.

    Parameters
    ----------
    d : ndarray, shape (n, 3)
        Unit directions in the local frame.

    Returns
    -------
    ndarray, shape (n,)
        Density in sr^-1.
    """
    d = np.asarray(d, dtype=np.float64)
    return np.maximum(d[:, 2], 0.0) / np.pi


def uniform_sphere(u: np.ndarray) -> np.ndarray:
    """Uniform directions on the unit sphere; density 1/(4 pi) per steradian.

    z = 1 - 2 u_0 is uniform in [-1, 1] (Archimedes' hat-box theorem) and the azimuth is
    2 pi u_1.

    Parameters
    ----------
    u : ndarray, shape (n, 2)
        Uniform numbers in [0, 1).

    Returns
    -------
    ndarray, shape (n, 3)
        Unit directions.

    References
    ----------
    M. Pharr, W. Jakob and G. Humphreys, "Physically Based Rendering", 3rd ed., section 13.6.1
    "Uniformly sampling a hemisphere" (sphere variant).
    """
    u = np.asarray(u, dtype=np.float64)
    z = 1.0 - 2.0 * u[:, 0]
    r = np.sqrt(np.maximum(0.0, 1.0 - z * z))
    phi = 2.0 * np.pi * u[:, 1]
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=-1)


def uniform_triangle(u: np.ndarray) -> np.ndarray:
    """Barycentric coordinates of uniform points in a triangle.

    With s = sqrt(u_0): b0 = 1 - s, b1 = s (1 - u_1), b2 = s u_1, i.e. the point
    b0 A + b1 B + b2 C is uniform over triangle ABC (density 1/area) for any A, B, C.

    Parameters
    ----------
    u : ndarray, shape (n, 2)
        Uniform numbers in [0, 1).

    Returns
    -------
    ndarray, shape (n, 2)
        (b1, b2); b0 = 1 - b1 - b2.

    References
    ----------
    G. Turk, "Generating random points in triangles", Graphics Gems (1990), pp. 24-28;
    R. Osada, T. Funkhouser, B. Chazelle and D. Dobkin, "Shape distributions", ACM Transactions
    on Graphics 21(4), 807-832 (2002), doi:10.1145/571647.571648.
    """
    u = np.asarray(u, dtype=np.float64)
    s = np.sqrt(u[:, 0])
    return np.stack([s * (1.0 - u[:, 1]), s * u[:, 1]], axis=-1)


def frame_from_normal(
    n: np.ndarray, tangent_hint: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Right-handed orthonormal frames (t, b, n) with t x b = n.

    Without a hint the branch-free construction of Duff et al. is used. With a hint, t is the
    hint's component perpendicular to n (e.g. to keep anisotropic lobes aligned with a surface
    direction); where the hint is (nearly) parallel to n (that component is shorter than
    1e-6 |hint|), the Duff frame is used instead.

    Parameters
    ----------
    n : ndarray, shape (n, 3)
        Normals; they are normalised here.
    tangent_hint : ndarray, shape (n, 3) or (3,), optional
        Preferred tangent direction.

    Returns
    -------
    t, b, n : ndarray, shape (n, 3) each
        Unit tangent, unit bitangent and unit normal.

    References
    ----------
    T. Duff, J. Burgess, P. Christensen, C. Hery, A. Kensler, M. Liani and R. Villemin,
    "Building an orthonormal basis, revisited", Journal of Computer Graphics Techniques 6(1),
    1-8 (2017), http://jcgt.org/published/0006/01/01/.
    """
    n = np.asarray(n, dtype=np.float64)
    n = n / norm(n)[..., None]
    x, y, z = n[..., 0], n[..., 1], n[..., 2]
    sign = np.copysign(1.0, z)
    a = -1.0 / (sign + z)
    c = x * y * a
    t = np.stack([1.0 + sign * x * x * a, sign * c, -sign * x], axis=-1)
    b = np.stack([c, sign + y * y * a, -y], axis=-1)
    if tangent_hint is None:
        return t, b, n

    hint = np.broadcast_to(np.asarray(tangent_hint, dtype=np.float64), n.shape)
    t_hint = hint - dot(hint, n)[..., None] * n
    length = norm(t_hint)[..., None]
    usable = length > 1e-6 * norm(hint)[..., None]
    t_hint = np.divide(t_hint, length, out=np.zeros_like(t_hint), where=usable)
    t = np.where(usable, t_hint, t)
    b = np.where(usable, np.cross(n, t), b)
    return t, b, n


def to_world(v_local: np.ndarray, t: np.ndarray, b: np.ndarray, n: np.ndarray) -> np.ndarray:
    """Local (t, b, n) components to world vectors: x t + y b + z n.

    Parameters
    ----------
    v_local : ndarray, shape (n, 3)
        Vectors in the local frame.
    t, b, n : ndarray, shape (n, 3) each
        An orthonormal frame, as from :func:`frame_from_normal`.

    Returns
    -------
    ndarray, shape (n, 3)
        The vectors in world coordinates.
    """
    v = np.asarray(v_local, dtype=np.float64)
    return axpy(v[:, 2], n, axpy(v[:, 1], b, scale(t, v[:, 0])))  # x t + y b + z n, in this order


def to_local(v_world: np.ndarray, t: np.ndarray, b: np.ndarray, n: np.ndarray) -> np.ndarray:
    """World vectors to their components (v.t, v.b, v.n) in an orthonormal frame.

    Parameters
    ----------
    v_world : ndarray, shape (n, 3)
        Vectors in world coordinates.
    t, b, n : ndarray, shape (n, 3) each
        An orthonormal frame, as from :func:`frame_from_normal`.

    Returns
    -------
    ndarray, shape (n, 3)
        The vectors in the local frame.
    """
    v = np.asarray(v_world, dtype=np.float64)
    return np.stack([dot(v, e) for e in (t, b, n)], axis=-1)


def gaussian_lobe(
    u: np.ndarray, beta0: np.ndarray, sigma: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Directions from a Gaussian scatter lobe in direction-cosine space (ABg-style).

    The projection beta = (d_x, d_y) of the direction onto the local tangent plane is drawn as
    beta = beta0 + sigma * z with z ~ N(0, I_2), from a Box-Muller transform of ``u`` (z_x from
    the cosine, z_y from the sine branch). Samples with |beta| >= 1 are evanescent: they are
    flagged invalid and the caller absorbs them, so the scattered fraction P(|beta| < 1) <= 1
    and energy is conserved.

    Parameters
    ----------
    u : ndarray, shape (n, 2)
        Uniform numbers in [0, 1).
    beta0 : ndarray, shape (n, 2)
        Lobe centre in direction cosines (the specular direction's tangent components).
    sigma : ndarray, shape (2,) or (n, 2)
        Standard deviations of beta_x and beta_y (dimensionless direction cosines, > 0).

    Returns
    -------
    d : ndarray, shape (n, 3)
        Unit directions in the local frame, (beta_x, beta_y, sqrt(1 - |beta|^2)); (0, 0, 1)
        where invalid.
    valid : ndarray of bool, shape (n,)
        |beta| < 1.

    References
    ----------
    J. E. Harvey, "Light-scattering characteristics of optical surfaces", PhD thesis,
    University of Arizona (1976); J. C. Stover, "Optical Scattering: Measurement and Analysis",
    3rd ed., SPIE Press (2012), doi:10.1117/3.975276; G. E. P. Box and M. E. Muller, "A note on
    the generation of random normal deviates", Ann. Math. Statist. 29(2), 610-611 (1958),
    doi:10.1214/aoms/1177706645.
    """
    u = np.asarray(u, dtype=np.float64)
    radius = np.sqrt(-2.0 * np.log1p(-u[:, 0]))
    angle = 2.0 * np.pi * u[:, 1]
    z = np.stack([radius * np.cos(angle), radius * np.sin(angle)], axis=-1)
    beta = np.asarray(beta0, dtype=np.float64) + np.asarray(sigma, dtype=np.float64) * z
    beta_sq = dot(beta, beta)
    valid = beta_sq < 1.0
    d = np.concatenate([beta, np.sqrt(np.maximum(0.0, 1.0 - beta_sq))[:, None]], axis=-1)
    d[~valid] = (0.0, 0.0, 1.0)
    return d, valid


def gaussian_lobe_pdf(d: np.ndarray, beta0: np.ndarray, sigma: np.ndarray) -> np.ndarray:
    """Density of :func:`gaussian_lobe` per steradian.

    pdf(d) = g2(beta - beta0; sigma) * d_z for d_z > 0 and 0 otherwise, with beta = (d_x, d_y)
    and g2 the axis-aligned bivariate normal density; the factor d_z is the Jacobian
    d beta_x d beta_y = d_z d omega. Its integral over the hemisphere is P(|beta| < 1) <= 1.

    Parameters
    ----------
    d : ndarray, shape (n, 3)
        Unit directions in the local frame.
    beta0 : ndarray, shape (n, 2)
        Lobe centre in direction cosines.
    sigma : ndarray, shape (2,) or (n, 2)
        Standard deviations in direction cosines.

    Returns
    -------
    ndarray, shape (n,)
        Density in sr^-1.
    """
    d = np.asarray(d, dtype=np.float64)
    sigma = np.asarray(sigma, dtype=np.float64)
    z = (d[:, :2] - np.asarray(beta0, dtype=np.float64)) / sigma
    g2 = np.exp(-0.5 * dot(z, z)) / (2.0 * np.pi * sigma[..., 0] * sigma[..., 1])
    return np.where(d[:, 2] > 0.0, g2 * d[:, 2], 0.0)


def sample_disk_aperture(
    origins: np.ndarray, center: np.ndarray, normal: np.ndarray, radius: float, u: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Directions from points towards uniform points on a disk (e.g. an eye-box pupil).

    A point is drawn uniformly on the disk (:func:`uniform_disk_concentric` in the frame
    :func:`frame_from_normal` of ``normal``) and the area density 1/(pi radius^2) is converted
    to solid angle at the origin: pdf = dist^2 / (area * |cos|), cos = d . normal.

    Where the direction grazes the disk plane (|cos| <= :data:`GRAZING_COS`, e.g. an origin in
    that plane) or the origin coincides with the sampled point, the density is unbounded; there
    ``pdf`` is 0 and ``d`` is ``normal``, and the caller must treat pdf == 0 as "no sample".

    Parameters
    ----------
    origins : ndarray, shape (n, 3)
        Ray origins (mm).
    center : ndarray, shape (3,)
        Disk centre (mm).
    normal : ndarray, shape (3,)
        Disk normal (normalised here; its sign does not matter).
    radius : float
        Disk radius (mm, > 0).
    u : ndarray, shape (n, 2)
        Uniform numbers in [0, 1).

    Returns
    -------
    d : ndarray, shape (n, 3)
        Unit directions from the origins to the sampled points.
    dist : ndarray, shape (n,)
        Distances to the sampled points (mm).
    pdf : ndarray, shape (n,)
        Solid-angle density of ``d`` (sr^-1); 0 where no sample could be made.

    References
    ----------
    M. Pharr, W. Jakob and G. Humphreys, "Physically Based Rendering", 3rd ed., section 14.2.2
    "Sampling shapes" (area-to-solid-angle density conversion); Shirley and Chiu (1997), see
    :func:`uniform_disk_concentric`.
    """
    origins = np.asarray(origins, dtype=np.float64)
    t, b, nn = (e[0] for e in frame_from_normal(np.asarray(normal, dtype=np.float64)[None, :]))
    xy = radius * uniform_disk_concentric(u)
    v = np.asarray(center, dtype=np.float64) + xy[:, 0:1] * t + xy[:, 1:2] * b - origins
    dist = norm(v)
    d = np.divide(v, dist[:, None], out=np.zeros_like(v), where=dist[:, None] > 0.0)
    cos = np.abs(dot(d, nn))
    ok = cos > GRAZING_COS
    d[~ok] = nn
    pdf = np.divide(dist * dist, np.pi * radius * radius * cos, out=np.zeros_like(dist), where=ok)
    return d, dist, pdf


def disk_aperture_pdf(
    origins: np.ndarray, d: np.ndarray, center: np.ndarray, normal: np.ndarray, radius: float
) -> np.ndarray:
    """Solid-angle density that :func:`sample_disk_aperture` assigns to direction ``d``.

    pdf = dist^2 / (pi radius^2 |cos|) where the ray origin + s d (s > 0) crosses the disk at
    distance dist, and 0 where it misses the disk or grazes its plane
    (|cos| <= :data:`GRAZING_COS`), as in the sampler.

    Parameters
    ----------
    origins : ndarray, shape (n, 3)
        Ray origins (mm).
    d : ndarray, shape (n, 3)
        Unit ray directions.
    center : ndarray, shape (3,)
        Disk centre (mm).
    normal : ndarray, shape (3,)
        Disk normal (normalised here; its sign does not matter).
    radius : float
        Disk radius (mm, > 0).

    Returns
    -------
    ndarray, shape (n,)
        Density in sr^-1.
    """
    origins = np.asarray(origins, dtype=np.float64)
    d = np.asarray(d, dtype=np.float64)
    center = np.asarray(center, dtype=np.float64)
    nn = np.asarray(normal, dtype=np.float64)
    nn = nn / np.linalg.norm(nn)
    cos = dot(d, nn)
    grazing = np.abs(cos) <= GRAZING_COS
    dist = np.divide(dot(center - origins, nn), cos, out=np.zeros_like(cos), where=~grazing)
    offset = origins + dist[:, None] * d - center
    hit = ~grazing & (dist > 0.0) & (dot(offset, offset) <= radius * radius)
    return np.divide(
        dist * dist, np.pi * radius * radius * np.abs(cos), out=np.zeros_like(cos), where=hit
    )


def triangle_areas(tris: np.ndarray) -> np.ndarray:
    """Areas of triangles.

    Parameters
    ----------
    tris : ndarray, shape (m, 3, 3)
        Vertices (mm): ``tris[i, k]`` is vertex k of triangle i.

    Returns
    -------
    ndarray, shape (m,)
        Areas (mm^2).
    """
    tris = np.asarray(tris, dtype=np.float64)
    cross = np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0])
    return 0.5 * norm(cross)


def sample_triangles(
    tris: np.ndarray, u: np.ndarray, areas: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Uniform points on a triangle mesh (density 1/total_area per unit area).

    A triangle is chosen with probability proportional to its area (:func:`sample_discrete` on
    ``u[:, 0]``), then a point uniformly inside it (:func:`uniform_triangle` on ``u[:, 1:]``).

    Parameters
    ----------
    tris : ndarray, shape (m, 3, 3)
        Vertices (mm); at least one triangle must have a positive area.
    u : ndarray, shape (n, 3)
        Uniform numbers in [0, 1).
    areas : ndarray, shape (m,), optional
        :func:`triangle_areas` of ``tris``, for callers that sample the same mesh many times.

    Returns
    -------
    points : ndarray, shape (n, 3)
        Sampled points (mm).
    tri_index : ndarray of int, shape (n,)
        Index of the triangle of each point.
    bary : ndarray, shape (n, 3)
        Barycentric coordinates (b0, b1, b2) of the points in their triangles.

    References
    ----------
    Turk (1990) and Osada et al. (2002), see :func:`uniform_triangle`.
    """
    tris = np.asarray(tris, dtype=np.float64)
    u = np.asarray(u, dtype=np.float64)
    tri_index, _ = sample_discrete(triangle_areas(tris) if areas is None else areas, u[:, 0])
    b12 = uniform_triangle(u[:, 1:])
    bary = np.concatenate([1.0 - b12[:, :1] - b12[:, 1:], b12], axis=-1)
    t = tris[tri_index]
    points = bary[:, :1] * t[:, 0] + bary[:, 1:2] * t[:, 1] + bary[:, 2:3] * t[:, 2]  # fixed summation order
    return points, tri_index, bary


def sample_discrete(weights: np.ndarray, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Indices drawn with probability proportional to non-negative weights (inverse CDF).

    Parameters
    ----------
    weights : ndarray, shape (k,)
        Finite, non-negative weights, not all zero. An index of weight 0 is never returned.
    u : ndarray, shape (n,)
        Uniform numbers in [0, 1).

    Returns
    -------
    idx : ndarray of int, shape (n,)
        Sampled indices.
    pmf : ndarray, shape (n,)
        Their probabilities weights[idx] / sum(weights).

    Raises
    ------
    ValueError
        If a weight is negative or not finite, or all weights are zero.

    References
    ----------
    L. Devroye, "Non-Uniform Random Variate Generation", Springer (1986), section III.2
    (inversion by sequential/binary search), http://luc.devroye.org/rnbookindex.html.
    """
    weights = np.asarray(weights, dtype=np.float64).reshape(-1)
    if not (np.all(np.isfinite(weights)) and np.all(weights >= 0.0) and np.any(weights > 0.0)):
        raise ValueError("weights must be finite, >= 0 and not all zero")
    cdf = np.cumsum(weights)
    total = cdf[-1]
    # The first index with cdf > u * total. Zero weights repeat their predecessor's cdf and
    # are skipped, and u < 1 gives u * total < total in floating point, so idx < k.
    idx = np.searchsorted(cdf, np.asarray(u, dtype=np.float64) * total, side="right")
    return idx, weights[idx] / total
