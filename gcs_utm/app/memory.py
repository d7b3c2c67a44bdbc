"""The C allocator's handling of the large arrays of the monitoring cycle.

Each cycle builds and frees the same large NumPy arrays: the (N, K, 4) prediction, its
(N, K) planes and the temporaries of the detectors (at 100,000 UAS and 61 points the
prediction alone is 195 MB, a plane 49 MB). glibc serves a block above its mmap threshold
(dynamic, at most 32 MB) with a fresh mapping and unmaps it on free, and returns free memory
at the top of the heap to the system beyond its trim threshold; either way the next cycle's
arrays are fresh pages the kernel must map and zero, once per page (or huge page) per cycle.
That costs system time in proportion to the memory, on top of the work, only above the
threshold: it is what made the cycle grow faster than N between 10,000 and 100,000 UAS.

:func:`retain_freed_memory` makes the process keep what it has freed: blocks up to 2 GiB
come from the heap, and the heap is never trimmed, so each cycle reuses the memory of the
last one. The price is that the process holds its largest cycle's memory from then on (its
peak, which it needs again every period anyway), instead of returning it between cycles.
Where the C library is not glibc (no ``mallopt``) nothing changes.
"""

from __future__ import annotations

import ctypes
import ctypes.util

M_TRIM_THRESHOLD = -1  # glibc <malloc.h>
M_MMAP_THRESHOLD = -3
MMAP_THRESHOLD_B = 2**31 - 1  # the largest value mallopt takes (its value is a C int)
NEVER_TRIM = -1  # read by glibc as the largest size_t: the heap top is never returned


def retain_freed_memory() -> bool:
    """Keep freed memory in the process (see the module doc); True if the C library took
    the settings (glibc), False where it has no ``mallopt``."""
    name = ctypes.util.find_library("c")
    if name is None:
        return False
    try:
        libc = ctypes.CDLL(name)
        mallopt = libc.mallopt
    except (OSError, AttributeError):
        return False
    mallopt.argtypes = (ctypes.c_int, ctypes.c_int)
    mallopt.restype = ctypes.c_int
    return bool(
        mallopt(M_MMAP_THRESHOLD, MMAP_THRESHOLD_B) and mallopt(M_TRIM_THRESHOLD, NEVER_TRIM)
    )
