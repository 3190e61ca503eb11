"""Resident memory of this process (GB, as ``ru_maxrss`` KB / 1e6): the peak so far and now — what the
adaptive FEM's memory budget is measured with (flexure.adaptive_sizing)."""

from __future__ import annotations


def peak_gb() -> float:
    """Peak resident memory of this process so far (GB)."""
    import resource

    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e6


def now_gb(trim: bool = False) -> float:
    """Resident memory of this process now (GB; Linux /proc, else the peak so far); ``trim``: after
    returning the allocator's free heap pages to the system (glibc malloc_trim), which RSS counts
    although the next allocations reuse them (the memory model's baseline: flexure.adaptive_sizing)."""
    import os

    if trim:
        try:
            import ctypes
            ctypes.CDLL("libc.so.6").malloc_trim(0)
        except (OSError, AttributeError):
            pass

    try:
        with open("/proc/self/statm") as f:
            return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 1024 / 1e6   # as ru_maxrss (KB) / 1e6
    except (OSError, ValueError, IndexError):
        return peak_gb()
