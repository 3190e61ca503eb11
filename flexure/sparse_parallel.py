"""Sparse matrix–vector products on flexure.threads' threads (the CGs' matvecs: scipy's are one
thread): ``matvec(A, x)`` = A x and ``rmatvec(A, x)`` = Aᵀ x of a CSR matrix, by the compiled row loops
of flexure._sparse_kernels; scipy's product without numba (estimator.compiled off) or for any other
format. A x has the same bits for every thread count; Aᵀ x is summed in one chunk per thread (equal to
round-off across thread counts, the same bits as scipy with one)."""

from __future__ import annotations

import numpy as np


def _compiled(A) -> bool:
    from estimator import compiled

    return compiled.available() and A.format == "csr" and A.dtype == np.float64


def matvec(A, x: np.ndarray) -> np.ndarray:
    """A x (x (n,) float)."""
    if not _compiled(A):
        return A @ x
    from flexure import _sparse_kernels as sk
    from flexure import threads

    threads.use()
    y = np.empty(A.shape[0])
    sk.csr_matvec(A.indptr, A.indices, A.data, np.ascontiguousarray(x, float), y)
    return y


def rmatvec(A, x: np.ndarray) -> np.ndarray:
    """Aᵀ x (x (m,) float)."""
    if not _compiled(A):
        return A.T @ x
    from flexure import _sparse_kernels as sk
    from flexure import threads

    n = threads.use()
    y = np.empty(A.shape[1])
    sk.csr_rmatvec(A.indptr, A.indices, A.data, np.ascontiguousarray(x, float), y, n)
    return y
