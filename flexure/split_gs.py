"""Block Gauss–Seidel on two cores: the P2 p-multigrid's smoother (flexure.solve) in an ordering
whose first two parts do not touch, so that their sweeps run side by side.

The nodal 3 × 3 block rows are renumbered by reverse Cuthill–McKee (a narrow band: neighbours in
space are neighbours in memory) and cut in two halves of equal count. The separator S holds the rows
of the second half that touch the first, and the dense rows (more than DENSE × the median number of
blocks: a rigid coupling's reference node, which touches a whole bore); the parts are P₀ = the first
half and P₁ = the rest of the second, without S. With the rows ordered P₀, P₁, S, block Gauss–Seidel

    x_i ← x_i + D_i⁻¹ (b_i − Σ_j A_ij x_j)        (rows in that order, forward; reversed, backward)

does P₀ and P₁ independently (A_P₀P₁ = 0) and then S (forward), or S and then both (backward): the
same sweeps as one thread in that ordering, bit for bit, whatever the threads. The separator is
small: on the thick disc 1.8 % of the rows at 83 k DOFs, 1.4 % at 338 k.
"""

from __future__ import annotations

import numpy as np

#: a row with more than DENSE × the median number of blocks goes to the separator
DENSE = 8.0


def warm() -> None:
    """Compile (and cache) the renumbering and the off-part product on a tiny matrix."""
    import scipy.sparse as sp

    for dtype in (np.float32, np.float64):
        A = sp.identity(6, format="csr") * 2.0
        H = SplitSmoother.from_csr(A, np.tile(np.eye(3) / 2.0, (2, 1, 1)), dtype)     # flexure.solve's path
        H.backward(H.forward_from_zero(np.ones((6, 1)))[0], np.ones((6, 1)))
        H.matvec(np.ones(6))


def rcm_order(bptr: np.ndarray, bcol: np.ndarray) -> np.ndarray:
    """Reverse Cuthill–McKee order of a block pattern's graph (new row r = old row order[r])."""
    import scipy.sparse as sp
    from scipy.sparse.csgraph import reverse_cuthill_mckee

    n = len(bptr) - 1
    G = sp.csr_matrix((np.ones(len(bcol), np.int8), bcol, bptr), shape=(n, n))
    return np.asarray(reverse_cuthill_mckee(G, symmetric_mode=True), np.int64)


def ordering(bptr: np.ndarray, bcol: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(order, part): the block rows in the order P₀, P₁, S (module docstring; new row r = old row
    order[r]) and each new row's part (0, 1, 2 = S)."""
    n = len(bptr) - 1
    rcm = rcm_order(bptr, bcol)
    pos = np.empty(n, np.int64)
    pos[rcm] = np.arange(n)
    deg = np.diff(bptr)
    half = np.where(pos < n // 2, 0, 1)
    half[deg > DENSE * max(np.median(deg), 1.0)] = 2
    row = np.repeat(np.arange(n), deg)
    touch = (half[row] == 1) & (half[bcol] == 0)
    half[np.unique(row[touch])] = 2
    order = rcm[np.argsort(half[rcm], kind="stable")]
    return order, half[order]


class SplitSmoother:
    """Block Gauss–Seidel of a symmetric BlockMatrix ``Ab`` (Dinv its 3 × 3 diagonal blocks'
    inverses) in the order P₀, P₁, S, with P₀ and P₁ side by side: ``perm`` (dofs: new dof d is old dof
    perm[d]), ``inv``; vectors passed to ``forward_from_zero`` and ``backward`` are in that order.
    ``from_csr`` builds the same parts from a scalar CSR without the block copy in A's order."""

    def __init__(self, Ab, Dinv: np.ndarray):
        from flexure import _split_kernels as sk
        from flexure import threads

        order, part, inv_b = self._order(Ab.bptr, Ab.bcol)
        threads.use()
        in_ptr, in_col, in_data, off_ptr, off_col, off_data = sk.split(Ab.bptr, Ab.bcol, Ab.data, order, inv_b, part)
        self._parts(order, part, Dinv, in_ptr, in_col, in_data, off_ptr, off_col, off_data)

    @classmethod
    def from_csr(cls, A, Dinv: np.ndarray, dtype=np.float32) -> "SplitSmoother":
        """The parts of the scalar CSR A (symmetric, 3 n × 3 n) with blocks of ``dtype``: its block
        pattern, the order, then each block's entries added straight into its place among the parts
        (flexure.solve's path): the same blocks, bit for bit, as ``SplitSmoother(BlockMatrix.from_csr(A,
        dtype), Dinv)``, and no block copy of A in its own order alive beside them."""
        from flexure import _block_kernels as bk
        from flexure import _split_kernels as sk
        from flexure import threads

        self = cls.__new__(cls)
        nt = threads.use()
        chunks = 1 if nt == 1 else 8 * nt
        nb = A.shape[0] // 3
        bptr, bcol = bk.csr_block_pattern(A.indptr, A.indices, nb, nb, chunks)
        order, part, inv_b = self._order(bptr, bcol)
        in_ptr, in_col, off_ptr, off_col, src = sk.split_places(bptr, bcol, order, inv_b, part)
        place = sk.inverse_permutation(src)
        del src
        vals = np.zeros((len(place), 3, 3), dtype)
        with threads.dynamic():
            bk.csr_block_values(A.indptr, A.indices, A.data, bptr, bcol, nb, place, vals, chunks)
        del place, bcol
        n_in = in_ptr[-1]
        self._parts(order, part, Dinv, in_ptr, in_col, vals[:n_in], off_ptr, off_col, vals[n_in:])
        return self

    @staticmethod
    def _order(bptr, bcol):
        order, part = ordering(bptr, bcol)
        inv_b = np.empty(len(order), np.int64)
        inv_b[order] = np.arange(len(order))
        return order, part, inv_b

    def _parts(self, order, part, Dinv, in_ptr, in_col, in_data, off_ptr, off_col, off_data) -> None:
        from flexure.block_sparse import BlockMatrix

        self.bounds = np.searchsorted(part, np.arange(4)).tolist()     # P₀, P₁, S as ranges of new rows
        self._off_ptr, self._off_col, self._off_data = off_ptr, off_col, off_data
        has_off = np.diff(off_ptr) > 0
        self._off_rows = [lo + np.flatnonzero(has_off[lo:hi]) for lo, hi in zip(self.bounds[:-1], self.bounds[1:])]
        self.blocks, self.D = [], []
        for lo, hi in zip(self.bounds[:-1], self.bounds[1:]):
            ptr = in_ptr[lo:hi + 1] - in_ptr[lo]
            cols = in_col[in_ptr[lo]:in_ptr[hi]] - np.int32(lo)
            self.blocks.append(BlockMatrix(ptr, cols, in_data[in_ptr[lo]:in_ptr[hi]], hi - lo))
            self.D.append(np.ascontiguousarray(Dinv[order[lo:hi]]))
        self.perm = (3 * order[:, None] + np.arange(3)).ravel()
        self.inv = np.empty_like(self.perm)
        self.inv[self.perm] = np.arange(len(self.perm))
        self.dtype = in_data.dtype

    def _rows(self, i: int) -> slice:
        return slice(3 * self.bounds[i], 3 * self.bounds[i + 1])

    def _off(self, i: int, X: np.ndarray, Y: np.ndarray) -> None:
        """Y −= (part i's blocks outside it) X, X (3 n, k) in the new order."""
        from flexure import _split_kernels as sk

        sk.subtract_off(self._off_ptr, self._off_col, self._off_data, self._off_rows[i], self.bounds[i], X, Y)

    def _both(self, work) -> list:
        """[work(0), work(1)]: side by side when flexure.threads gives more than one thread."""
        from flexure import threads

        if threads.count() < 2:
            return [work(0), work(1)]
        second = threads.helper().submit(work, 1)          # this process's helper thread
        first = work(0)
        return [first, second.result()]

    def forward_from_zero(self, B: np.ndarray):
        """(X, R): one forward sweep from X = 0 on A X = B (B (n, k), new order) and its residual
        R = B − A X."""
        from flexure import multirhs

        sweep = multirhs.forward_gauss_seidel_residual_bsr
        done = self._both(lambda i: sweep(self.blocks[i], self.D[i], B[self._rows(i)]))
        X = np.empty_like(B)
        R = np.empty_like(B)
        for i in (0, 1):
            X[self._rows(i)], R[self._rows(i)] = done[i]
        s = np.array(B[self._rows(2)])
        self._off(2, X, s)                        # S after both parts
        X[self._rows(2)], R[self._rows(2)] = sweep(self.blocks[2], self.D[2], s)
        for i in (0, 1):                          # the parts' residuals with S's new values
            self._off(i, X, R[self._rows(i)])
        return X, R

    def backward(self, X: np.ndarray, B: np.ndarray) -> None:
        """One backward sweep in place on X (n, k) (C-ordered, new order) for A X = B."""
        from flexure import multirhs

        sweep = multirhs.block_gauss_seidel_bsr
        s = np.array(B[self._rows(2)])
        self._off(2, X, s)
        sweep(self.blocks[2], self.D[2], X[self._rows(2)], s, False)      # S first, then both parts

        def part(i):
            b = np.array(B[self._rows(i)])
            self._off(i, X, b)
            sweep(self.blocks[i], self.D[i], X[self._rows(i)], b, False)
        self._both(part)

    def matvec(self, x: np.ndarray) -> np.ndarray:
        """A x in the original numbering (x (n,) float64): the parts' blocks, summed in float64."""
        xp = np.ascontiguousarray(np.asarray(x, float)[self.perm])
        y = np.concatenate([b.matvec(xp[self._rows(i)]) for i, b in enumerate(self.blocks)])
        minus_off = np.zeros((len(y), 1))
        for i in range(3):
            self._off(i, xp.reshape(-1, 1), minus_off[self._rows(i)])
        return (y - minus_off[:, 0])[self.inv]
