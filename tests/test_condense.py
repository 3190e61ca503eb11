"""flexure.condense: Tᵀ K T of the kinematic couplings built in one pass, against the sparse product."""

import numpy as np
import pytest

from flexure.bc import Problem
from flexure.fem import stiffness_matrix
from flexure.material import Material
from flexure.mesh import box_mesh, to_quadratic

pytest.importorskip("numba")


def _problem(n_couplings: int):
    mesh = to_quadratic(box_mesh(4, 3, 3))
    mat = Material(70e9, 0.33, 270e6, "test")
    x = mesh.points
    pr = Problem(mesh, mat).fix(np.flatnonzero(np.isclose(x[:, 0], x[:, 0].min())))
    right = np.flatnonzero(np.isclose(x[:, 0], x[:, 0].max()))
    if n_couplings == 1:
        pr.couple_rigid(right, x[right].mean(axis=0) + [0.01, 0.0, 0.0], kind="kinematic")
    else:                        # two couplings: the right face split at mid height, and the top face's interior
        lo, hi = right[x[right, 2] < x[:, 2].mean()], right[x[right, 2] >= x[:, 2].mean()]
        pr.couple_rigid(lo, x[lo].mean(axis=0), kind="kinematic")
        pr.couple_rigid(hi, x[hi].mean(axis=0), moment_Nm=(0, 0, 1), kind="kinematic")
    return mesh, mat, pr


@pytest.mark.parametrize("n_couplings", [1, 2])
def test_tkt_equals_the_sparse_product(n_couplings):
    from flexure.condense import tkt

    mesh, mat, pr = _problem(n_couplings)
    K = stiffness_matrix(mesh, mat)
    T = pr.reduced_system(K).T
    n_free = T.shape[1] - 6 * n_couplings
    A = tkt(K, T, n_free)
    ref = (T.T @ K @ T).toarray()
    starts = np.zeros(A.nnz, bool)
    starts[A.indptr[:-1][np.diff(A.indptr) > 0]] = True
    assert A.has_sorted_indices and np.all((np.diff(A.indices) > 0) | starts[1:])     # each row strictly increasing
    assert np.abs(A.toarray() - ref).max() <= 1e-13 * np.abs(ref).max()


def test_reduced_system_solves_as_before():
    """The rigid coupling's rotation under a unit moment, by the compiled condensation and by the product."""
    import flexure.bc as bc
    from flexure import stiffness_assembly
    from scipy.sparse.linalg import spsolve

    mesh, mat, pr = _problem(2)
    K = stiffness_matrix(mesh, mat)
    S = pr.reduced_system(K)
    saved = stiffness_assembly.available
    try:
        stiffness_assembly.available = lambda: False
        S0 = pr.reduced_system(K)
    finally:
        stiffness_assembly.available = saved
    q, q0 = spsolve(S.A.tocsc(), S.b), spsolve(S0.A.tocsc(), S0.b)
    assert np.abs(q - q0).max() <= 1e-9 * np.abs(q0).max()
    assert abs(q[S.ref_slices[1]][5]) > 0
