"""What each pixel of a render's image shows (tracer.products.fill), and the products computed once per
sampled pixel (tracer.products.render.render_products) against the same products computed pixel by
pixel over whole images."""

import numpy as np
import pytest

from presets import PRESETS
from tracer.core.film import Film, Splats, batch_arrays
from tracer.core.units import luminance
from tracer.methods import INTEGRATORS, Budget
from tracer.products.fill import ImageFill
from tracer.products.render import render_products
from tracer.products.tonemap import adaptation_luminance, log_average_luminance, tonemap_ward
from tracer.scene import load_scene
from tracer.transport.world import World


def _reference_fill(image: np.ndarray, missing: np.ndarray) -> np.ndarray:
    """Pixel by pixel: a missing pixel takes the nearest sampled pixel of its row (the left one on a
    tie: argmin takes the first), a row without one the nearest row that has one (the upper one)."""
    h, w = missing.shape
    out = np.empty_like(image)
    rows = np.flatnonzero((~missing).any(axis=1))
    for y in range(h):
        src = rows[np.argmin(np.abs(rows - y))]
        cols = np.flatnonzero(~missing[src])
        nearest = cols[np.argmin(np.abs(np.arange(w)[:, None] - cols[None, :]), axis=1)]
        out[y] = image[src, nearest]
    return out


def _film_with(missing: np.ndarray, rng) -> Film:
    """A film whose batches sampled every pixel not ``missing`` once (a compact film: they are few)."""
    h, w = missing.shape
    film = Film(w, h, {"hit": "samples per pixel"})
    sampled = rng.permutation(np.flatnonzero(~missing))
    for part in np.array_split(sampled, 3):
        values = rng.uniform(0.0, 50.0, (3, len(part)))
        splats = Splats()
        splats.add("hit", part, np.zeros(len(part), np.int64), values)
        film.merge_arrays(batch_arrays(["hit"], w * h, splats, 1, {"hit": part}))
    return film


@pytest.mark.parametrize("case", ["scattered", "empty rows", "one pixel", "edges"])
def test_each_pixel_shows_its_nearest_sampled_neighbour(case):
    """The runs of ImageFill give every pixel the value the pixel-by-pixel rule gives, for rows with
    samples at their ends, rows without any (they copy the nearest row, the upper on a tie), and a
    single sampled pixel; the sampled pixels show their own value and only they hold a variance."""
    rng = np.random.default_rng({"scattered": 1, "empty rows": 2, "one pixel": 3, "edges": 4}[case])
    h, w = 9, 13
    missing = rng.random((h, w)) > 0.15
    if case == "empty rows":
        missing[[0, 3, 4, 5, 8]] = True
        missing[1, 6] = False
    elif case == "one pixel":
        missing[:] = True
        missing[4, 7] = False
    elif case == "edges":
        missing[:] = True
        missing[:, 0] = missing[:, -1] = False
        missing[2] = True
    film = _film_with(missing, rng)
    assert not film.dense
    fill = ImageFill(film)
    assert fill.unsampled == int(missing.sum())
    own = film.rgb()
    got = fill.image(np.ascontiguousarray(film.layout_rgb().T))
    assert np.array_equal(got, _reference_fill(own, missing))
    var = fill.as_film(film.layout_variance_y())
    assert np.array_equal(var, film.variance_y())
    # statistics over the weighted population are those of the image
    y = luminance(got)
    values, weights = fill.population(luminance(film.layout_rgb().T))
    assert weights.sum() == h * w
    assert np.average(values, weights=weights) == pytest.approx(y.mean(), rel=1e-13)
    assert log_average_luminance(values, weights=weights) == pytest.approx(log_average_luminance(y), rel=1e-13)
    for mode in ("log_average", "mean"):
        assert adaptation_luminance(values, mode, weights) == pytest.approx(adaptation_luminance(y, mode), rel=1e-13)


def test_a_forward_film_shows_black_where_nothing_landed(tmp_path):
    """A film without sample counts (forward: particles land anywhere) shows zero where none landed:
    nothing is filled, and the population holds those pixels as one value 0."""
    world = World(load_scene(PRESETS["hud-direct"].write(tmp_path / "s")))
    res = INTEGRATORS["forward"](world, 2).render(Budget(rays=30_000))
    film = res.film
    fill = ImageFill(film)
    assert fill.counts is None and fill.unsampled == 0
    image = fill.image(np.ascontiguousarray(film.layout_rgb().T))
    assert np.array_equal(image, film.rgb())
    values, weights = fill.population(luminance(film.layout_rgb().T))
    assert weights.sum() == film.pixels and np.average(values, weights=weights) == pytest.approx(
        luminance(film.rgb()).mean(), rel=1e-13)


@pytest.mark.slow
@pytest.mark.parametrize("rays, dense, filled", [(40_000, False, True), (400_000, True, True),
                                                 (1_500_000, True, False)])
def test_products_per_sampled_pixel_equal_those_of_the_whole_image(tmp_path, rays, dense, filled):
    """Backward renders of hud-direct in batches of 2,048 of its 65,520 pixels: a compact film with
    most pixels filled, a dense one with some, and one with every pixel sampled. Their EXR channels
    and preview are bit for bit those made pixel by pixel from the whole image (film.rgb(), the fill
    of the unsampled pixels, Ward's tone map of the image), and the report's luminance figures are
    theirs to 1e-12."""
    world = World(load_scene(PRESETS["hud-direct"].write(tmp_path / "s")))
    integ = INTEGRATORS["backward"](world, 4, batch_size=2048)
    result = integ.render(Budget(rays=rays))
    film = result.film
    counts = film.sample_counts()
    assert film.dense == dense and bool((counts == 0).any()) == filled
    products = render_products(world, integ, result, Budget(rays=rays), analyse=False)
    image = _reference_fill(film.rgb(), counts == 0) if filled else film.rgb()
    y = luminance(image)
    for k, c in enumerate("RGB"):
        assert np.array_equal(products.channels[c], image[..., k].astype(np.float32))
    assert np.array_equal(products.channels["Y"], y.astype(np.float32))
    assert np.array_equal(products.channels["Y_var"], film.variance_y().astype(np.float32))
    adapt = adaptation_luminance(y, world.eye.spec.adaptation)
    preview, info = tonemap_ward(image, adapt)
    assert np.array_equal(products.preview, preview)
    report = products.report
    assert report["preview"]["clipped_fraction"] == info["clipped_fraction"]
    assert report["adaptation_luminance"] == pytest.approx(adapt, rel=1e-12)
    lum = report["luminance"]
    assert lum["mean"] == pytest.approx(y.mean(), rel=1e-12) and lum["max"] == y.max()
    assert lum["log_average"] == pytest.approx(log_average_luminance(y), rel=1e-12)
    assert report["image"]["samples_per_pixel"]["unsampled_pixels"] == int((counts == 0).sum())
    assert np.array_equal(products.y, y) and np.array_equal(products.var_y, film.variance_y())
