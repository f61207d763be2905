"""An environment's radiance read for directions given as rows, as the environment tests write them."""

import numpy as np


def radiance_rows(env, d) -> np.ndarray:
    """The environment's radiance for directions given as rows (n, 3), as rows (n, 3) (the tracer
    works on (3, n) planes)."""
    return env.radiance(np.asarray(d, dtype=np.float64).T).T
