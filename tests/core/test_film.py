"""The film (tracer.core.film): a batch's film travels as the columns of its lit pixels and merges to the
same bits as the dense film."""

import numpy as np
import pytest

from presets import PRESETS
from tracer.methods import INTEGRATORS
from tracer.scene import load_scene
from tracer.transport.world import World

pytestmark = pytest.mark.slow


def test_batches_travel_as_their_lit_pixels_and_merge_to_the_same_bits(tmp_path):
    """A forward batch lights a few thousand of hud-direct's 65,520 pixels: its film travels as those
    columns (tracer.core.film.Columns), and merging it gives every array of the dense merge, bit for bit
    (sums, per-component and per-group sums of the replicates' squares). A backward batch's connections
    light most pixels and travel whole; its paths that hit an LED, a few hundred, as columns."""
    import pickle

    from tracer.core.film import SPARSE_SHARE, Columns

    world = World(load_scene(PRESETS["hud-direct"].write(tmp_path / "s")))

    def dense(data):
        names, sums, norms, c_sq, groups = data
        full = lambda a: a if not isinstance(a, Columns) else _scatter(a)  # noqa: E731
        return (names, [full(a) for a in sums], norms, [full(a) for a in c_sq],
                {g: (full(q), *rest) for g, (q, *rest) in groups.items()})

    def _scatter(c):
        out = np.zeros(c.values.shape[:-1] + (world.eye.width * world.eye.height,))
        out[..., c.idx] = c.values
        return out

    def arrays_of(film):
        film.make_dense()
        return ([film.sums[k] for k in film.kinds] + [film.comp_rep_sq[k] for k in film.kinds]
                + [g.sq for g in film.groups.values()])

    for method, sparse in (("forward", {"light": True}), ("backward", {"hit": True, "connection": False})):
        integ = INTEGRATORS[method](world, 3)
        batches = [pickle.loads(pickle.dumps(integ.trace_batch(k))) for k in range(3)]  # as from a worker
        for b in batches:
            names, sums = b.film[0], b.film[1]
            assert {k: isinstance(a, Columns) for k, a in zip(names, sums, strict=True)} == sparse, method
            assert all(0 < len(a.idx) < SPARSE_SHARE * world.eye.width * world.eye.height
                       for a in sums if isinstance(a, Columns))
        a, b = integ.new_film(), integ.new_film()
        for batch in batches:
            a.merge_arrays(batch.film)
            b.merge_arrays(dense(batch.film))
        assert a.replicates == b.replicates > 0 and a.norm == b.norm
        for x, y in zip(arrays_of(a), arrays_of(b), strict=True):
            assert np.array_equal(x, y) and x.any(), method


def test_a_film_holds_the_pixels_sampled_so_far_and_gives_the_same_numbers(tmp_path):
    """Backward batches smaller than the image (4,096 of hud-direct's 65,520 pixels) merge into a film
    that holds only the pixels sampled so far (tracer.core.film: compact layout) until they pass
    COMPACT_SHARE of the retina, then every pixel. At each step its image, variance, sample counts,
    normalisers and replicate counts are those of a film that held every pixel from the start, bit for
    bit (sums over the pixels, the components' totals and the mean's standard error, add in another
    order: to 1e-12)."""
    from tracer.core.film import COMPACT_SHARE

    world = World(load_scene(PRESETS["hud-direct"].write(tmp_path / "s")))
    integ = INTEGRATORS["backward"](world, 5, batch_size=4096)
    npix = world.eye.width * world.eye.height
    compact, dense = integ.new_film(), integ.new_film()
    dense.make_dense()
    assert dense.dense and not compact.dense
    seen = []
    for k in range(6):
        batch = integ.trace_batch(k)
        compact.merge_arrays(batch.film)
        dense.merge_arrays(batch.film)
        seen.append(compact.dense)
        assert np.array_equal(compact.rgb(), dense.rgb())
        assert np.array_equal(compact.variance_y(), dense.variance_y())
        assert np.array_equal(compact.sample_counts(), dense.sample_counts())
        for name in compact.kinds:
            assert compact.count_summary(name) == dense.count_summary(name)
            assert compact.component_totals(name) == pytest.approx(dense.component_totals(name), rel=1e-12)
        assert compact.replicates == dense.replicates == 0  # most pixels hold no sample yet
        assert compact.mean_standard_error() == pytest.approx(dense.mean_standard_error(), rel=1e-12)
        assert compact.finite()
    # compact while the sampled pixels are at most COMPACT_SHARE of the retina, dense after
    sampled = np.cumsum([len(integ.batch_pixels(k)) for k in range(6)])  # 4,095 each: 16 parts of a pass
    assert seen == list(sampled > COMPACT_SHARE * npix) and not seen[0] and seen[-1]
    assert compact.count_summary("hit") == (sampled[-1] / npix, 0, 1)
