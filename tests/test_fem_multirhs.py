"""Load cases solved together (flexure.multirhs): the loops equal scipy/pyamg column by column,
and the P2 solve gives the same iterations and answers as one CG per load case."""

from pathlib import Path

import numpy as np
import pytest
import scipy.sparse as sp

from flexure import multirhs
from flexure import solve as fsolve
from flexure.bc import Problem
from flexure.fem import stiffness_matrix
from flexure.material import ALUMINIUM_6061_T6 as MAT
from flexure.mesh import cylinder_mesh


def test_warm_compiles_every_width():
    assert multirhs.warm()
    X = np.zeros((6, 2))
    multirhs.block_gauss_seidel(sp.identity(6, format="csr") * 2.0, np.tile(np.eye(3) / 2.0, (2, 1, 1)), X,
                                np.ones((6, 2)), True)
    assert np.allclose(X, 0.5)                     # one sweep on a diagonal system solves it


@pytest.mark.parametrize("name", sorted(multirhs.GENERATED))
def test_generated_loops_are_the_generator_output(name):
    path = Path(multirhs.__file__).with_name(name)
    assert path.read_text() == multirhs._generate(name)


@pytest.fixture(scope="module")
def disc():
    """An annular P2 disc, rim fixed, bore rigidly coupled: the reduced system and six unit wrenches.
    4326 unknowns: CG needs 36–49 iterations per case; at 10758 (4 × 32 × 3 cells) the one-CG-per-
    case reference alone took 7 CPU-s for the same check."""
    m = cylinder_mesh(0.004, 0.03, 0.006, 3, 24, 2, order=2)
    r = np.hypot(m.points[:, 0], m.points[:, 1])
    p = Problem(m, MAT).fix(np.flatnonzero(r > 0.03 * (1 - 1e-9)))
    p.couple_rigid(np.flatnonzero(r < 0.004 * (1 + 1e-9)), (0, 0, 0.003))
    sy = p.reduced_system(stiffness_matrix(m, MAT))
    B = np.zeros((sy.A.shape[0], 6))
    B[sy.ref_slices[0], :] = np.eye(6)
    return sy, B


@pytest.mark.parametrize("k", [1, 4, 6, 9])
def test_spmm_equals_scipy(disc, k):
    sy, _ = disc
    X = np.random.default_rng(k).standard_normal((sy.A.shape[0], k))
    Y = multirhs.spmm(sy.A, X)
    assert np.abs(Y - sy.A @ X).max() <= 1e-12 * np.abs(sy.A @ X).max()


def test_spmm_same_bits_on_any_thread_count(disc):
    """The rows are split among threads, each row summed in order: 1 and 2 threads give the same bits."""
    from flexure import threads

    sy, _ = disc
    X = np.random.default_rng(5).standard_normal((sy.A.shape[0], 5))
    with threads.limited(1):
        Y1 = multirhs.spmm(sy.A, X)
    with threads.limited(2):                  # 4326 rows: three chunks of ROW_CHUNK, both threads take some
        Y2 = multirhs.spmm(sy.A, X)
    assert np.array_equal(Y1, Y2)


@pytest.mark.parametrize("forward", [True, False])
def test_block_gauss_seidel_equals_pyamg_per_column(disc, forward):
    from pyamg.relaxation.relaxation import block_gauss_seidel
    from pyamg.util.utils import get_block_diag

    sy, _ = disc
    A = sy.A.tocsr()
    Dinv = np.ascontiguousarray(get_block_diag(A.tobsr(blocksize=(3, 3)), blocksize=3, inv_flag=True))
    rng = np.random.default_rng(1)
    B = rng.standard_normal((A.shape[0], 7))
    X = rng.standard_normal((A.shape[0], 7))
    ref = X.copy()
    multirhs.block_gauss_seidel(A, Dinv, X, B, forward)
    for j in range(7):
        x = ref[:, j].copy()
        block_gauss_seidel(A.tobsr(blocksize=(3, 3)), x, B[:, j], iterations=1,
                           sweep="forward" if forward else "backward", blocksize=3, Dinv=Dinv)
        assert np.abs(X[:, j] - x).max() <= 1e-10 * np.abs(x).max()


def test_load_cases_together_equal_one_cg_per_case(disc, monkeypatch):
    sy, B = disc
    B = B.copy()
    B[:, 2] = 0.0                                      # an all-zero case: zero answer, no iterations
    monkeypatch.setattr(fsolve, "SPLIT_SWEEPS", False)       # pyamg's natural-order sweeps on both sides
    out = {}
    for multi in (True, False):
        monkeypatch.setattr(fsolve, "MULTI_RHS", multi)
        out[multi] = fsolve.solve_system(sy.A, B, sy.B, "amg", 1e-10, coarse=sy.coarse, B_coarse=sy.B_coarse)
    (q1, i1), (q0, i0) = out[True], out[False]
    assert "together" in i1["solver"] and "together" not in i0["solver"]
    assert i1["iterations"][2] == 0 and np.all(q1[:, 2] == 0.0)
    assert all(abs(a - b) <= 1 for a, b in zip(i1["iterations"], i0["iterations"]))
    assert np.abs(q1 - q0).max() <= 1e-8 * np.abs(q0).max()
    assert i1["residual_norm"] < 1e-9 and len(i1["case_residuals"]) == 6
    direct = sp.linalg.spsolve(sy.A.tocsc(), B)
    assert np.abs(q1 - direct).max() <= 1e-7 * np.abs(direct).max()


@pytest.mark.parametrize("smoothed", [False, True])
def test_vcycle_on_all_columns_equals_pyamg_per_column(disc, smoothed):
    """flexure.vcycle: one V-cycle of a 3-level hierarchy (3×3 blocks on the finest level, 6×6 below)
    on seven columns at once equals pyamg's V-cycle preconditioner column by column."""
    from flexure.vcycle import MultiVCycle

    sy, _ = disc
    A1 = (sy.coarse.T @ sy.A @ sy.coarse).tocsr()
    ml = fsolve._sa_hierarchy(A1, sy.B_coarse, smoothed=smoothed, max_coarse=10)
    assert len(ml.levels) >= 3 and ml.levels[1].A.blocksize == (6, 6)
    V = MultiVCycle(ml, coarse_dtype=np.float64)
    M = ml.aspreconditioner(cycle="V")
    R = np.random.default_rng(3).standard_normal((A1.shape[0], 7))
    X = V(R)
    for j in range(7):
        ref = M @ R[:, j]
        assert np.abs(X[:, j] - ref).max() <= 1e-10 * np.abs(ref).max()
    assert V.n_levels == len(ml.levels) and V.operator_complexity == pytest.approx(ml.operator_complexity())


def test_last_level_lu_on_the_diagonal_solves_the_p1_system(disc):
    """flexure.vcycle's last level factored with its pivots on the diagonal (COARSE_OPTIONS: the
    coarse matrix is SPD): where the P1 system itself is the last level (max_coarse above its nodes),
    the cycle is its exact solve, equal to a partially pivoted sparse solve."""
    from flexure import vcycle

    sy, _ = disc
    A1 = (sy.coarse.T @ sy.A @ sy.coarse).tocsr()
    ml = fsolve._sa_hierarchy(A1, sy.B_coarse, smoothed=False, max_coarse=A1.shape[0])
    assert len(ml.levels) == 1 and vcycle.COARSE_OPTIONS["diag_pivot_thresh"] == 0.0
    R = np.random.default_rng(5).standard_normal((A1.shape[0], 4))
    X = vcycle.MultiVCycle(ml, coarse_dtype=np.float64)(R)
    ref = sp.linalg.spsolve(A1.tocsc(), R)
    assert np.abs(X - ref).max() <= 1e-10 * np.abs(ref).max()
    assert np.abs(A1 @ X - R).max() <= 1e-9 * np.abs(R).max()


def test_last_level_factor_in_float32_is_a_float64_solve_to_its_precision(disc):
    """The default last-level factor (vcycle.COARSE_DTYPE, float32): on the P1 system as the last level
    its solve is the float64 one to ~1e-5 relative (single precision times the coarse matrix's
    condition), far inside a V-cycle's own error reduction; the cycle's output stays float64."""
    from flexure import vcycle

    sy, _ = disc
    A1 = (sy.coarse.T @ sy.A @ sy.coarse).tocsr()
    ml = fsolve._sa_hierarchy(A1, sy.B_coarse, smoothed=False, max_coarse=A1.shape[0])
    assert vcycle.COARSE_DTYPE == np.float32
    R = np.random.default_rng(6).standard_normal((A1.shape[0], 3))
    X32 = vcycle.MultiVCycle(ml)(R)
    X64 = vcycle.MultiVCycle(ml, coarse_dtype=np.float64)(R)
    assert X32.dtype == np.float64
    err = np.abs(X32 - X64).max() / np.abs(X64).max()
    assert 1e-9 < err <= 1e-4


def test_last_level_factor_on_its_thread_raises_where_it_is_first_used(disc, monkeypatch):
    """The last level is factored on a thread beside the caller's set-up (vcycle.MultiVCycle, where the
    kernels may use two threads; in the caller's where they are held to one): the same bits either way
    and as many times as the cycle is built; a factorisation that fails (a singular coarse matrix)
    raises its own error at the first cycle, in the caller's thread; a thread that did not factor (a
    forked child's copy of a cycle built before the fork) leaves it to the first cycle."""
    from flexure import threads, vcycle

    sy, _ = disc
    A1 = (sy.coarse.T @ sy.A @ sy.coarse).tocsr()
    ml = fsolve._sa_hierarchy(A1, sy.B_coarse, smoothed=False, max_coarse=200)
    R = np.random.default_rng(7).standard_normal((A1.shape[0], 2))
    with threads.limited(1):
        V1 = vcycle.MultiVCycle(ml)
        assert V1._lu is not None and V1._factor is None
        first = V1(R)
    real, calls = vcycle.MultiVCycle._factorize, []

    def first_call_lost(self):
        calls.append(1)
        if len(calls) > 1:
            real(self)

    def singular(*args, **kwargs):
        raise RuntimeError("Factor is exactly singular")

    with threads.limited(2):
        V2 = vcycle.MultiVCycle(ml)
        import numba

        assert (V2._factor is not None) == (numba.config.NUMBA_NUM_THREADS > 1)   # a one-core machine: no thread
        assert np.array_equal(V2(R), first) and np.array_equal(vcycle.MultiVCycle(ml)(R), first)
        monkeypatch.setattr(vcycle.MultiVCycle, "_factorize", first_call_lost)
        assert np.array_equal(vcycle.MultiVCycle(ml)(R), first) and len(calls) == 2
        monkeypatch.setattr(vcycle.MultiVCycle, "_factorize", real)
        monkeypatch.setattr(vcycle.spla, "splu", singular)
        V = vcycle.MultiVCycle(ml)
        with pytest.raises(RuntimeError, match="exactly singular"):
            V(R)


@pytest.mark.parametrize("k", [1, 5, 8])
def test_forward_sweep_from_zero_with_residual_equals_sweep_then_product(disc, k):
    """multirhs.forward_gauss_seidel_residual: one pass over the lower triangle gives the forward
    sweep from X = 0 and R = B − A X (A symmetric), as the sweep and a product do in two passes;
    and the block-diagonal inverses read from the diagonals equal pyamg's from the BSR form."""
    from pyamg.util.utils import get_block_diag

    sy, _ = disc
    A = sy.A.tocsr()
    A.sort_indices()
    Dinv = np.ascontiguousarray(get_block_diag(A.tobsr(blocksize=(3, 3)), blocksize=3, inv_flag=True))
    assert np.abs(fsolve.block_diagonal_inverse(A) - Dinv).max() <= 1e-12 * np.abs(Dinv).max()
    B = np.random.default_rng(k).standard_normal((A.shape[0], k))
    X, R = multirhs.forward_gauss_seidel_residual(A, Dinv, B)
    X_ref = np.zeros_like(B)
    multirhs.block_gauss_seidel(A, Dinv, X_ref, B, True)
    assert np.abs(X - X_ref).max() <= 1e-12 * np.abs(X_ref).max()
    R_ref = B - A @ X_ref
    assert np.abs(R - R_ref).max() <= 1e-9 * np.abs(B).max()


@pytest.mark.parametrize("k", [1, 5, 8])
def test_block_storage_sweeps_equal_the_csr_sweeps(disc, k):
    """multirhs' sweeps on 3 × 3 block storage (flexure.block_sparse, fsolve.SMOOTHER_STORAGE): float64
    blocks give the CSR sweeps to round-off; float32 blocks to their rounding (~1e-7)."""
    from flexure.block_sparse import BlockMatrix

    sy, _ = disc
    A = sy.A.tocsr()
    A.sort_indices()
    Dinv = np.ascontiguousarray(fsolve.block_diagonal_inverse(A))
    B = np.random.default_rng(k).standard_normal((A.shape[0], k))
    X, R = multirhs.forward_gauss_seidel_residual(A, Dinv, B)
    multirhs.block_gauss_seidel(A, Dinv, X, B, False)
    for dtype, tol in ((np.float64, 1e-12), (np.float32, 1e-5)):
        Ab = BlockMatrix.from_csr(A, dtype)
        assert Ab.data.dtype == dtype
        Xb, Rb = multirhs.forward_gauss_seidel_residual_bsr(Ab, Dinv, B)
        assert np.abs(Rb - R).max() <= tol * np.abs(R).max()
        multirhs.block_gauss_seidel_bsr(Ab, Dinv, Xb, B, False)
        assert np.abs(Xb - X).max() <= tol * np.abs(X).max()
    assert np.abs(Xb - X).max() > 0.0                                  # float32: not the same bits


def test_p2_solve_same_iterations_with_the_block_smoother(disc, monkeypatch):
    """The float32 block smoother changes the preconditioner by its rounding only: the same CG
    iterations per case (± 1) and the same answers to the CG tolerance as the CSR smoother."""
    sy, B = disc
    monkeypatch.setattr(fsolve, "SPLIT_SWEEPS", False)       # the same order of rows on both sides
    out = {}
    for storage in ("csr", "block32"):
        monkeypatch.setattr(fsolve, "SMOOTHER_STORAGE", storage)
        out[storage] = fsolve.solve_system(sy.A, B, sy.B, "amg", 1e-10, coarse=sy.coarse, B_coarse=sy.B_coarse)
    (q0, i0), (q1, i1) = out["csr"], out["block32"]
    assert all(abs(a - b) <= 1 for a, b in zip(i1["iterations"], i0["iterations"]))
    assert np.abs(q1 - q0).max() <= 1e-8 * np.abs(q0).max()
    assert i1["residual_norm"] < 1e-10


def test_the_aggregation_hierarchy_does_not_depend_on_the_global_random_state(disc):
    """pyamg's spectral-radius estimate starts from np.random.rand: the set-up seeds it, so two set-ups
    after different global states give the same prolongators bit for bit, and the caller's state is
    given back untouched."""
    sy, _ = disc
    A1 = (sy.coarse.T @ sy.A @ sy.coarse).tocsr()
    Ps = []
    for seed in (1, 2):
        np.random.seed(seed)
        ml = fsolve._sa_hierarchy(A1, sy.B_coarse, smoothed=True, max_coarse=10)
        after = np.random.rand()
        np.random.seed(seed)
        assert after == np.random.rand()                 # the global generator given back as it was
        Ps.append([lv.P.toarray() for lv in ml.levels[:-1]])
    assert all(np.array_equal(a, b) for a, b in zip(*Ps))
