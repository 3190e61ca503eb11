"""Threads of the FEM's compiled kernels (numba ``prange`` loops): one setting.

``THREADS`` comes from the environment variable ``TORQUEBENCH_THREADS``: a positive integer fixes
the count; unset (or ``auto``) the kernels use the cores no other process is running on at the
call, between 1 and the machine's cores (``os.sched_getaffinity``): the kernel regions are short
(10 ms – 2 s) and a thread waiting at their end for a partner descheduled by another process's
work is slower than one thread (measured on the shared 2-core machine at load 3: the enriched
assembly 1.4 s with 1 thread, 1.7 s with 2; a CSR product 55 ms against 92 ms). "Busy" is the
kernel's instantaneous count of runnable tasks (/proc/stat ``procs_running``) less this process's
own (its numba workers may still be spinning after the last region).
Everything is capped by numba's pool (``NUMBA_NUM_THREADS``). ``use()`` applies the count before a
parallel kernel runs (numba's setting is per calling thread); ``limited(n)`` fixes ``n`` within a
block (tests and benchmarks compare 1 and N). The kernels' results do not depend on the count (the
reductions' partial sums are REDUCTION_CHUNKS ranges whatever the threads). BLAS stays at
one thread (flexure.blas explains why).
"""

from __future__ import annotations

import contextlib
import os


def _cores() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        return os.cpu_count() or 1


def _from_env() -> int | None:
    v = os.environ.get("TORQUEBENCH_THREADS", "").strip().lower()
    try:
        n = int(v)
    except ValueError:
        return None
    return n if n > 0 else None


#: threads of the FEM's parallel kernels (env TORQUEBENCH_THREADS); None: the idle cores at each call
THREADS: int | None = _from_env()
#: the partial sums of a reduction over rows (Aᵀ x: each range of rows into its own copy of the
#: result, then summed): a fixed count, not the threads found at the call, so that the order of the
#: sums, and the result's bits, do not change with the machine's load (an adaptive run repeated
#: refines the same way)
REDUCTION_CHUNKS = 2
CORES: int = _cores()
_override: int | None = None


def _running(line_of_stat: bytes) -> bool:
    return line_of_stat.rsplit(b")", 1)[-1].split()[0] == b"R"


def _others_running() -> int:
    """Runnable tasks on the machine that are not this process's own threads (/proc/stat
    ``procs_running`` minus this process's tasks in state R, /proc/self/task/*/stat; 0 if unknown)."""
    try:
        with open("/proc/stat", "rb") as f:
            total = next((int(line.split()[1]) for line in f if line.startswith(b"procs_running")), 0)
        own = 0
        for tid in os.listdir("/proc/self/task"):
            try:
                with open(f"/proc/self/task/{tid}/stat", "rb") as f:
                    own += _running(f.read())
            except OSError:
                pass
    except OSError:
        return 0
    return max(0, total - max(own, 1))


def idle_cores(own_children: int = 0) -> int:
    """Cores no other process is running on now, this one's ``own_children`` running processes
    not counted as others (flexure.gmsh_attempts runs attempts ahead on these only)."""
    return max(0, CORES - max(0, _others_running() - own_children))


def count() -> int:
    """The threads the parallel kernels use now: ``limited``'s, else THREADS, else the idle cores."""
    import numba

    if _override is not None:
        n = _override
    elif THREADS is not None:
        n = THREADS
    else:
        n = CORES - _others_running()
    return max(1, min(int(n), numba.config.NUMBA_NUM_THREADS))


_LAYER_SET = False


def select_layer() -> None:
    """numba's threading layer: ``workqueue`` unless NUMBA_THREADING_LAYER says otherwise. GNU
    OpenMP (numba's default where present) kills a process forked after it ran ("fork() called
    from a process already using GNU OpenMP"): torquebench.sweep forks its workers after the first
    point ran in the parent. workqueue is fork-safe and its idle workers sleep instead of spinning
    on a shared machine; it must not launch kernels from two threads at once (the FEM calls them
    from one)."""
    global _LAYER_SET
    if not _LAYER_SET:
        import numba

        if "NUMBA_THREADING_LAYER" not in os.environ:
            numba.config.THREADING_LAYER = "workqueue"
        _LAYER_SET = True


def use() -> int:
    """Set numba's thread count for this calling thread to ``count()``; → that count."""
    import numba

    select_layer()
    n = count()
    if numba.get_num_threads() != n:
        numba.set_num_threads(n)
    return n


@contextlib.contextmanager
def dynamic(chunk: int = 1):
    """Within the block numba hands a ``prange``'s iterations out ``chunk`` at a time to whichever
    thread is free (not in equal static shares: a descheduled thread delays the region by one chunk,
    not by its whole share)."""
    import numba

    with numba.parallel_chunksize(chunk):
        yield


_HELPER = None


def helper():
    """One helper Python thread (a one-worker ``ThreadPoolExecutor``) for work that releases the GIL
    beside the calling thread's (flexure.split_gs's second part). It must not launch numba's
    parallel loops (``select_layer``: workqueue, one launching thread)."""
    global _HELPER
    if _HELPER is None or _HELPER[0] != os.getpid():    # a forked child has not its parent's thread
        from concurrent.futures import ThreadPoolExecutor

        _HELPER = (os.getpid(), ThreadPoolExecutor(max_workers=1, thread_name_prefix="flexure-helper"))
    return _HELPER[1]


def is_limited() -> bool:
    """Whether ``limited`` fixes the thread count here (then no look at the idle cores)."""
    return _override is not None


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
