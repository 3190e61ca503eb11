"""Sparse matrix–vector products on flexure.threads' threads (the CGs' matvecs: scipy's are one
thread): ``matvec(A, x)`` = A x and ``rmatvec(A, x)`` = Aᵀ x of a CSR matrix, by the compiled row loops
of flexure._sparse_kernels when flexure.threads gives more than one thread; scipy's product with
one, without numba (estimator.compiled off) or for any other format. A x has the same bits for every thread count; Aᵀ x is summed in one chunk per thread (equal to
round-off across thread counts, the same bits as scipy with one)."""

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
    """Aᵀ x (x (m,) float)."""
    n = _threads(A)
    if not n:
        return A.T @ x
    from flexure import _sparse_kernels as sk

    y = np.empty(A.shape[1])
    sk.csr_rmatvec(A.indptr, A.indices, A.data, np.ascontiguousarray(x, float), y, n)
    return y
