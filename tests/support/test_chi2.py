"""The chi-square test's own arithmetic (tests/support/chi2.py): the regularised upper incomplete gamma
function against closed forms, the Poisson distribution and its edges."""

from __future__ import annotations

import math

import pytest

from tests.support.chi2 import gamma_q


@pytest.mark.parametrize("x", [1e-3, 0.5, 1.9, 2.1, 10.0, 60.0])
def test_gamma_q_closed_forms(x):
    assert gamma_q(1.0, x) == pytest.approx(math.exp(-x), rel=1e-12)
    assert gamma_q(0.5, x) == pytest.approx(math.erfc(math.sqrt(x)), rel=1e-10)


@pytest.mark.parametrize(
    "k, x", [(3, 2.5), (3, 7.0), (50, 40.0), (50, 65.0), (2000, 1950.0), (2000, 2150.0)]
)
def test_gamma_q_integer_shape_is_poisson_cdf(k, x):
    # Q(k, x) = P(Poisson(x) < k) for integer k.
    terms = (math.exp(-x + j * math.log(x) - math.lgamma(j + 1)) for j in range(k))
    assert gamma_q(float(k), x) == pytest.approx(math.fsum(terms), rel=1e-9)


def test_gamma_q_edges():
    assert gamma_q(3.0, 0.0) == 1.0
    with pytest.raises(ValueError):
        gamma_q(0.0, 1.0)
    with pytest.raises(ValueError):
        gamma_q(1.0, -1.0)
