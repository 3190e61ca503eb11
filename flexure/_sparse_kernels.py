"""The compiled loops of flexure.sparse_parallel (numba ``prange``, compiled on first use and cached
beside this file): y = A x of a CSR matrix, rows split among the threads (each row summed in order:
the same bits as scipy's one-thread loop whatever the thread count), and y = Aᵀ x, the rows in
``nchunk`` ranges each adding into its own copy of y, summed chunk by chunk (1 chunk: scipy's order)."""

import numba
import numpy as np

from flexure import threads

threads.select_layer()                 # before any parallel loop runs (flexure.threads: fork safety)


@numba.njit(cache=True, nogil=True, parallel=True)
def csr_matvec(indptr, indices, data, x, y):
    """y_i = Σ_p data_p x_{indices_p}, p ∈ [indptr_i, indptr_{i+1})."""
    for i in numba.prange(len(indptr) - 1):
        s = 0.0
        for p in range(indptr[i], indptr[i + 1]):
            s += data[p] * x[np.uint64(indices[p])]          # unsigned: no negative-index wrap test
        y[i] = s


@numba.njit(cache=True, nogil=True, parallel=True)
def csr_rmatvec(indptr, indices, data, x, y, nchunk):
    """y = Aᵀ x (y zeroed here): y_j = Σ_i Σ_{p: indices_p = j} data_p x_i."""
    n = len(indptr) - 1
    m = len(y)
    part = np.zeros((nchunk, m))
    for t in numba.prange(nchunk):
        for i in range(n * t // nchunk, n * (t + 1) // nchunk):
            xi = x[i]
            for p in range(indptr[i], indptr[i + 1]):
                part[t, np.uint64(indices[p])] += data[p] * xi
    for j in numba.prange(m):
        s = part[0, j]
        for t in range(1, nchunk):
            s += part[t, j]
        y[j] = s
