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


class KeptResults:
    """Results of any kind by key, at most ``most`` of them (least recently used dropped first), for a
    computation that depends only on what its key covers (a scene's hash, a seed): an analysis run again
    on the same scene, F12 after F12 in Blender or a test suite's renders of one preset. ``copy`` makes
    what a caller gets from what is kept (identity for results nobody changes: a photon map; a deep copy
    for a report's block that a caller adds to). Safe across threads; two threads that miss one key at
    once both compute it, and the later result is kept."""

    def __init__(self, most: int, copy=None):
        self.most = int(most)
        self.copy = copy if copy is not None else (lambda value: value)
        self._entries: OrderedDict = OrderedDict()
        self._lock = threading.Lock()

    def __len__(self) -> int:
        return len(self._entries)

    def get(self, key, make):
        """What is kept under ``key``, or ``make()``'s result, kept (``copy`` of it either way)."""
        with self._lock:
            if key in self._entries:
                self._entries.move_to_end(key)
                return self.copy(self._entries[key])
        made = make()
        with self._lock:
            self._entries[key] = made
            self._entries.move_to_end(key)
            while len(self._entries) > self.most:
                self._entries.popitem(last=False)
        return self.copy(made)

    def clear(self):
        with self._lock:
            self._entries.clear()
