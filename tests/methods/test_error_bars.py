"""The errors the methods report: the same seed gives the same image, two seeds differ as the reported
variance says, and the error of the unbiased methods falls as N^-1/2."""

import math

import numpy as np
import pytest

from presets import PRESETS
from tests.support.render import render
from tests.support.scenes import edit_json
from tracer.methods import INTEGRATORS, Budget
from tracer.scene import load_scene


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


def test_batches_smaller_than_the_image_cover_it_evenly_and_measure_the_pixels_sampled_twice(tmp_path):
    """Issue 31: a backward batch of fewer paths than pixels covers part of a pass (one sample through each
    of its pixels), so that a render of a large retina can stop after any batch. Twenty batches of 4,000
    pixels over a 300 x 200 retina (15 parts per pass): every pixel holds one or two samples, the two
    counts in the right numbers (the parts of a pass are disjoint and cover it); Y_var is positive where a
    pixel holds two samples and 0 where it holds one; the image mean (every sample of the disk's foot
    reads rho L sin^2 alpha = 100 cd/m^2 on average) agrees with the closed form within its standard
    error (alpha = 0.01), which comes from the pixels' own variances; and a batch's pixels depend on its
    index alone (seed-addressed: the same bits from a fresh integrator)."""
    from presets.analytic_disk import expected_luminance
    from tests.support.stats import z_bound
    from tracer.core.units import luminance

    folder = PRESETS["analytic-disk"].write(tmp_path / "disk")
    edit_json(folder, lambda d: d["eye"].update(resolution=[300, 200]))
    integ = INTEGRATORS["backward"](load_scene(folder), 5, 4096)
    film = integ.new_film()
    batches = [integ.trace_batch(k) for k in range(20)]
    for b in batches:
        film.merge_arrays(b.film)
    counts = film.sample_counts()
    assert counts is not None and film.partial_coverage
    assert counts.min() == 1 and counts.max() == 2 and int((counts == 2).sum()) == 20 * 4000 - 60000
    var = film.variance_y()
    assert np.all(var[counts == 1] == 0) and np.mean(var[counts == 2] > 0) > 0.99
    y = luminance(film.rgb())
    se = film.mean_standard_error()
    assert se > 0 and abs(float(y.mean()) - expected_luminance()) < z_bound(1) * se, (y.mean(), se)
    again = INTEGRATORS["backward"](load_scene(folder), 5, 4096).trace_batch(17)
    assert np.array_equal(np.asarray(again.film[2][0]), np.asarray(batches[17].film[2][0]))  # the pixels sampled
    assert (again.rays, again.found) == (batches[17].rays, batches[17].found)  # and what they found


def test_a_render_stopped_before_one_sample_per_pixel_fills_its_image_and_says_so(tmp_path):
    """A budget that ends before every pixel has a sample: the unsampled pixels show their nearest
    sampled neighbour's value (no black holes in a uniform view: every pixel of analytic-furnace's
    100 cd/m^2 walls reads about 100), the report's image.samples_per_pixel says how many were
    unsampled, and a warning says that error bars are missing; the EXR holds no NaN."""
    from tracer.core.imageio import read_exr_channels
    from tracer.products.render import render_folder

    folder = PRESETS["analytic-furnace"].write(tmp_path / "f")
    edit_json(folder, lambda d: d["eye"].update(resolution=[320, 240]))
    report, res = render_folder(folder, "backward", Budget(rays=1), 1, tmp_path / "out", batch_size=8192)
    spp = report["image"]["samples_per_pixel"]
    assert res.batches == 1 and spp["min"] == 0 and spp["max"] == 1
    assert spp["unsampled_pixels"] == 320 * 240 - 320 * 240 // 10  # a batch of 8,192: a tenth of a pass
    y = read_exr_channels(tmp_path / "out" / "image.exr")[0]["Y"]
    assert np.all(np.isfinite(y)) and np.all(np.abs(y - 100.0) < 1.0), (y.min(), y.max())
    assert any("samples per pixel" in w and "nearest sampled neighbour" in w for w in report["warnings"])
