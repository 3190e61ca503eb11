"""A 3 × 3 block-sparse matrix (BSR: block row pointer, one int32 column per block, values
(n_blocks, 3, 3) of any float type) and its products on flexure.threads' threads: the enriched
solve's K_WW and K_hW (flexure.enriched). Against the scalar CSR of the same matrix (float64 values,
an int32 column per entry: 12 bytes an entry) it stores 4 + 9 s bytes a block (s the value size:
4.4 bytes an entry in float32, 8.4 in float64); products accumulate in float64 (y = A x: each row
in order; Aᵀ x: flexure.threads.REDUCTION_CHUNKS partial sums, then summed: the same bits for every
thread count)."""

from __future__ import annotations

import numpy as np

#: block rows a thread takes at a time in A x (dynamic hand-out: flexure.threads.dynamic)
ROW_CHUNK = 1024


class BlockMatrix:
    """(3 n_rows × 3 n_cols) with blocks ``data[p]`` at (r, bcol[p]), p ∈ [bptr[r], bptr[r+1])."""

    def __init__(self, bptr: np.ndarray, bcol: np.ndarray, data: np.ndarray, n_cols: int):
        self.bptr, self.bcol, self.data = bptr, bcol, data
        self.shape = (3 * (len(bptr) - 1), 3 * int(n_cols))

    @property
    def dtype(self):
        """The value type of the blocks."""
        return self.data.dtype

    @property
    def nbytes(self) -> int:
        """Bytes of the arrays held."""
        return self.bptr.nbytes + self.bcol.nbytes + self.data.nbytes

    def astype(self, dtype) -> "BlockMatrix":
        """The same pattern (shared) with values of ``dtype``."""
        return BlockMatrix(self.bptr, self.bcol, self.data.astype(dtype), self.shape[1] // 3)

    def matvec(self, x: np.ndarray) -> np.ndarray:
        """A x (x (3 n_cols,) float64)."""
        from flexure import _block_kernels as bk
        from flexure import threads

        y = np.empty(self.shape[0])
        with threads.dynamic(ROW_CHUNK):
            bk.matvec(self.bptr, self.bcol, self.data, np.ascontiguousarray(x, float), y)
        return y

    def rmatvec(self, x: np.ndarray) -> np.ndarray:
        """Aᵀ x (x (3 n_rows,) float64)."""
        from flexure import _block_kernels as bk
        from flexure import threads

        y = np.empty(self.shape[1])
        threads.use()
        bk.rmatvec(self.bptr, self.bcol, self.data, np.ascontiguousarray(x, float), y, threads.REDUCTION_CHUNKS)
        return y

    def matvec_rmatvec(self, x: np.ndarray, xt: np.ndarray):
        """(A x, Aᵀ xt) in one pass over A (x (3 n_cols,), xt (3 n_rows,) float64): the rows in
        ``rmatvec``'s chunks, so A x has ``matvec``'s bits and Aᵀ xt ``rmatvec``'s."""
        from flexure import _block_kernels as bk
        from flexure import threads

        threads.use()
        y, yt = np.empty(self.shape[0]), np.empty(self.shape[1])
        bk.matvec_rmatvec(self.bptr, self.bcol, self.data, np.ascontiguousarray(x, float),
                          np.ascontiguousarray(xt, float), y, yt, threads.REDUCTION_CHUNKS)
        return y, yt

    def colouring(self):
        """(cptr, order): the block rows by colour, no two of a colour sharing a block (square,
        structurally symmetric patterns; computed once)."""
        if getattr(self, "_colours", None) is None:
            from flexure import _block_kernels as bk

            self._colours = bk.colour_rows(self.bptr, self.bcol)
        return self._colours

    def symmetric_gauss_seidel(self, Dinv: np.ndarray, r: np.ndarray) -> np.ndarray:
        """z = M⁻¹ r of the multicolour symmetric block Gauss–Seidel M = (D + L) D⁻¹ (D + U) (D the
        3 × 3 diagonal blocks, Dinv their inverses (n,3,3); SPD where A is): one forward and one
        backward sweep from z = 0, each colour's rows in parallel."""
        from flexure import _block_kernels as bk
        from flexure import threads

        z = np.empty(self.shape[0])
        with threads.dynamic(ROW_CHUNK):
            bk.symmetric_gauss_seidel(self.bptr, self.bcol, self.data, Dinv, *self.colouring(),
                                      np.ascontiguousarray(r, float), z)
        return z

    @classmethod
    def from_csr(cls, A, dtype=np.float32) -> "BlockMatrix":
        """The 3 × 3 blocks of a scalar CSR A (3 n × 3 m) with values of ``dtype`` (each entry rounded
        once; an entry stored twice is summed in ``dtype``)."""
        from flexure import _block_kernels as bk
        from flexure import threads

        nt = threads.use()
        bptr, bcol, vals = bk.csr_to_blocks(A.indptr, A.indices, A.data, A.shape[0] // 3, A.shape[1] // 3,
                                            np.zeros(1, dtype), 1 if nt == 1 else 8 * nt)
        return cls(bptr, bcol, vals, A.shape[1] // 3)

    def tocsr(self):
        """The scipy CSR (float64) of the same matrix (tests, references)."""
        import scipy.sparse as sp

        n = len(self.bptr) - 1
        return sp.bsr_matrix((self.data.astype(float), self.bcol.astype(np.int64), self.bptr.astype(np.int64)),
                             shape=(3 * n, self.shape[1])).tocsr()
