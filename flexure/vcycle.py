"""One V-cycle of a pyamg hierarchy on k right-hand sides at once: the coarse correction of the P2
p-multigrid (flexure.solve) for all load cases and goal duals together.

On level ℓ (matrix A_ℓ, prolongation P_ℓ, restriction R_ℓ = P_ℓᵀ), from X = 0:

    X ← block Gauss–Seidel forward on A_ℓ X = B,     B_(ℓ+1) = R_ℓ (B − A_ℓ X),
    X ← X + P_ℓ V_(ℓ+1)(B_(ℓ+1)),                    X ← block Gauss–Seidel backward,

and on the last level X = A_L⁻¹ B (sparse LU, every column in one triangular solve). The same
arithmetic per column as pyamg's ``ml.aspreconditioner(cycle="V")`` with its block Gauss–Seidel
smoothers (D⁻¹ the pseudo-inverses of the diagonal blocks, as pyamg), so the same CG iterations;
it reads each level's matrix once for all k columns, and skips what pyamg's ``solve`` does per
call for a stand-alone solver (‖b‖ and a residual norm). Needs numba (flexure.multirhs).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla


#: SuperLU's fill-reducing ordering of the last level: minimum degree on Aᵀ + A suits the symmetric
#: coarse matrix (thick disc, 5472 unknowns: L + U 2.8 M entries against COLAMD's 5.0 M, the factor
#: 0.31 s against 0.66 s, a 5-column solve 12 against 18 ms; solutions equal to 4e-14;
#: benchmarks/bench_fem_goal_solve.py --cg)
COARSE_ORDERING = "MMD_AT_PLUS_A"
#: and its pivots on the diagonal (the matrix is symmetric positive definite: no pivoting needed for
#: stability). With SuperLU's default partial pivoting (threshold 1) the rows it swaps break the
#: symmetric ordering's structure: on the thick disc's first mesh, whose P1 system (13,263 unknowns)
#: is the last level, the factor took 1.22 s and a 5-column solve 78 ms, against 0.15 s and 8.5 ms on
#: the diagonal (the same 2.6 M entries, solutions equal to 3e-14); on aggregation-coarsened last levels
#: (8.2 k and 14 k unknowns) 1.2× both (2026-11-27, load 3, best of 5 of SuperLU alone)
COARSE_OPTIONS = {"diag_pivot_thresh": 0.0, "options": {"SymmetricMode": True}}
#: the last level's factor in float32 (SuperLU's single-precision path): half the factor's bytes and
#: ~0.6× its time; its solves are ~5e-5 relative off the float64 ones (six_spoke_thick at 811 k P2 DOFs,
#: 15.9 k coarse unknowns: the factor 1.66 → 1.01 s, L + U 17.7 M entries), far inside the V-cycle's
#: own error reduction. float64: pyamg's coarse solve to round-off (tests). The factor is computed on a
#: thread of its own (``MultiVCycle``), beside the smoother's set-up that follows it (flexure.solve
#: ``_pmg_split``)
COARSE_DTYPE = np.float32


def _blocks(A) -> int:
    return A.blocksize[0] if A.format == "bsr" else 1


def _csr(A) -> sp.csr_matrix:
    """A as CSR with sorted int32 indices (the numba loops' input)."""
    C = sp.csr_matrix(A, dtype=np.float64)
    C.sort_indices()
    if C.shape[0] < 2**31 and C.nnz < 2**31:
        C.indices = C.indices.astype(np.int32, copy=False)
        C.indptr = C.indptr.astype(np.int32, copy=False)
    return C


class MultiVCycle:
    """V(B) → X for B (n, k): one V-cycle of ``ml`` (a pyamg MultilevelSolver whose smoothers are
    block Gauss–Seidel, forward before and backward after) on all columns; ``levels`` and
    ``operator_complexity`` describe the hierarchy (``ml`` itself is not kept)."""

    def __init__(self, ml, coarse_dtype=None):
        import threading

        from pyamg.util.utils import get_block_diag

        from flexure import threads

        self.n_levels = len(ml.levels)
        self.operator_complexity = float(ml.operator_complexity())
        Ac = sp.csc_matrix(ml.levels[-1].A, dtype=np.float64)
        Ac.eliminate_zeros()
        keep = np.flatnonzero(np.diff(Ac.indptr) != 0)          # zero rows/columns (pyamg's splu does the same)
        self._keep = keep
        self._n_last = Ac.shape[0]
        self._dtype = np.dtype(COARSE_DTYPE if coarse_dtype is None else coarse_dtype)
        # the last level's factor on a thread of its own while the levels above and the caller's set-up
        # go on (SuperLU holds no GIL): joined at the first coarse solve (``_coarse``); here, where the
        # kernels are held to one thread (flexure.threads: TORQUEBENCH_THREADS=1, a busy machine)
        self._lu, self._lu_error = None, None
        self._Ac = Ac[keep][:, keep].astype(self._dtype).tocsc()
        self._factor = None
        if threads.count() > 1:
            self._factor = threading.Thread(target=self._factorize, daemon=True)
            self._factor.start()
        else:
            self._factorize()
        self._levels = []
        for lv in ml.levels[:-1]:
            bs = _blocks(lv.A)
            Dinv = (get_block_diag(lv.A, blocksize=bs, inv_flag=True) if bs > 1
                    else (1.0 / lv.A.diagonal()).reshape(-1, 1, 1))
            self._levels.append((_csr(lv.A), np.ascontiguousarray(Dinv, dtype=np.float64),
                                 _csr(lv.P), _csr(lv.R)))

    def _factorize(self) -> None:
        try:
            self._lu = spla.splu(self._Ac, permc_spec=COARSE_ORDERING, **COARSE_OPTIONS)
            self._Ac = None
        except BaseException as exc:              # noqa: BLE001 (raised where the factor is first used)
            self._lu_error = exc

    def _coarse(self, B: np.ndarray) -> np.ndarray:
        if self._lu is None:
            if self._factor is not None:
                self._factor.join()
            if self._lu is None and self._lu_error is None:    # a forked child: the thread did not come along
                self._factorize()
            if self._lu_error is not None:
                raise self._lu_error
        X = np.zeros((self._n_last, B.shape[1]))
        X[self._keep] = self._lu.solve(np.asfortranarray(B[self._keep], dtype=self._dtype))
        return X

    def __call__(self, B: np.ndarray) -> np.ndarray:
        return self._cycle(0, np.ascontiguousarray(B, dtype=np.float64))

    def _cycle(self, lvl: int, B: np.ndarray) -> np.ndarray:
        from flexure import multirhs

        if lvl == len(self._levels):
            return self._coarse(B)
        A, Dinv, P, R = self._levels[lvl]
        X = np.zeros_like(B)
        # 3 × 3 blocks (the P1 vertex level): the loops generated for k columns, the same bits as the
        # runtime-sized ones in about half the time (thick disc, 51 k unknowns: 5.9 → 3.1 ms a sweep)
        gs = multirhs.block_gauss_seidel if Dinv.shape[1] == 3 else multirhs.block_gauss_seidel_blocks
        gs(A, Dinv, X, B, True)
        Bc = np.ascontiguousarray(R @ (B - A @ X))
        X += P @ self._cycle(lvl + 1, Bc)
        gs(A, Dinv, X, B, False)
        return X
