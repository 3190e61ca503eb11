"""The FEM's parallel kernels (flexure.threads) give the same results with 1 and 2 threads: the
colour-by-colour enriched assembly (equal bits: every entry sums its elements in the colour order),
the element colouring itself (no two elements of a colour share a vertex), the block pattern, and
the CSR products of flexure.sparse_parallel (A x equal bits; Aᵀ x to round-off) against scipy.
Small meshes; no timings (benchmarks/bench_fem_parallel.py)."""

import numpy as np
import pytest

from flexure import enriched, enriched_assembly, sparse_parallel, threads
from flexure.material import Material
from flexure.mesh import box_mesh, to_linear, to_quadratic

pytestmark = pytest.mark.skipif(not enriched_assembly.available(), reason="numba not installed")

AL = Material(70e9, 0.33, 270e6, "aluminium")


def _curved_box(seed=5):
    rng = np.random.default_rng(seed)
    m = to_quadratic(to_linear(to_quadratic(box_mesh(3, 3, 4, size=(1.0, 0.8, 1.3)))))
    m.points[:] += rng.normal(size=m.points.shape) * 0.02
    x = m.points
    u = np.column_stack([np.sin(2 * x[:, 0]) * x[:, 2], np.cos(x[:, 1] * x[:, 0]), x[:, 2] ** 3 - x[:, 1]]) * 1e-3
    return m, u


def test_colouring_separates_elements_sharing_a_vertex():
    from flexure import _enriched_kernels as ek

    mesh, _ = _curved_box()
    V = np.ascontiguousarray(mesh.tets[:, :4], dtype=np.int64)
    cptr, order = ek.colour_elements(V, mesh.n_nodes)
    assert np.array_equal(np.sort(order), np.arange(mesh.n_elements))
    assert len(cptr) > 2 and cptr[-1] == mesh.n_elements
    for c in range(len(cptr) - 1):
        verts = V[order[cptr[c]:cptr[c + 1]]].ravel()
        assert len(np.unique(verts)) == len(verts), f"colour {c} has elements sharing a vertex"


def test_block_pattern_does_not_depend_on_the_chunks():
    from flexure import _enriched_kernels as ek

    mesh, _ = _curved_box()
    G, sign, free = enriched.surplus_numbering(mesh, np.zeros(mesh.n_nodes, bool))
    tets = np.ascontiguousarray(mesh.tets, dtype=np.int64)
    nk = len(free)
    ref = ek.block_pattern(tets, G.astype(np.int64), mesh.n_nodes, nk, 1)
    for nchunk in (2, 3, 7):
        got = ek.block_pattern(tets, G.astype(np.int64), mesh.n_nodes, nk, nchunk)
        assert all(np.array_equal(a, b) for a, b in zip(ref, got))


@pytest.mark.parametrize("constrain", [False, True])
def test_enriched_assembly_same_with_one_and_two_threads(constrain):
    mesh, u = _curved_box()
    cons = np.zeros(mesh.n_nodes, bool)
    if constrain:
        cons[mesh.points[:, 2] < 0.1] = True
    num = enriched.surplus_numbering(mesh, cons)
    out = {}
    for n in (1, 2):
        with threads.limited(n):
            out[n] = enriched_assembly.assemble_enriched(mesh, AL, u, num)
    (K1, r1, C1, D1, _), (K2, r2, C2, D2, _) = out[1], out[2]
    for a, b in ((K1, K2), (C1, C2)):
        assert np.array_equal(a.indptr, b.indptr) and np.array_equal(a.indices, b.indices)
        assert np.abs(a.data - b.data).max() <= 1e-12 * np.abs(a.data).max()
    assert np.abs(r1 - r2).max() <= 1e-12 * np.abs(r1).max()
    assert np.abs(D1 - D2).max() <= 1e-12 * np.abs(D1).max()
    # and the numpy form (the reference) agrees with the parallel one
    K0, r0, _ = enriched.assemble(mesh, AL, u, cons)
    keep = np.repeat(num[2], 3)
    assert abs(K0[keep][:, keep] - K2).max() <= 1e-12 * abs(K0).max()


def test_sparse_products_match_scipy_with_one_and_two_threads():
    import scipy.sparse as sp

    rng = np.random.default_rng(3)
    A = sp.random(3001, 1777, density=0.01, format="csr", random_state=rng)
    A.indices = A.indices.astype(np.int32)
    A.indptr = A.indptr.astype(np.int32)
    x, y = rng.normal(size=1777), rng.normal(size=3001)
    out = []
    for n in (1, 2):
        with threads.limited(n):
            assert np.abs(sparse_parallel.matvec(A, x) - A @ x).max() <= 1e-12 * np.abs(A @ x).max()
            ref = A.T @ y
            out.append(sparse_parallel.rmatvec(A, y))
            assert np.abs(out[-1] - ref).max() <= 1e-12 * np.abs(ref).max()
    assert np.array_equal(out[0], out[1])               # the same partial sums whatever the threads


def test_threads_setting_is_within_numbas_pool():
    import numba

    assert 1 <= threads.count() <= numba.config.NUMBA_NUM_THREADS
    with threads.limited(1):
        assert threads.count() == 1 and numba.get_num_threads() == 1


@pytest.mark.parametrize("order", [1, 2])
def test_compiled_stiffness_equals_numpy_with_one_and_two_threads(order):
    from flexure import fem

    mesh, _ = _curved_box()
    if order == 1:
        mesh = to_linear(mesh)
    K0 = fem._stiffness_numpy(mesh, AL)
    out = {}
    for n in (1, 2):
        with threads.limited(n):
            out[n] = fem.stiffness_matrix(mesh, AL)
    for K in out.values():
        assert np.array_equal(K.indptr, K0.indptr) and np.array_equal(K.indices, K0.indices)
        assert np.abs(K.data - K0.data).max() <= 1e-12 * np.abs(K0.data).max()
    assert np.abs(out[1].data - out[2].data).max() <= 1e-12 * np.abs(K0.data).max()


def test_compiled_jacobians_and_gradients_equal_the_numpy_forms(monkeypatch):
    from estimator import compiled
    from flexure import bank_weiser, fem

    mesh, _ = _curved_box()
    X = mesh.points[mesh.tets]
    xi, _ = fem.TET_QUAD[2]
    dN = fem.tet_shape(2, xi)[1]
    got = {}
    for n in (1, 2):
        with threads.limited(n):
            got[n] = (fem.physical_gradients(X, dN), bank_weiser.point_jacobians(X, dN))
    monkeypatch.setattr(compiled, "ENABLED", False)
    (G0, d0), (dj0, Ji0) = fem.physical_gradients(X, dN), bank_weiser.point_jacobians(X, dN)
    for (G, d), (dj, Ji) in got.values():
        assert np.abs(G - G0).max() <= 1e-12 * np.abs(G0).max()
        assert np.abs(d - d0).max() <= 1e-12 * np.abs(d0).max()
        assert np.abs(dj - dj0).max() <= 1e-12 * np.abs(dj0).max()
        assert np.abs(Ji - Ji0).max() <= 1e-12 * np.abs(Ji0).max()
    assert np.array_equal(got[1][0][0], got[2][0][0])                # each element on its own: same bits


def _parallel_product(_=None):
    import scipy.sparse as sp

    A = (sp.identity(3000, format="csr") * 2.0).tocsr()
    A.indices, A.indptr = A.indices.astype(np.int32), A.indptr.astype(np.int32)
    with threads.limited(2):
        return float(sparse_parallel.matvec(A, np.ones(3000)).sum())


def test_a_process_forked_after_a_parallel_kernel_can_run_them():
    """torquebench.sweep forks its workers after the first point ran in the parent: the threading
    layer (flexure.threads.select_layer) must survive that (GNU OpenMP's kills the child)."""
    import multiprocessing as mp

    assert _parallel_product() == 6000.0
    with mp.get_context("fork").Pool(1) as pool:
        assert pool.map(_parallel_product, [0], chunksize=1) == [6000.0]


def _helper_runs(_):
    return threads.helper().submit(lambda: 7).result(timeout=20)


def test_the_helper_thread_runs_in_a_process_forked_after_it_started():
    """flexure.threads.helper (the split smoother's second part): a forked child (torquebench.sweep)
    gets a helper of its own, not its parent's thread, absent there."""
    import multiprocessing as mp

    assert _helper_runs(0) == 7
    with mp.get_context("fork").Pool(1) as pool:
        assert pool.map(_helper_runs, [0], chunksize=1) == [7]
