"""Allocator settings for processes that trace: keep freed memory for the next bounce.

Each bounce of the path loop allocates and frees tens of numpy arrays of 0.25 to 3 MiB. glibc's
malloc serves blocks above its mmap threshold (128 KiB at start, raised as blocks are freed) with
fresh pages from the kernel, and returns the top of its heap to the kernel once more than its trim
threshold is free; either way the next bounce faults the same pages in again (on hud-direct, 9 to 15 %
of a backward render's time in the kernel; the gain is in docs/results/speed.md).

:func:`keep_freed_memory` raises both thresholds (mallopt, glibc only; elsewhere it does nothing).
It changes the whole process, so it is called where a process exists to trace: the command line,
render worker processes, ``hud-render``, the benchmarks and a Dask worker once it traces a render's
batches (Dask's nanny starts workers with MALLOC_TRIM_THRESHOLD_=65536, which made a hud-direct batch
take 3.0 s there against 0.8 s in a plain process); not inside Blender's own process (the add-on's F12
render), whose memory belongs to others too.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import sys

#: mallopt parameters (glibc's malloc.h).
M_TRIM_THRESHOLD, M_MMAP_THRESHOLD = -1, -3
#: Blocks up to this size come from the heap (glibc's upper limit for the mmap threshold on 64-bit).
MMAP_THRESHOLD_BYTES = 32 << 20
#: Free memory kept at the top of the heap before it is returned to the kernel.
TRIM_THRESHOLD_BYTES = 1 << 30

_done = False


def keep_freed_memory() -> bool:
    """Raise glibc's mmap and trim thresholds for this process (once); True where they were set."""
    global _done
    if _done:
        return True
    if not sys.platform.startswith("linux"):
        return False
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        mallopt = libc.mallopt
    except (OSError, AttributeError):  # not glibc (musl has no mallopt)
        return False
    mallopt.argtypes, mallopt.restype = (ctypes.c_int, ctypes.c_int), ctypes.c_int
    _done = bool(mallopt(M_MMAP_THRESHOLD, MMAP_THRESHOLD_BYTES)) and bool(
        mallopt(M_TRIM_THRESHOLD, TRIM_THRESHOLD_BYTES))
    return _done
