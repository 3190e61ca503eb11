"""Threads of the FEM's compiled kernels (numba ``prange`` loops): one setting.

``THREADS`` is read once from the environment variable ``TORQUEBENCH_THREADS`` (a positive integer;
unset or invalid: the machine's cores, ``os.cpu_count()``), capped by numba's own pool size
(``NUMBA_NUM_THREADS``). ``use()`` applies it before a parallel kernel runs (numba's setting is per
calling thread); ``limited(n)`` runs a block with ``n`` threads (tests and benchmarks compare 1 and N).
Every parallel kernel gives results independent of the thread count or equal to round-off
(flexure._parallel_kernels says which). BLAS stays at one thread (flexure.blas explains why).
"""

from __future__ import annotations

import contextlib
import os


def _from_env() -> int:
    try:
        n = int(os.environ.get("TORQUEBENCH_THREADS", ""))
    except ValueError:
        n = 0
    return n if n > 0 else (os.cpu_count() or 1)


#: threads of the FEM's parallel kernels (env TORQUEBENCH_THREADS; default the machine's cores)
THREADS: int = _from_env()
_override: int | None = None


def count() -> int:
    """The threads the parallel kernels use now (``limited``'s, else THREADS), within numba's pool."""
    import numba

    n = THREADS if _override is None else _override
    return max(1, min(int(n), numba.config.NUMBA_NUM_THREADS))


def use() -> int:
    """Set numba's thread count for this calling thread to ``count()``; → that count."""
    import numba

    n = count()
    if numba.get_num_threads() != n:
        numba.set_num_threads(n)
    return n


@contextlib.contextmanager
def limited(n: int):
    """Within the block the parallel kernels use ``n`` threads."""
    global _override
    old = _override
    _override = int(n)
    try:
        use()
        yield
    finally:
        _override = old
        use()
