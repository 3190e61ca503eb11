"""BLAS threads while the FEM runs: one.

The FEM's hot loops are sparse (scipy: one thread; numba: the element loops and CSR products on
flexure.threads' threads, which leaves BLAS alone); the BLAS calls inside it are
level-1/2 on vectors of 10⁴–10⁶ entries (norms and dot products, the triangular solves of the coarse
LU, small batched solves), where threads only add their hand-over — and on a machine whose cores
are busy with other processes, a BLAS thread waiting for a descheduled partner: measured on the
2-core machine at load ~5, a norm of 30 000 entries took 5.3 ms with OpenBLAS's 2 threads and
0.012 ms with 1; a 5-column solve with a 5832-unknown sparse LU 53 ms against 25 ms
(benchmarks/bench_fem.py --only adaptive measures the whole solve both ways).
Without threadpoolctl the limit is not applied (same results, maybe slower).
"""

from __future__ import annotations

import contextlib
import functools

#: BLAS threads inside ``limited`` (None: leave the library's own setting)
THREADS: int | None = 1


@contextlib.contextmanager
def limited(threads: int | None = None):
    """Within the block, BLAS (OpenBLAS, MKL, BLIS) uses ``threads`` (default THREADS) threads."""
    n = THREADS if threads is None else threads
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:
        n = None
    if n is None:
        yield
        return
    with threadpool_limits(limits=n, user_api="blas"):
        yield


def single_threaded(fn):
    """``fn`` run within ``limited()``."""
    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        with limited():
            return fn(*args, **kwargs)
    return wrapper
