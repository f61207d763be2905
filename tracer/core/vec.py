"""Vector operations on structure-of-arrays planes, and the tracer's two precisions.

Every batch of vectors in the tracer is a (3, n) array: one contiguous plane per component (x, y, z),
so elementwise work runs over contiguous memory (numpy's fast path; (n, 3) rows made every operation
that broadcasts a column run its inner loop over 3 components, 5-10 times slower). A single vector is
(3,) and broadcasts as ``v[:, None]``.

Precision. Positions and distances (mm) are float64: millimetre optics a metre wide need it for
sub-micrometre hit points. Directions, normals, path weights, BSDF values and densities are float32
(:data:`F32`): a direction is then exact to about 1e-7 rad (a pixel of the eye is 3e-4 rad), and
numpy's float32 kernels (twice the SIMD width, half the memory traffic, much faster division, square
root and transcendental functions) run the shading several times as fast as float64. Film sums are
float64. Where the two meet, positions stay float64 (a hit point o + t d is computed in float64).

Sums are written out term by term on purpose: einsum and BLAS pick summation orders by memory
alignment, so the same batch could differ in the last bit between processes; with fixed-order
elementwise sums a batch gives the same numbers wherever it runs (tracer.runtime.parallel merges films
exactly).
"""

from __future__ import annotations

import numpy as np

#: The precision of directions, normals, weights and densities (see the module docstring).
F32 = np.float32


def f32(a) -> np.ndarray:
    """``a`` as float32 (no copy if it is already)."""
    return np.asarray(a, dtype=F32)


def take(a: np.ndarray, idx) -> np.ndarray:
    """``a[..., idx]``: the entries ``idx`` (integers) of the last axis of ``a``, the path axis of every
    plane and table, in that order.

    It is np.take in mode "wrap": for indices in [-n, n) the same values as np.take and fancy indexing
    (-1 is the last entry, which the tables with a column appended for misses rely on), without their
    bounds check, which in numpy 1.26 makes a take along the last axis of a (3, n) plane 1.5 to 2.5
    times as slow (fancy indexing ``a[:, idx]``, 5 to 7 times; benchmarks/gather.py). Indices come
    from the tracer itself (argsort, flatnonzero, face and slot ids), never from input: one out of
    range would wrap silently.
    """
    return np.take(a, idx, axis=-1, mode="wrap")


def put(a: np.ndarray, idx, v) -> None:
    """``a[..., idx] = v``, one row of the last axis at a time where ``idx`` is an index array (a
    two-dimensional fancy assignment takes 1.7 to 2.9 times as long in numpy 1.26; benchmarks/gather.py).
    ``v`` broadcasts to ``a[..., idx]``."""
    if isinstance(idx, slice):
        a[..., idx] = v
        return
    v = np.broadcast_to(v, a.shape[:-1] + (len(idx),))
    for i in np.ndindex(a.shape[:-1]):
        a[i][idx] = v[i]


def dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Component-wise dot product of (k, n) planes (or (k,) vectors broadcast as columns), summed in
    component order; (n,)."""
    out = a[0] * b[0]
    for i in range(1, len(a)):
        out = out + a[i] * b[i]
    return out


def norm(a: np.ndarray) -> np.ndarray:
    """Euclidean length of (k, n) planes, (n,)."""
    return np.sqrt(dot(a, a))


def normalize(a: np.ndarray) -> np.ndarray:
    """Unit vectors of (k, n) planes (columns must be non-zero)."""
    return a * (1.0 / norm(a))


def cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Cross product of (3, n) planes (either may be a (3, 1) column), (3, n)."""
    return np.stack([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])


def max3(a: np.ndarray) -> np.ndarray:
    """Largest of the three components of (3, n) planes (RGB weights), (n,)."""
    return np.maximum(np.maximum(a[0], a[1]), a[2])


def col(v) -> np.ndarray:
    """A vector (3,) as a (3, 1) column that broadcasts against (3, n) planes."""
    return np.asarray(v, dtype=np.float64).reshape(-1, 1)


def planes(rows: np.ndarray) -> np.ndarray:
    """(n, k) rows -> contiguous (k, n) planes."""
    return np.ascontiguousarray(np.asarray(rows, dtype=np.float64).T)


def reflect(d: np.ndarray, n: np.ndarray) -> np.ndarray:
    """Mirror direction of ``d`` about normals ``n`` ((3, n) planes; either side of the normal)."""
    return d - (2.0 * dot(d, n)) * n
