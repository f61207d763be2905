"""The tests' own statistics (tests/support/stats.py): the Student-t bound that film-based tests use, whose
variances come from the spread of a few replicates, against closed forms and by its false-alarm rate."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tests.support.stats import t_bound, welch_dof, z_bound


@pytest.mark.parametrize("m,alpha", [(1, 0.05), (1, 0.01), (24, 0.01), (3000, 0.01)])
def test_t_bound_matches_the_closed_forms_of_one_and_two_degrees_of_freedom(m, alpha):
    """With one degree of freedom T is Cauchy: P(|T| > t) = 1 - 2 atan(t) / pi; with two,
    P(|T| > t) = 1 - t / sqrt(2 + t^2)."""
    tail = 1 - (1 - alpha) ** (1 / m)
    assert t_bound(m, 1, alpha) == pytest.approx(math.tan(math.pi / 2 * (1 - tail)), rel=1e-9)
    c = 1 - tail
    assert t_bound(m, 2, alpha) == pytest.approx(math.sqrt(2 * c * c / (1 - c * c)), rel=1e-9)


def test_t_bound_falls_to_the_normal_bound_with_the_degrees_of_freedom():
    """Known quantiles (t_0.975 with 10 dof 2.2281, with 30 dof 2.0423; t_0.995 with 5 dof 4.0321), a
    bound that falls as the degrees of freedom grow, and the normal bound in the limit."""
    assert t_bound(1, 10, 0.05) == pytest.approx(2.228139, abs=1e-6)
    assert t_bound(1, 30, 0.05) == pytest.approx(2.042272, abs=1e-6)
    assert t_bound(1, 5, 0.01) == pytest.approx(4.032143, abs=1e-6)
    bounds = [t_bound(12, dof) for dof in (3, 7, 31, 255, 10_000)]
    assert all(a > b for a, b in zip(bounds, bounds[1:], strict=False)) and bounds[-1] > z_bound(12)
    assert t_bound(12, 10_000) == pytest.approx(z_bound(12), rel=1e-3)
    assert t_bound(12, math.inf) == z_bound(12)
    with pytest.raises(ValueError, match="degree of freedom"):
        t_bound(1, 0)


@pytest.mark.parametrize("replicates", [3, 5, 9])
def test_t_bound_rejects_a_true_mean_at_alpha_where_the_normal_bound_does_not(replicates):
    """200,000 experiments, each the mean of a few normal replicates against the true mean with the
    standard error from their spread (as a film's is): the t bound rejects a fraction alpha = 0.01 of
    them (within the binomial error, Sidak over the three cases), the normal bound more than three
    times as many (measured: 12 times on 3 replicates, 6 on 5, 3.3 on 9)."""
    n, alpha = 200_000, 0.01
    x = np.random.default_rng(replicates).standard_normal((n, replicates))
    z = np.abs(x.mean(axis=1)) / (x.std(axis=1, ddof=1) / math.sqrt(replicates))
    rate_t = float((z > t_bound(1, replicates - 1, alpha)).mean())
    rate_z = float((z > z_bound(1, alpha)).mean())
    assert abs(rate_t - alpha) < z_bound(3) * math.sqrt(alpha * (1 - alpha) / n), rate_t
    assert rate_z > 3 * alpha, rate_z


def test_welch_dof_of_equal_parts_adds_their_degrees_of_freedom_and_leans_on_the_larger_part():
    """k equal variances with nu degrees of freedom each give k nu; a sum dominated by one part has about
    that part's degrees of freedom."""
    assert welch_dof((np.full(50, 2.0), 7)) == pytest.approx(350.0)
    assert welch_dof((1.0, 4), (1.0, 4)) == pytest.approx(8.0)
    assert 3.0 < welch_dof((1.0, 3), (1e-3, 1000)) < 3.01
    assert welch_dof((np.zeros(4), 3)) == math.inf
