"""The P2 smoother's two parts side by side (flexure.split_gs): the renumbered blocks hold the whole
matrix and the two parts do not touch, a sweep is block Gauss–Seidel in the new order, the cycle stays
a symmetric preconditioner, the bits do not depend on the threads, and the CG iterations stay."""

import numpy as np
import pytest

from flexure import split_gs, threads
from flexure import solve as fsolve
from flexure.block_sparse import BlockMatrix
from test_fem_multirhs import disc as multirhs_disc  # noqa: F401  (a fixture)


@pytest.fixture(scope="module")
def disc(multirhs_disc):
    """test_fem_multirhs's annular P2 disc (4326 unknowns; rim fixed, bore rigidly coupled): its reduced
    system, the system's matrix with sorted indices, the six unit wrenches."""
    sy, B = multirhs_disc
    A = sy.A.tocsr()
    A.sort_indices()
    return sy, A, B


def _parts(A, dtype=np.float64):
    Dinv = np.ascontiguousarray(fsolve.block_diagonal_inverse(A))
    return split_gs.SplitSmoother(BlockMatrix.from_csr(A, dtype), Dinv), Dinv


def test_the_parts_hold_the_whole_matrix_and_do_not_touch(disc):
    """In-part blocks (columns ascending) plus off-part blocks = the renumbered matrix; P₀ and P₁
    share no block; the separator holds the dense reference rows; A x through the parts equals A x."""
    sy, A, _ = disc
    H, _ = _parts(A)
    Ap = A[H.perm][:, H.perm].toarray()
    for i, P in enumerate(H.blocks):
        for r in range(len(P.bptr) - 1):
            assert np.all(np.diff(P.bcol[P.bptr[r]:P.bptr[r + 1]]) > 0)
        assert np.array_equal(P.tocsr().toarray(), Ap[H._rows(i), H._rows(i)])
    assert not Ap[H._rows(0), H._rows(1)].any()
    assert min(H.bounds[1] - H.bounds[0], H.bounds[2] - H.bounds[1]) > 0.25 * len(Ap) // 3
    ref = np.arange(sy.ref_slices[0].start, sy.ref_slices[0].stop)
    assert np.all((H.inv[ref] >= 3 * H.bounds[2]))                 # the reference rows in S
    x = np.random.default_rng(0).standard_normal(A.shape[0])
    assert np.abs(H.matvec(x) - A @ x).max() <= 1e-12 * np.abs(A @ x).max()


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_the_parts_from_the_csr_are_the_block_copys(disc, dtype):
    """``from_csr`` (flexure.solve's path: each block's entries added straight into its place among the
    parts) gives the same blocks, bit for bit, as the parts of the block copy in A's order."""
    _, A, _ = disc
    H, Dinv = _parts(A, dtype)
    Hc = split_gs.SplitSmoother.from_csr(A, Dinv, dtype)
    assert Hc.bounds == H.bounds and np.array_equal(Hc.perm, H.perm)
    for P, Q in zip(H.blocks, Hc.blocks):
        assert np.array_equal(P.bptr, Q.bptr) and np.array_equal(P.bcol, Q.bcol)
        assert Q.data.dtype == dtype and np.array_equal(P.data, Q.data)
    for name in ("_off_ptr", "_off_col", "_off_data"):
        assert np.array_equal(getattr(H, name), getattr(Hc, name))
    B = np.random.default_rng(2).standard_normal((A.shape[0], 2))
    assert np.array_equal(H.forward_from_zero(B)[0], Hc.forward_from_zero(B)[0])


def test_blocks_of_a_wide_csr():
    """A scalar CSR with more block columns than block rows (the enriched coupling's shape): its blocks
    hold every entry (the column markers span the columns, not the rows)."""
    import scipy.sparse as sp

    W = sp.random(9, 30, density=0.3, format="csr", random_state=np.random.default_rng(4))
    Ab = BlockMatrix.from_csr(W, np.float64)
    assert Ab.shape == (9, 30) and abs(Ab.tocsr() - W).max() == 0.0


def test_a_sweep_is_block_gauss_seidel_in_the_new_order(disc):
    """The forward sweep from zero and the backward sweep equal x = (D + L)⁻¹ b and
    x + (D + U)⁻¹ (b − A x) of the renumbered matrix (L, U by 3 × 3 blocks), with the forward one's residual."""
    _, A, _ = disc
    H, _ = _parts(A)
    Ap = A[H.perm][:, H.perm].toarray()
    n = len(Ap)
    node = np.arange(n) // 3
    lower = np.where(node[:, None] >= node[None, :], Ap, 0.0)
    B = np.random.default_rng(1).standard_normal((n, 2))
    X, R = H.forward_from_zero(B)
    X_ref = np.linalg.solve(lower, B)
    assert np.abs(X - X_ref).max() <= 1e-10 * np.abs(X_ref).max()
    assert np.abs(R - (B - Ap @ X)).max() <= 1e-10 * np.abs(B).max()
    X0 = X.copy()
    H.backward(X, B)
    X_ref = X0 + np.linalg.solve(lower.T, B - Ap @ X0)
    assert np.abs(X - X_ref).max() <= 1e-10 * np.abs(X_ref).max()


def test_the_cycle_is_symmetric_and_the_threads_do_not_change_its_bits(disc, monkeypatch):
    """yᵀ M x = xᵀ M y to round-off (float64 blocks, float64 coarse factor), and 1 or 2 threads give
    the same bits; with the default float32 coarse factor (flexure.vcycle.COARSE_DTYPE) symmetric to
    its single precision."""
    from flexure import vcycle

    sy, A, _ = disc
    monkeypatch.setattr(fsolve, "SMOOTHER_STORAGE", "block64")
    M32, _ = fsolve._pmg_multi(A, sy.coarse, sy.B_coarse, False, 1)
    monkeypatch.setattr(vcycle, "COARSE_DTYPE", np.float64)
    M, _ = fsolve._pmg_multi(A, sy.coarse, sy.B_coarse, False, 1)
    assert isinstance(M.blocks, split_gs.SplitSmoother)
    rng = np.random.default_rng(2)
    x, y = rng.standard_normal((A.shape[0], 1)), rng.standard_normal((A.shape[0], 1))
    with threads.limited(1):
        Mx1, My = M(x), M(y)
    with threads.limited(2):
        Mx2 = M(x)
    assert np.array_equal(Mx1, Mx2)
    assert abs(float(y[:, 0] @ Mx1[:, 0]) - float(x[:, 0] @ My[:, 0])) <= 1e-12 * abs(float(y[:, 0] @ Mx1[:, 0]))
    assert float(x[:, 0] @ Mx1[:, 0]) > 0
    yMx, xMy = float(y[:, 0] @ M32(x)[:, 0]), float(x[:, 0] @ M32(y)[:, 0])
    assert abs(yMx - xMy) <= 1e-5 * abs(yMx)


def test_the_cg_iterations_stay(disc, monkeypatch):
    """The same P2 solve in the natural order and in P₀, P₁, S: another Gauss–Seidel ordering, so
    not the same iterations, but not a worse preconditioner by more than a quarter (measured: 1.10–1.17×
    here, where S is a fifth of the rows; the thick disc's goal solves 0.9–1.08× at 83–354 k DOFs) and
    the same answers to the CG tolerance."""
    sy, A, B = disc
    out = {}
    for split in (False, True):
        monkeypatch.setattr(fsolve, "SPLIT_SWEEPS", split)
        out[split] = fsolve.solve_system(sy.A, B, sy.B, "amg", 1e-10, coarse=sy.coarse, B_coarse=sy.B_coarse)
    (q0, i0), (q1, i1) = out[False], out[True]
    assert np.max(np.array(i1["iterations"]) / np.array(i0["iterations"])) <= 1.25
    assert np.abs(q1 - q0).max() <= 1e-8 * np.abs(q0).max()


def test_warm_compiles_on_a_matrix_without_a_second_part():
    """run.sh's warm-up: two isolated rows, no separator; the sweeps solve the diagonal system."""
    split_gs.warm()
    import scipy.sparse as sp

    H = split_gs.SplitSmoother(BlockMatrix.from_csr(sp.identity(6, format="csr") * 2.0, np.float64),
                               np.tile(np.eye(3) / 2.0, (2, 1, 1)))
    assert H.bounds[3] - H.bounds[2] == 0
    X, R = H.forward_from_zero(np.ones((6, 1)))
    assert np.allclose(X, 0.5) and np.allclose(R, 0.0)
