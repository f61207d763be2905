"""Vector helpers (tracer.core.vec): take and put against numpy's indexing."""

import numpy as np


def test_take_and_put_match_numpy_indexing():
    """tracer.core.vec.take and put give what fancy indexing along the last axis gives, for the tracer's
    indices (in range, -1 for the appended miss column), on planes of 1 to 3 dimensions."""
    from tracer.core.vec import put, take

    rng = np.random.default_rng(3)
    for shape in ((7,), (3, 7), (3, 2, 7)):
        a = rng.random(shape)
        idx = np.array([6, 0, -1, 3, 3, 5])
        np.testing.assert_array_equal(take(a, idx), a[..., idx])
        for where in (np.array([5, 1, 2]), slice(2, 5)):
            v = rng.random(a[..., where].shape)
            ours, theirs = a.copy(), a.copy()
            put(ours, where, v)
            theirs[..., where] = v
            np.testing.assert_array_equal(ours, theirs)
        ours = a.copy()
        put(ours, np.array([0, 4]), 2.5)  # a scalar broadcasts
        assert np.all(ours[..., [0, 4]] == 2.5)
