"""Row-wise vector operations on (..., 3) arrays.

numpy reductions over a short last axis (``np.linalg.norm(a, axis=1)``, ``a.max(axis=1)``) are
several times slower than these einsum and elementwise forms, and they sit in every bounce.
"""

from __future__ import annotations

import numpy as np


def dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise dot product of (..., k) arrays."""
    return np.einsum("...i,...i->...", a, b)


def norm(a: np.ndarray) -> np.ndarray:
    """Row-wise Euclidean length of (..., k) arrays."""
    return np.sqrt(np.einsum("...i,...i->...", a, a))


def normalize(a: np.ndarray) -> np.ndarray:
    """Row-wise unit vectors of (..., k) arrays (rows must be non-zero)."""
    return a / norm(a)[..., None]


def max3(a: np.ndarray) -> np.ndarray:
    """Row-wise maximum of (..., 3) arrays (RGB weights)."""
    return np.maximum(np.maximum(a[..., 0], a[..., 1]), a[..., 2])
