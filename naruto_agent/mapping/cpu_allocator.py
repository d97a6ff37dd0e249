"""Let glibc keep freed tensor memory for reuse, so a mapping iteration does not page-fault.

A mapping iteration allocates and frees a few hundred MB of temporaries of 1-30 MB each (the
hash grid's corner indices and weights, the MLP activations). glibc serves every block above
its mmap threshold with fresh pages from the kernel and hands them back on free, so every
iteration page-faults all of its temporaries in again, a share of the iteration's time that
matters on a CPU. Raising the mmap threshold to glibc's maximum (32 MiB) and the trim
threshold keeps those blocks on the heap, where the next iteration reuses them.

This is glibc's documented ``mallopt`` tuning (the same as setting ``MALLOC_MMAP_THRESHOLD_``
and ``MALLOC_TRIM_THRESHOLD_`` in the environment). It is process-wide, costs at most the
peak of what was freed staying mapped, and does nothing on other C libraries.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import sys

from naruto_gym.utils.checks import check_integer

# mallopt parameter numbers from glibc's <malloc.h>.
_M_TRIM_THRESHOLD = -1
_M_MMAP_THRESHOLD = -3
# glibc refuses mmap thresholds above HEAP_MAX_SIZE / 2, which is 32 MiB on 64-bit.
MAX_MMAP_THRESHOLD_BYTES = 32 * 1024 * 1024
DEFAULT_TRIM_THRESHOLD_BYTES = 1024 * 1024 * 1024

_applied = False


def _glibc() -> ctypes.CDLL | None:
    if not sys.platform.startswith("linux"):
        return None
    name = ctypes.util.find_library("c")
    if name is None:
        return None
    try:
        libc = ctypes.CDLL(name)
    except OSError:
        return None
    # Only glibc has gnu_get_libc_version; mallopt's parameter numbers are glibc's.
    if not (hasattr(libc, "gnu_get_libc_version") and hasattr(libc, "mallopt")):
        return None
    return libc


def keep_freed_memory_for_reuse(
    mmap_threshold_bytes: int = MAX_MMAP_THRESHOLD_BYTES,
    trim_threshold_bytes: int = DEFAULT_TRIM_THRESHOLD_BYTES,
) -> bool:
    """Tune glibc's allocator once per process; returns True when it is (or already was) set.

    Returns False, changing nothing, on a C library other than glibc.
    """
    global _applied
    check_integer(
        "mmap_threshold_bytes (glibc's maximum is 32 MiB)",
        mmap_threshold_bytes,
        low=1,
        high=MAX_MMAP_THRESHOLD_BYTES,
    )
    check_integer("trim_threshold_bytes", trim_threshold_bytes, low=1)
    if _applied:
        return True
    libc = _glibc()
    if libc is None:
        return False
    libc.mallopt.argtypes = [ctypes.c_int, ctypes.c_int]
    libc.mallopt.restype = ctypes.c_int
    trim_threshold_bytes = min(trim_threshold_bytes, 2**31 - 1)
    ok = bool(libc.mallopt(_M_MMAP_THRESHOLD, mmap_threshold_bytes)) and bool(
        libc.mallopt(_M_TRIM_THRESHOLD, trim_threshold_bytes)
    )
    _applied = ok
    return ok
