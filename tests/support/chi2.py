"""Chi-square goodness-of-fit test of a sampling routine against its claimed density.

In the manner of Mitsuba 3's ``mitsuba/python/chi2.py``: samples are mapped to a 2D domain
rectangle and histogrammed, the density is integrated over every histogram cell to get the
expected counts, cells with small expected counts are pooled, and Pearson's chi^2 statistic
is compared with the chi^2 distribution. One extra cell collects the samples that are invalid
or fall outside the rectangle; its expected count is the density's missing mass, so a sampler
whose density integrates to less than 1 over the rectangle (absorbed or truncated samples) is
tested as well.

References
----------
W. H. Press, S. A. Teukolsky, W. T. Vetterling and B. P. Flannery, "Numerical Recipes", 3rd ed.
(2007), sections 6.2 (incomplete gamma function) and 14.3 (chi-square test); W. Jakob et al.,
Mitsuba 3, https://github.com/mitsuba-renderer/mitsuba3 (``src/python/python/chi2.py``).
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

#: Cells expected to receive fewer samples than this are pooled (Numerical Recipes section 14.3).
MIN_EXPECTED = 5.0

#: Gauss-Legendre nodes per axis and cell used to integrate the density.
QUADRATURE_ORDER = 6

_EPS = 1e-15
_TINY = 1e-300
_MAX_ITERATIONS = 100_000


def gamma_q(a: float, x: float) -> float:
    """Regularised upper incomplete gamma function Q(a, x) = Gamma(a, x) / Gamma(a).

    Series for P = 1 - Q where x < a + 1, modified Lentz continued fraction for Q otherwise
    (Numerical Recipes, 3rd ed., section 6.2). The chi^2 survival function is
    Q(dof / 2, chi2 / 2).

    Parameters
    ----------
    a : float
        Shape, > 0.
    x : float
        Argument, >= 0.

    Returns
    -------
    float
        Q(a, x) in [0, 1].
    """
    if a <= 0.0 or x < 0.0:
        raise ValueError(f"gamma_q needs a > 0 and x >= 0, got a={a}, x={x}")
    if x == 0.0:
        return 1.0
    prefactor = math.exp(-x + a * math.log(x) - math.lgamma(a))
    if x < a + 1.0:
        term = total = 1.0 / a
        ap = a
        for _ in range(_MAX_ITERATIONS):
            ap += 1.0
            term *= x / ap
            total += term
            if abs(term) < abs(total) * _EPS:
                return max(0.0, 1.0 - total * prefactor)
    else:
        b = x + 1.0 - a
        c = 1.0 / _TINY
        d = 1.0 / b
        h = d
        for i in range(1, _MAX_ITERATIONS):
            an = -i * (i - a)
            b += 2.0
            d = an * d + b
            d = _TINY if abs(d) < _TINY else d
            c = b + an / c
            c = _TINY if abs(c) < _TINY else c
            d = 1.0 / d
            delta = d * c
            h *= delta
            if abs(delta - 1.0) < _EPS:
                return min(1.0, prefactor * h)
    raise RuntimeError(f"gamma_q({a}, {x}) did not converge")


class ChiSquareTest:
    """Chi-square test of a 2D sample distribution against a density.

    Parameters
    ----------
    bounds : ((float, float), (float, float))
        The domain rectangle ((x0, x1), (y0, y1)).
    resolution : (int, int)
        Histogram cells (nx, ny) over the rectangle.
    sample_func : callable
        ``sample_func(n, rng) -> (pts, valid)`` with ``pts`` of shape (n, 2) in the domain
        coordinates and ``valid`` a bool array of shape (n,); ``rng`` is a
        ``numpy.random.Generator``. Invalid samples and samples outside the rectangle are
        counted in the extra "outside" cell.
    pdf_func : callable
        ``pdf_func(x, y) -> density``, arrays of shape (k,), the density of the valid samples
        per unit area of the domain coordinates. Its mass missing from the rectangle is the
        expected fraction of the outside cell.
    sample_count : int
        Number of samples.
    seed : int
        Seed of the generator passed to ``sample_func``.
    order : int
        Gauss-Legendre nodes per axis and cell (densities with jumps inside cells, such as the rim
        of an aperture, need more than the default).
    """

    def __init__(
        self,
        bounds: tuple[tuple[float, float], tuple[float, float]],
        resolution: tuple[int, int],
        sample_func: Callable[[int, np.random.Generator], tuple[np.ndarray, np.ndarray]],
        pdf_func: Callable[[np.ndarray, np.ndarray], np.ndarray],
        sample_count: int = 1_000_000,
        seed: int = 0,
        order: int = QUADRATURE_ORDER,
    ):
        (self.x0, self.x1), (self.y0, self.y1) = bounds
        self.nx, self.ny = resolution
        self.sample_func = sample_func
        self.pdf_func = pdf_func
        self.sample_count = int(sample_count)
        self.seed = seed
        self.order = order

    def observed(self) -> np.ndarray:
        """Sample counts: shape (nx * ny + 1,), cell (i, j) at i * ny + j, the outside cell last."""
        pts, valid = self.sample_func(self.sample_count, np.random.default_rng(self.seed))
        x, y = pts[:, 0], pts[:, 1]
        inside = valid & (x >= self.x0) & (x < self.x1) & (y >= self.y0) & (y < self.y1)
        ix = ((x[inside] - self.x0) * (self.nx / (self.x1 - self.x0))).astype(np.int64)
        iy = ((y[inside] - self.y0) * (self.ny / (self.y1 - self.y0))).astype(np.int64)
        cell = np.minimum(ix, self.nx - 1) * self.ny + np.minimum(iy, self.ny - 1)
        counts = np.bincount(cell, minlength=self.nx * self.ny)
        return np.append(counts, self.sample_count - np.count_nonzero(inside))

    def expected(self) -> np.ndarray:
        """Expected counts, laid out as :meth:`observed`.

        The density is integrated over each cell by a tensor Gauss-Legendre rule of ``order``
        nodes per axis; the outside cell gets the remaining mass, clipped at 0.

        Raises
        ------
        ValueError
            If the density is negative or not finite at a quadrature node.
        """
        nodes, weights = np.polynomial.legendre.leggauss(self.order)
        hx = (self.x1 - self.x0) / self.nx
        hy = (self.y1 - self.y0) / self.ny
        x = self.x0 + hx * (np.arange(self.nx)[:, None] + 0.5 * (nodes + 1.0))
        y = self.y0 + hy * (np.arange(self.ny)[:, None] + 0.5 * (nodes + 1.0))
        xx, yy = np.meshgrid(x.ravel(), y.ravel(), indexing="ij")
        f = np.asarray(self.pdf_func(xx.ravel(), yy.ravel()), dtype=np.float64)
        if not np.all(np.isfinite(f)) or np.any(f < 0.0):
            raise ValueError("the density must be finite and >= 0")
        f = f.reshape(self.nx, self.order, self.ny, self.order)
        mass = np.einsum("iajb,a,b->ij", f, weights, weights).ravel() * (0.25 * hx * hy)
        return self.sample_count * np.append(mass, max(0.0, 1.0 - mass.sum()))

    def run(self, significance: float = 0.01, test_count: int = 1) -> tuple[bool, str]:
        """Run the test.

        Parameters
        ----------
        significance : float
            Family-wise probability of rejecting a correct sampler.
        test_count : int
            Number of tests in the family; each uses the Sidak-corrected level
            1 - (1 - significance) ** (1 / test_count).

        Returns
        -------
        ok : bool
            False if the sampler is rejected: a sample fell where the density is zero, too few
            cells remain after pooling, or the p-value is below the corrected level.
        message : str
            The statistic, degrees of freedom, p-value and level, or the reason for failing.
        """
        observed = self.observed()
        try:
            expected = self.expected()
        except ValueError as err:
            return False, str(err)
        stray = (expected == 0.0) & (observed > 0)
        if np.any(stray):
            return False, (
                f"{observed[stray].sum()} samples in {np.count_nonzero(stray)} cells where the "
                "density is zero (outside its support)"
            )

        keep = expected > 0.0
        order = np.argsort(expected[keep], kind="stable")
        exp = expected[keep][order]
        obs = observed[keep][order]
        pooled = np.count_nonzero(exp < MIN_EXPECTED)
        if pooled:
            # One pooled cell of all low cells, grown with the next-smallest cells if needed.
            grown = int(np.searchsorted(np.cumsum(exp), MIN_EXPECTED)) + 1
            pooled = min(max(pooled, grown), exp.size)
            exp = np.append(exp[:pooled].sum(), exp[pooled:])
            obs = np.append(obs[:pooled].sum(), obs[pooled:])
        dof = exp.size - 1
        if dof < 1:
            return False, "too few cells with enough expected samples; raise sample_count"

        chi2 = float(np.sum((obs - exp) ** 2 / exp))
        p_value = gamma_q(0.5 * dof, 0.5 * chi2)
        level = 1.0 - (1.0 - significance) ** (1.0 / test_count)
        ok = p_value >= level
        message = (
            f"chi2 = {chi2:.1f}, dof = {dof}, p-value = {p_value:.3g} "
            f"{'>=' if ok else '<'} level {level:.3g} ({pooled} cells pooled; "
            f"outside cell: observed {observed[-1]}, expected {expected[-1]:.1f})"
        )
        return ok, message


class SurfaceAdapter:
    """The chi-square test of any sampler with the material interface (tracer.optics.bsdf): a
    material, an aimed mixture (tracer.optics.aimed.Aimed) or the cosine emission.

    In the manner of Mitsuba 3's ``BSDFAdapter``: one incoming direction ``d`` (3,) on a surface
    point with normal ``normal`` (3,) at ``point`` (3,); the sampler's outgoing directions are mapped
    to (phi, cos theta) about the world z axis, where d omega = d phi d cos theta, so the expected
    density there is the sampler's own ``pdf`` per steradian. Samples the sampler marks absorbed
    (flags 0) go to the outside cell, whose expected count is the pdf's missing mass. The adapter
    also checks, on every valid sample, that the weight equals eval / pdf (the sampler's three
    methods agree) and returns the largest relative mismatch in :attr:`weight_mismatch`.

    Parameters
    ----------
    sampler : object with ``sample(it, u, mode)``, ``eval(it, wo, mode)``, ``pdf(it, wo)``, ``dims``.
    d, normal, point : (3,) incoming propagation direction, geometric normal, position (mm).
    slot : the object slot the interaction belongs to. uv : (2,) texture coordinates or None.
    mode : transport mode (tracer.optics.bsdf.RADIANCE or IMPORTANCE).
    """

    def __init__(self, sampler, d, normal, point=(0.0, 0.0, 0.0), slot: int = 0, uv=None, mode="radiance"):
        self.sampler, self.mode, self.slot = sampler, mode, slot
        self.d = np.asarray(d, dtype=np.float64) / np.linalg.norm(d)
        self.normal = np.asarray(normal, dtype=np.float64) / np.linalg.norm(normal)
        self.point = np.asarray(point, dtype=np.float64)
        self.uv = None if uv is None else np.asarray(uv, dtype=np.float64)
        self.weight_mismatch = 0.0

    def interaction(self, n: int):
        from tracer.optics.bsdf import Interaction

        rep = lambda v: np.repeat(v.reshape(-1, 1), n, axis=1)  # noqa: E731
        return Interaction(rep(self.d), rep(self.point), rep(self.normal), rep(self.normal),
                           None if self.uv is None else rep(self.uv), np.full(n, self.slot, np.int64))

    def sample(self, n: int, rng: np.random.Generator):
        it = self.interaction(n)
        s = self.sampler.sample(it, rng.random((self.sampler.dims, n)), self.mode)
        valid = s.flags != 0
        if np.any(valid):
            k = np.flatnonzero(valid)
            sub = it.take(k)
            wo = s.wo[:, k]
            f = self.sampler.eval(sub, wo, self.mode)
            pdf = self.sampler.pdf(sub, wo)
            expected = f / pdf
            got = np.broadcast_to(s.weight, (3, n))[:, k]
            self.weight_mismatch = max(self.weight_mismatch, float(np.max(np.abs(got - expected) /
                                                                         np.maximum(np.abs(expected), 1e-300))))
            if not np.allclose(s.pdf[k], pdf, rtol=1e-9, atol=0):
                self.weight_mismatch = max(self.weight_mismatch, float(np.max(np.abs(s.pdf[k] - pdf) / pdf)))
        wo = s.wo
        pts = np.stack([np.arctan2(wo[1], wo[0]) % (2 * np.pi), np.clip(wo[2], -1.0, 1.0)], axis=-1)
        return pts, valid

    def pdf(self, phi: np.ndarray, cos_theta: np.ndarray) -> np.ndarray:
        sin_theta = np.sqrt(np.maximum(0.0, 1.0 - cos_theta**2))
        wo = np.stack([sin_theta * np.cos(phi), sin_theta * np.sin(phi), cos_theta])
        return self.sampler.pdf(self.interaction(len(phi)), wo)

    def test(self, resolution=(64, 64), sample_count: int = 400_000, seed: int = 0,
             bounds=((0.0, 2 * np.pi), (-1.0, 1.0)), order: int = 16) -> ChiSquareTest:
        """The test over ``bounds`` in (phi, cos theta); ``order`` 16 integrates the jump of an
        aimed mixture's density at its target's rim to well below the test's resolution."""
        return ChiSquareTest(bounds, resolution, self.sample, self.pdf, sample_count, seed, order)
