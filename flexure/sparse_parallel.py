"""Sparse matrix–vector products on flexure.threads' threads (the CGs' matvecs: scipy's are one
thread): ``matvec(A, x)`` = A x and ``rmatvec(A, x)`` = Aᵀ x of a CSR matrix, by the compiled row loops
of flexure._sparse_kernels (A x: where flexure.threads gives more than one thread, else scipy's
product, the same bits); scipy's products without numba (estimator.compiled off) or for any other
format. Aᵀ x is summed in flexure.threads.REDUCTION_CHUNKS partial sums whatever the threads: the
same bits for every thread count."""

from __future__ import annotations

import numpy as np


#: rows a thread takes at a time in A x (dynamic hand-out: flexure.threads.dynamic)
ROW_CHUNK = 4096


def _threads(A) -> int:
    """Threads for a product with A: 0 where scipy's one-thread loop is used (no numba, not float CSR,
    or one thread: the compiled loop is no faster than scipy's on one)."""
    from estimator import compiled
    from flexure import threads

    if not (compiled.available() and A.format == "csr" and A.dtype == np.float64):
        return 0
    n = threads.use()
    return n if n > 1 else 0


def matvec(A, x: np.ndarray) -> np.ndarray:
    """A x (x (n,) float)."""
    if not _threads(A):
        return A @ x
    from flexure import _sparse_kernels as sk
    from flexure import threads

    y = np.empty(A.shape[0])
    with threads.dynamic(ROW_CHUNK):
        sk.csr_matvec(A.indptr, A.indices, A.data, np.ascontiguousarray(x, float), y)
    return y


def rmatvec(A, x: np.ndarray) -> np.ndarray:
    """Aᵀ x (x (m,) float): in flexure.threads.REDUCTION_CHUNKS partial sums on any thread count (the
    same bits whatever the load), scipy's product without numba or for another format."""
    from estimator import compiled

    if not (compiled.available() and A.format == "csr" and A.dtype == np.float64):
        return A.T @ x
    from flexure import _sparse_kernels as sk
    from flexure import threads

    threads.use()
    y = np.empty(A.shape[1])
    sk.csr_rmatvec(A.indptr, A.indices, A.data, np.ascontiguousarray(x, float), y, threads.REDUCTION_CHUNKS)
    return y
