"""The heap of a ``pmdcid`` command's own process (never a library user's: the command line's edge
calls :func:`tune_malloc`, docs/performance.md)."""

from __future__ import annotations

import os
import sys


def tune_malloc() -> bool:
    """In a ``pmdcid`` process on glibc: large arrays from the heap, and freed memory kept for
    the next one, instead of glibc's default (arrays above 32 MB mapped fresh and unmapped on
    free). A fit on a half-hour log makes the same few arrays of tens of megabytes hundreds of
    times; mapping them anew page-faults every page each time, which made long fits
    superlinear (docs/performance.md: 16x the log, CPU 15.3 s -> 9.8 s, peak memory +11 %).
    Set here, for the command line's own process only, never by the library (a process that
    imports pmdcid keeps its allocator as it is); ``PMDCID_MALLOC=default`` turns it off.
    True when set."""
    if os.environ.get("PMDCID_MALLOC") == "default" or not sys.platform.startswith("linux"):
        return False
    try:
        import ctypes

        mallopt = ctypes.CDLL(None).mallopt  # glibc only (musl has none)
    except (OSError, AttributeError):
        return False
    m_trim_threshold, m_mmap_threshold = -1, -3  # glibc's malloc.h
    return bool(mallopt(m_mmap_threshold, 1 << 30) and mallopt(m_trim_threshold, 1 << 30))


__all__ = ["tune_malloc"]
