"""Statistical bounds for comparing estimates with their reported errors: Sidak-corrected normal and
Student-t bounds, Welch-Satterthwaite degrees of freedom, and a film's degrees of freedom (checked by
tests/support/test_stats.py)."""

from __future__ import annotations

import math

import numpy as np


def _sidak(m: int, alpha: float) -> float:
    """The per-comparison two-sided level that keeps the family-wise level ``alpha`` over m independent
    comparisons (Sidak 1967, doi:10.1080/01621459.1967.10482935)."""
    return 1 - (1 - alpha) ** (1 / m)


def z_bound(m: int, alpha: float = 0.01) -> float:
    """Sidak-corrected two-sided normal bound for alpha over m comparisons: for errors whose standard
    deviation is known (binomial counts of a known probability) or estimated from thousands of
    independent values. An error estimated from the spread of a few replicates needs :func:`t_bound`."""
    from statistics import NormalDist

    return NormalDist().inv_cdf(1 - _sidak(m, alpha) / 2)


def _betacf(a: float, b: float, x: float) -> float:
    """The continued fraction of the regularised incomplete beta function, by the modified Lentz
    method (Press et al., Numerical Recipes in C, 2nd ed., sec. 6.4)."""
    tiny = 1e-300
    c, d = 1.0, 1.0 - (a + b) * x / (a + 1.0)
    d = 1.0 / (d if abs(d) > tiny else tiny)
    h = d
    for m in range(1, 10_000):
        for num in (m * (b - m) * x / ((a - 1.0 + 2 * m) * (a + 2 * m)),
                    -(a + m) * (a + b + m) * x / ((a + 2 * m) * (a + 1.0 + 2 * m))):
            d = 1.0 + num * d
            d = 1.0 / (d if abs(d) > tiny else tiny)
            c = 1.0 + num / c
            c = c if abs(c) > tiny else tiny
            h *= d * c
        if abs(d * c - 1.0) < 1e-15:
            return h
    raise ArithmeticError(f"incomplete beta ({a}, {b}, {x}) did not converge")


def betainc(a: float, b: float, x: float) -> float:
    """The regularised incomplete beta function I_x(a, b)."""
    if x <= 0.0 or x >= 1.0:
        return 0.0 if x <= 0.0 else 1.0
    front = math.exp(math.lgamma(a + b) - math.lgamma(a) - math.lgamma(b) + a * math.log(x) + b * math.log1p(-x))
    if x < (a + 1.0) / (a + b + 2.0):
        return front * _betacf(a, b, x) / a
    return 1.0 - front * _betacf(b, a, 1.0 - x) / b


def t_bound(m: int, dof: float, alpha: float = 0.01) -> float:
    """Sidak-corrected two-sided Student-t bound for alpha over m comparisons of errors whose variance
    is estimated with ``dof`` degrees of freedom (the spread of r replicates: r - 1; a sum of such
    estimates: :func:`welch_dof`); the normal bound for infinite ``dof``. A normal bound on 8 replicates
    would reject a true hypothesis several times as often as alpha says (tests/support/test_stats.py).

    The two-sided tail of T with nu degrees of freedom beyond t is I_x(nu/2, 1/2), x = nu / (nu + t^2)
    (Numerical Recipes in C, 2nd ed., eq. 6.4.9), increasing in x: solved by bisection."""
    if dof < 1:
        raise ValueError(f"a Student-t bound needs at least one degree of freedom, got {dof}")
    if math.isinf(dof):
        return z_bound(m, alpha)
    tail = _sidak(m, alpha)
    lo, hi = 0.0, 1.0
    for _ in range(80):  # x to 2^-80
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if betainc(0.5 * dof, 0.5, mid) < tail else (lo, mid)
    x = 0.5 * (lo + hi)
    return math.sqrt(dof * (1.0 - x) / x)


def welch_dof(*parts) -> float:
    """Welch-Satterthwaite degrees of freedom of a sum of independent variance estimates, each given as
    (variance, its degrees of freedom); arrays of variances with one dof broadcast (Satterthwaite 1946,
    doi:10.2307/3002019): (sum v)^2 / sum (v^2 / dof)."""
    total = denom = 0.0
    for var, dof in parts:
        v = np.asarray(var, dtype=float)
        total += float(v.sum())
        denom += float((v * v).sum()) / dof
    return total * total / denom if denom > 0 else math.inf


def film_dof(film) -> int:
    """Degrees of freedom of a film's variances (per pixel and of the image mean): its replicates less
    one (one group; a hybrid film's groups combine by :func:`welch_dof`)."""
    if len(film.groups) != 1:
        raise ValueError("a film of several groups: combine their variances with welch_dof")
    return film.replicates - 1
