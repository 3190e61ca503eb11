"""The compiled loops of flexure.split_gs (numba, compiled on first use and cached beside this
file): a 3 × 3 block matrix renumbered and split into parts (rows among the threads, each row's
output at its own place: the same result on any thread count), and the product of its off-part blocks."""

import numba
import numpy as np

from flexure import threads

threads.select_layer()                 # before any parallel loop runs (flexure.threads: fork safety)


@numba.njit(cache=True, nogil=True, parallel=True)
def split(bptr, bcol, data, perm, inv, part_of):
    """The block matrix A (bptr, bcol, data) renumbered, row and column r of the new one being
    row and column perm[r] of A (inv = perm⁻¹), each new row's blocks split into those whose column
    lies in the row's own part (``part_of`` per new row; parts are ranges of new rows) and the
    others. → (in_ptr, in_col, in_data): the in-part blocks, columns ascending, still global new
    numbers; (off_ptr, off_col, off_data): the off-part ones, in A's order."""
    in_ptr, in_col, off_ptr, off_col, src = split_places(bptr, bcol, perm, inv, part_of)
    n_in = in_ptr[len(perm)]
    in_data = np.empty((n_in, 3, 3), data.dtype)
    off_data = np.empty((len(src) - n_in, 3, 3), data.dtype)
    for q in numba.prange(n_in):
        in_data[q] = data[src[q]]
    for q in numba.prange(len(src) - n_in):
        off_data[q] = data[src[n_in + q]]
    return in_ptr, in_col, in_data, off_ptr, off_col, off_data


@numba.njit(cache=True, nogil=True, parallel=True)
def split_places(bptr, bcol, perm, inv, part_of):
    """``split``'s layout without its values: → (in_ptr, in_col, off_ptr, off_col, src): new block q
    (the in-part blocks in ``split``'s order first, then the off-part ones from n_in = in_ptr[-1] on)
    is A's block src[q] (flexure.split_gs.SplitSmoother.from_csr adds each block's entries there)."""
    n = len(perm)
    in_ptr = np.zeros(n + 1, np.int64)
    off_ptr = np.zeros(n + 1, np.int64)
    for r in numba.prange(n):
        i = perm[r]
        k = 0
        for p in range(bptr[i], bptr[i + 1]):
            k += part_of[inv[bcol[p]]] == part_of[r]
        in_ptr[r + 1] = k
        off_ptr[r + 1] = bptr[i + 1] - bptr[i] - k
    for r in range(n):
        in_ptr[r + 1] += in_ptr[r]
        off_ptr[r + 1] += off_ptr[r]
    n_in = in_ptr[n]
    in_col = np.empty(n_in, np.int32)
    off_col = np.empty(off_ptr[n], np.int32)
    src = np.empty(n_in + off_ptr[n], np.int64)
    for r in numba.prange(n):
        i = perm[r]
        a = in_ptr[r]
        b = off_ptr[r]
        for p in range(bptr[i], bptr[i + 1]):
            c = inv[bcol[p]]
            if part_of[c] == part_of[r]:
                q = a
                while q > in_ptr[r] and in_col[q - 1] > c:
                    in_col[q] = in_col[q - 1]
                    src[q] = src[q - 1]
                    q -= 1
                in_col[q] = c
                src[q] = p
                a += 1
            else:
                off_col[b] = c
                src[n_in + b] = p
                b += 1
    return in_ptr, in_col, off_ptr, off_col, src


@numba.njit(cache=True, nogil=True, parallel=True)
def inverse_permutation(src):
    """place (int64) with place[src[q]] = q: where each of A's blocks goes among the parts."""
    place = np.empty(len(src), np.int64)
    for q in numba.prange(len(src)):
        place[src[q]] = q
    return place


@numba.njit(cache=True, nogil=True)
def subtract_off(off_ptr, off_col, off_data, rows, r0, X, Y):
    """Y (rows 3 r0 … of the product, shifted to 0) −= the off-part blocks of the block ``rows``
    (those of a part that have any, ascending) times X (3 n, k), summed in float64."""
    k = X.shape[1]
    for r in rows:
        y = 3 * (r - r0)
        for p in range(off_ptr[r], off_ptr[r + 1]):
            c = 3 * np.int64(off_col[p])
            for a in range(3):
                v0 = np.float64(off_data[p, a, 0])
                v1 = np.float64(off_data[p, a, 1])
                v2 = np.float64(off_data[p, a, 2])
                for j in range(k):
                    Y[y + a, j] -= v0 * X[c, j] + v1 * X[c + 1, j] + v2 * X[c + 2, j]
