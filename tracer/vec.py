"""Row-wise vector operations on (..., 3) arrays.

numpy reductions over a short last axis (``np.linalg.norm(a, axis=1)``, ``a.max(axis=1)``) are
several times slower than these elementwise forms, and they sit in every bounce. They are also
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
    return a / norm(a)[..., None]


def max3(a: np.ndarray) -> np.ndarray:
    """Row-wise maximum of (..., 3) arrays (RGB weights)."""
    return np.maximum(np.maximum(a[..., 0], a[..., 1]), a[..., 2])
