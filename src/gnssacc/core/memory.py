"""Giving freed memory back to the operating system between the stages of a long run.

glibc's allocator keeps blocks freed by the process for reuse, and raises its threshold for
serving large arrays from their own mappings each time such an array is freed; after a stage that
made many large temporaries (parsing a CSV file in blocks, differencing a long IMU record) the
process can hold a hundred MiB it no longer uses, which then adds to the next stage's peak.
``malloc_trim(0)`` returns the free pages (also those inside the heap) at once. Elsewhere (macOS,
musl, Windows) this is a no-op. Dask's workers do the same for the same reason.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import functools


@functools.lru_cache(maxsize=1)
def _trim():
    """glibc's ``malloc_trim``, or ``None`` where the C library has none."""
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        return libc.malloc_trim
    except (OSError, AttributeError):
        return None


def release_free_memory() -> bool:
    """Return freed heap pages to the operating system; ``True`` when the C library could."""
    trim = _trim()
    return bool(trim(0)) if trim is not None else False
