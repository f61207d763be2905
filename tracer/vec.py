"""Row-wise vector operations on (..., 3) arrays.

numpy reductions over a short last axis (``np.linalg.norm(a, axis=1)``, ``a.max(axis=1)``) are
several times slower than these elementwise forms, and they sit in every bounce. For the same reason
rows are scaled column by column (:func:`scale`, not ``v * s[:, None]``, whose inner loop runs over
the 3 components) and gathered with ``np.take`` (:func:`rows`, not ``v[idx]``): 3-4 times faster
on (n, 3) arrays, with the same numbers. They are also
written out term by term on purpose: einsum and BLAS pick summation orders by memory alignment, so
the same batch could differ in the last bit between processes; with fixed-order elementwise sums a
batch gives the same numbers wherever it runs (tracer.parallel merges films exactly).
"""

from __future__ import annotations

import numpy as np


def dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise dot product of (..., k) arrays, summed in index order."""
    a, b = np.broadcast_arrays(a, b)
    out = a[..., 0] * b[..., 0]
    for i in range(1, a.shape[-1]):
        out = out + a[..., i] * b[..., i]
    return out


def norm(a: np.ndarray) -> np.ndarray:
    """Row-wise Euclidean length of (..., k) arrays."""
    return np.sqrt(dot(a, a))


def normalize(a: np.ndarray) -> np.ndarray:
    """Row-wise unit vectors of (..., k) arrays (rows must be non-zero)."""
    length = norm(a)
    if a.ndim != 2:
        return a / length[..., None]
    out = np.empty(a.shape)
    for i in range(a.shape[1]):
        np.divide(a[:, i], length, out=out[:, i])
    return out


def max3(a: np.ndarray) -> np.ndarray:
    """Row-wise maximum of (..., 3) arrays (RGB weights)."""
    return np.maximum(np.maximum(a[..., 0], a[..., 1]), a[..., 2])


def scale(v: np.ndarray, s: np.ndarray) -> np.ndarray:
    """``v * s[:, None]`` for rows v (n, k) or one vector v (k,) and factors s (n,), column by column."""
    s = np.asarray(s, dtype=np.float64)
    out = np.empty(s.shape + v.shape[-1:], dtype=np.result_type(v, s))
    for i in range(v.shape[-1]):
        np.multiply(v[..., i], s, out=out[:, i])
    return out


def axpy(s: np.ndarray, v: np.ndarray, y: np.ndarray) -> np.ndarray:
    """``y + s[:, None] * v`` (rows v and y (n, k) or vectors (k,), factors s (n,)), column by column."""
    out = scale(v, s)
    out += y
    return out


def minus(a: np.ndarray, c: np.ndarray) -> np.ndarray:
    """``a - c`` for rows a (n, k) and one vector c (k,), column by column."""
    out = np.empty(a.shape, dtype=np.result_type(a, c))
    for i in range(a.shape[1]):
        np.subtract(a[:, i], c[i], out=out[:, i])
    return out


def rows(a: np.ndarray, idx: np.ndarray) -> np.ndarray:
    """``a[idx]`` for an index array, through ``np.take`` (its fast path for rows of a 2-D array)."""
    return np.take(a, idx, axis=0)
