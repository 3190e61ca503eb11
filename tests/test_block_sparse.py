"""flexure.block_sparse and the enriched solve's block storage (flexure.enriched STORAGE) against the
scalar CSR path it replaces: the same K_WW, K_hW (float64 blocks to round-off, float32 blocks to the
float32 rounding), the same products as scipy's, and the same J(u⁺) − J(u_h) on a small case."""

import numpy as np
import pytest

from flexure import enriched, enriched_assembly
from flexure.material import Material

pytestmark = pytest.mark.skipif(not enriched_assembly.available(), reason="numba not installed")

AL = Material(70e9, 0.33, 270e6, "aluminium")


@pytest.mark.parametrize("dtype", [np.float64, np.float32])
def test_block_assembly_equals_the_csr_assembly_and_products_match_scipy(dtype):
    from test_enriched_speed import _curved_box

    mesh, u = _curved_box()
    cons = np.zeros(mesh.n_nodes, bool)
    cons[mesh.points[:, 2] < 0.1] = True
    num = enriched.surplus_numbering(mesh, cons)
    K0, r0, C0, D0, _ = enriched_assembly.assemble_enriched(mesh, AL, u, num)
    K1, r1, C1, D1, _ = enriched_assembly.assemble_enriched_blocks(mesh, AL, u, num, dtype)
    assert K1.data.dtype == dtype and K1.bcol.dtype == np.int32
    tol = 0.0 if dtype == np.float64 else 2e-6   # float64: the CSR's additions in its order; float32: 6e-8 an addition
    for M0, M1 in ((K0, K1), (C0, C1)):
        assert M1.shape == M0.shape
        assert abs(M1.tocsr() - M0).max() <= tol * abs(M0).max()
        assert M1.nbytes < (0.75 if dtype == np.float64 else 0.4) * (M0.data.nbytes + M0.indices.nbytes)
    assert np.array_equal(r1, r0) and np.array_equal(D1, D0)
    rng = np.random.default_rng(1)
    x, y = rng.normal(size=K1.shape[1]), rng.normal(size=C1.shape[0])
    Kd, Cd = K1.tocsr(), C1.tocsr()                        # the stored values, products in float64
    assert np.allclose(K1.matvec(x), Kd @ x, rtol=1e-12, atol=1e-12 * np.abs(Kd @ x).max())
    assert np.allclose(C1.matvec(x), Cd @ x, rtol=1e-12, atol=1e-12 * np.abs(Cd @ x).max())
    assert np.allclose(C1.rmatvec(y), Cd.T @ y, rtol=1e-12, atol=1e-12 * np.abs(Cd.T @ y).max())


def test_block_products_the_same_with_one_and_two_threads():
    from flexure import threads
    from test_enriched_speed import _curved_box

    mesh, u = _curved_box()
    num = enriched.surplus_numbering(mesh, np.zeros(mesh.n_nodes, bool))
    K, _, C, _, _ = enriched_assembly.assemble_enriched_blocks(mesh, AL, u, num)
    rng = np.random.default_rng(2)
    x, y = rng.normal(size=K.shape[1]), rng.normal(size=C.shape[0])
    out = {}
    for n in (1, 2):
        with threads.limited(n):
            out[n] = (K.matvec(x), C.rmatvec(y))
    assert np.array_equal(out[1][0], out[2][0])
    assert np.array_equal(out[1][1], out[2][1])        # Aᵀ y: threads.REDUCTION_CHUNKS partial sums on any count
    xw = rng.normal(size=C.shape[1])
    for n in (1, 2):                          # C x and Cᵀ y in one pass: the bits of the two apart
        with threads.limited(n):
            both = C.matvec_rmatvec(xw, y)
            assert np.array_equal(both[0], C.matvec(xw)) and np.array_equal(both[1], C.rmatvec(y))


@pytest.mark.parametrize("rtol, rel", [(1e-12, 1e-5), (enriched.RTOL, 2e-2)])
def test_enriched_solve_same_estimate_with_every_storage(rtol, rel):
    """The rigidly coupled bar of tests/test_enriched.py: θ⁺ − θ_h and the gauge's J(u⁺) − J(u_h)
    from float64 blocks equal the CSR path's to the CG's round-off; from float32 blocks within the
    float32 rounding of the operator (converged CG) or well inside the estimate's accuracy (the
    adaptive run's RTOL)."""
    from test_enriched import _bar_unit_rotation

    mesh, pr, sy, lu, g, cons, i_th, q, U = _bar_unit_rotation()
    out = {}
    for st in ("csr", "block64", "block32"):
        d_eps, d_th, info = enriched.enriched_solve(sy, mesh, AL, [g], U, q, cons, lambda R: lu.solve(R),
                                                    rtol=rtol, theta_index=i_th, storage=st, w_precond="jacobi")
        out[st] = (d_eps[0], d_th, info)
    assert out["csr"][1] > 0
    for k in (0, 1):
        assert out["block64"][k] == pytest.approx(out["csr"][k], rel=1e-9)
        assert out["block32"][k] == pytest.approx(out["csr"][k], rel=rel)
    assert out["block32"][2]["matrix_bytes"] < 0.4 * out["csr"][2]["matrix_bytes"]


def test_symmetric_gauss_seidel_is_the_sweep_pair_and_symmetric():
    """The multicolour symmetric block Gauss–Seidel: z = (D + U)⁻¹ D (D + L)⁻¹ r in the colour order
    (scipy's triangular solves of the permuted matrix as the reference), M⁻¹ symmetric (the CG needs
    an SPD preconditioner), no two rows of a colour sharing a block, the same bits on 1 and 2 threads."""
    import scipy.sparse as sp
    import scipy.sparse.linalg as spla

    from flexure import threads
    from test_enriched_speed import _curved_box

    mesh, u = _curved_box()
    num = enriched.surplus_numbering(mesh, np.zeros(mesh.n_nodes, bool))
    K, _, _, Dinv, _ = enriched_assembly.assemble_enriched_blocks(mesh, AL, u, num, np.float64)
    cptr, order = K.colouring()
    assert len(cptr) > 2 and np.array_equal(np.sort(order), np.arange(len(order)))
    col = np.empty(len(order), np.int64)
    for c in range(len(cptr) - 1):
        col[order[cptr[c]:cptr[c + 1]]] = c
    rows = np.repeat(np.arange(len(K.bptr) - 1), np.diff(K.bptr))
    assert np.all((col[rows] != col[K.bcol]) | (rows == K.bcol))
    perm = (3 * order[:, None] + np.arange(3)).ravel()
    Kp = K.tocsr()[perm][:, perm]
    nb = len(order)
    Dp = sp.block_diag([Kp[3 * k:3 * k + 3, 3 * k:3 * k + 3].toarray() for k in range(nb)]).tocsr()
    lower = (sp.tril(Kp, -1) - sp.tril(Dp, -1)) + Dp
    upper = (sp.triu(Kp, 1) - sp.triu(Dp, 1)) + Dp
    rng = np.random.default_rng(3)
    r = rng.normal(size=K.shape[0])
    y = spla.spsolve(lower.tocsc(), r[perm])                # block triangular: a sparse LU solve
    ref = np.empty_like(r)
    ref[perm] = spla.spsolve(upper.tocsc(), Dp @ y)
    out = {}
    for n in (1, 2):
        with threads.limited(n):
            out[n] = K.symmetric_gauss_seidel(Dinv, r)
    assert np.array_equal(out[1], out[2])
    assert np.allclose(out[1], ref, rtol=1e-9, atol=1e-9 * np.abs(ref).max())
    s = rng.normal(size=K.shape[0])
    a, b = s @ K.symmetric_gauss_seidel(Dinv, r), r @ K.symmetric_gauss_seidel(Dinv, s)
    assert a == pytest.approx(b, rel=1e-10)
    assert r @ out[1] > 0


def test_enriched_solve_with_sgs_same_estimate():
    """The bar of tests/test_enriched.py: the W block's symmetric Gauss–Seidel changes the CG's path,
    not its limit: converged θ⁺ − θ_h and gauge estimate equal the block-Jacobi ones, in no more
    iterations."""
    from test_enriched import _bar_unit_rotation

    mesh, pr, sy, lu, g, cons, i_th, q, U = _bar_unit_rotation()
    out = {}
    for wp in ("jacobi", "sgs"):
        out[wp] = enriched.enriched_solve(sy, mesh, AL, [g], U, q, cons, lambda R: lu.solve(R), rtol=1e-12,
                                          theta_index=i_th, storage="block64", w_precond=wp)
    assert out["sgs"][0][0] == pytest.approx(out["jacobi"][0][0], rel=1e-8)
    assert out["sgs"][1] == pytest.approx(out["jacobi"][1], rel=1e-8)
    assert out["sgs"][2]["pcg_iterations"] <= out["jacobi"][2]["pcg_iterations"]


def test_blocks_from_a_csr_hold_its_entries():
    """BlockMatrix.from_csr: unsorted indices, blocks stored in part, an entry stored twice (summed)
    → the same matrix (float64) and products; float32 to its rounding."""
    import scipy.sparse as sp

    from flexure.block_sparse import BlockMatrix

    M = sp.random(12, 12, density=0.3, random_state=7, format="csr")
    M = (M + M.T).tocsr()
    ind, dat, ptr = [], [], [0]
    for r in range(12):                                               # each row reversed; row 4 a duplicate
        cols, vals = M.indices[M.indptr[r]:M.indptr[r + 1]][::-1], M.data[M.indptr[r]:M.indptr[r + 1]][::-1]
        if r == 4:
            cols, vals = np.r_[cols, 7], np.r_[vals, 1.5]
        ind += list(cols)
        dat += list(vals)
        ptr.append(len(ind))
    U = sp.csr_matrix((np.array(dat), np.array(ind, np.int32), np.array(ptr, np.int32)), shape=(12, 12))
    ref = sp.csr_matrix(U.toarray())                                  # the duplicate summed
    Ab = BlockMatrix.from_csr(U, np.float64)
    for r in range(4):
        assert np.all(np.diff(Ab.bcol[Ab.bptr[r]:Ab.bptr[r + 1]]) > 0)
    assert abs(Ab.tocsr() - ref).max() == 0.0
    x = np.random.default_rng(5).standard_normal(12)
    assert np.allclose(Ab.matvec(x), ref @ x, rtol=1e-14, atol=1e-14)
    A32 = BlockMatrix.from_csr(U, np.float32)
    assert A32.data.dtype == np.float32 and abs(A32.tocsr() - ref).max() <= 1e-7 * abs(ref).max()


def test_blocks_from_a_csr_the_same_in_any_chunks():
    """csr_to_blocks' block rows in parallel ranges: the same pattern and values as in one range."""
    from test_enriched_speed import _curved_box

    from flexure import _block_kernels as bk
    from flexure import fem

    mesh, _ = _curved_box()
    K = fem.stiffness_matrix(mesh, AL)
    one = bk.csr_to_blocks(K.indptr, K.indices, K.data, K.shape[0] // 3, K.shape[1] // 3, np.zeros(1, np.float32), 1)
    for n in (3, 16):
        got = bk.csr_to_blocks(K.indptr, K.indices, K.data, K.shape[0] // 3, K.shape[1] // 3, np.zeros(1, np.float32), n)
        assert all(np.array_equal(a, b) for a, b in zip(one, got))
