"""What a gather along the path axis costs in this numpy: the figures behind tracer.core.vec.take and put.

    .venv/bin/python benchmarks/gather.py

Times (best of 5 x 50 calls, microseconds) of taking 60,000 of 65,536 columns of a (3, n) float64
plane, sorted and permuted, with np.take in its default mode, in mode "wrap" (tracer.core.vec.take) and
by fancy indexing, and of writing them back with a fancy assignment and with tracer.core.vec.put.
"""

from __future__ import annotations

import sys
import timeit
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from tracer.core.vec import put, take  # noqa: E402


def best_us(f) -> float:
    return min(timeit.repeat(f, number=50, repeat=5)) / 50 * 1e6


def main():
    n = 1 << 16
    rng = np.random.default_rng(0)
    a = rng.random((3, n))
    idx = np.sort(rng.choice(n, 60_000, replace=False))
    perm = rng.permutation(n)[:60_000]
    v = rng.random((3, len(idx)))
    print(f"numpy {np.__version__}: (3, {n:,}) float64, 60,000 columns")
    for label, index in (("sorted", idx), ("permuted", perm)):
        base = best_us(lambda index=index: np.take(a, index, axis=1))
        wrap = best_us(lambda index=index: take(a, index))
        fancy = best_us(lambda index=index: a[:, index])
        print(f"gather {label:8s}: np.take {base:7.0f} us, tracer.core.vec.take (mode wrap) {wrap:7.0f} us "
              f"({base / wrap:.1f} x as fast), a[:, idx] {fancy:7.0f} us ({fancy / wrap:.1f} x as slow)")
    fancy_set = best_us(lambda: a.__setitem__((slice(None), idx), v))
    rows = best_us(lambda: put(a, idx, v))
    print(f"scatter sorted : a[:, idx] = v {fancy_set:7.0f} us, tracer.core.vec.put {rows:7.0f} us "
          f"({fancy_set / rows:.1f} x as fast)")


if __name__ == "__main__":
    main()
