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
