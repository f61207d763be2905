"""The errors the methods report: the same seed gives the same image, two seeds differ as the reported
variance says, and the error of the unbiased methods falls as N^-1/2."""

import math

import numpy as np
import pytest

from tests.support.render import render


def test_same_seed_same_image_and_seeds_differ_by_their_variance(preset):
    folder = preset("analytic-mirror", resolution=(16, 12))
    y1, v1, _ = render(folder, "forward", 600_000, seed=11)
    y2, _, _ = render(folder, "forward", 600_000, seed=11)
    y3, v3, _ = render(folder, "forward", 600_000, seed=12)
    assert np.array_equal(y1, y2)
    lit = (v1 > 0) & (v3 > 0)
    z = (y1 - y3)[lit] / np.sqrt(v1 + v3)[lit]
    assert not np.array_equal(y1, y3)
    assert abs(z.mean()) < 4 / math.sqrt(lit.sum()) and 0.7 < z.std() < 1.3


@pytest.mark.slow
@pytest.mark.parametrize("method", ["backward", "forward"])
def test_error_falls_as_one_over_root_n(preset, method):
    """log RMSE against log rays has slope in [-0.6, -0.4]: the furnace, whose every pixel is exactly
    L0 = 100 cd/m^2, so the error is the estimator's alone (squared errors averaged over 4 seeds)."""
    folder = preset("analytic-furnace", resolution=(12, 8))
    budgets = [100_000, 400_000, 1_600_000]
    errs = []
    for rays in budgets:
        mse = np.mean([np.mean((render(folder, method, rays, seed=s)[0] - 100.0) ** 2) for s in range(4)])
        errs.append(math.sqrt(mse) / 100.0)
    slope = np.polyfit(np.log(budgets), np.log(errs), 1)[0]
    assert -0.6 <= slope <= -0.4, (slope, errs)


@pytest.mark.parametrize("method", ["backward", "forward"])
def test_two_seeds_differ_as_the_reported_variance_says(preset, method):
    """Two seeds of analytic-mirror, compared over 16 x 16 blocks of the image (60 of them lit): z = (Y1 - Y2) /
    sqrt(V1 + V2) per block, with V the block mean's variance from the film's own per-pixel
    variance. If that variance is right, sum z^2 follows chi^2 with one degree of freedom per block:
    a too small variance (overconfident report) fails on the high side, a too large one on the low
    side. Two-sided, alpha = 0.01, Sidak over the two methods."""
    from tests.support.chi2 import gamma_q

    folder = preset("analytic-mirror")
    (y1, v1, _), (y2, v2, _) = (render(folder, method, 1_000_000, seed=s) for s in (11, 12))
    z2 = []
    for rows_ in np.array_split(np.arange(y1.shape[0]), 16):
        for cols in np.array_split(np.arange(y1.shape[1]), 16):
            block = np.ix_(rows_, cols)
            m = y1[block].size
            var = (v1[block].sum() + v2[block].sum()) / m**2
            if var > 0:
                z2.append((y1[block].mean() - y2[block].mean()) ** 2 / var)
    assert len(z2) >= 30, "the panel must light enough blocks for the test to have power"
    a = 1 - (1 - 0.01) ** (1 / 2)
    p_upper = gamma_q(len(z2) / 2, sum(z2) / 2)
    assert a / 2 < p_upper < 1 - a / 2, (sum(z2), len(z2), p_upper)
