"""Arrays kept by the digest of what they were computed from, for a process that computes the same thing
again: parsed mesh files and exact surfaces' distances (tracer.scene; an F12 after F12 in Blender
exports the same files into a new folder). Least recently used dropped first, within a byte budget;
safe across threads; arrays are handed out as copies, so no caller spoils another's."""

from __future__ import annotations

import threading
from collections import OrderedDict

import numpy as np


def _nbytes(entry: tuple) -> int:
    return sum(a.nbytes for a in entry if a is not None)


class Kept:
    """Tuples of arrays (or None) by key, at most ``max_bytes`` of arrays in all."""

    def __init__(self, max_bytes: int):
        self.max_bytes = int(max_bytes)
        self._entries: OrderedDict = OrderedDict()
        self._lock = threading.Lock()

    def __len__(self) -> int:
        return len(self._entries)

    def __iter__(self):
        """The keys, least recently used first (a snapshot)."""
        with self._lock:
            return iter(list(self._entries))

    def get(self, key) -> tuple | None:
        """Copies of the arrays kept under ``key``, or None."""
        with self._lock:
            entry = self._entries.get(key)
            if entry is None:
                return None
            self._entries.move_to_end(key)
        return tuple(None if a is None else a.copy() for a in entry)

    def put(self, key, entry: tuple[np.ndarray | None, ...]):
        """Keep copies of ``entry``'s arrays (one larger than the whole budget is not kept: it would
        only empty the rest)."""
        if _nbytes(entry) > self.max_bytes:
            return
        entry = tuple(None if a is None else a.copy() for a in entry)
        with self._lock:
            self._entries[key] = entry
            self._entries.move_to_end(key)
            total = sum(_nbytes(e) for e in self._entries.values())
            while total > self.max_bytes:
                _, dropped = self._entries.popitem(last=False)
                total -= _nbytes(dropped)
