"""A = Tᵀ K T by flexure.reduce's row loop equals scipy's products (bc.REDUCE_COMPILED False, the
reference): the matrix to round-off, and b, B, the fixed dofs and the coarse interpolation exactly."""

import numpy as np
import pytest
import scipy.sparse as sp

from flexure import bc
from flexure.bc import Problem
from flexure.fem import stiffness_matrix
from flexure.material import ALUMINIUM_6061_T6 as MAT
from flexure.mesh import cylinder_mesh

pytest.importorskip("numba")


def _problem(cells, two_couplings: bool, prescribed: bool):
    m = cylinder_mesh(0.004, 0.03, 0.006, *cells, order=2)
    r = np.hypot(m.points[:, 0], m.points[:, 1])
    p = Problem(m, MAT).fix(np.flatnonzero(r > 0.03 * (1 - 1e-9)), value_m=(1e-6, 0, -2e-6) if prescribed else 0.0)
    bore = np.flatnonzero(r < 0.004 * (1 + 1e-9))
    if two_couplings:       # the bore split in two halves, each its own rigid coupling
        up = m.points[bore, 1] >= 0
        p.couple_rigid(bore[up], (0, 0.001, 0.003), force_N=(1, 2, 3), moment_Nm=(0, 0, 1))
        p.couple_rigid(bore[~up], (0, -0.001, 0.003), moment_Nm=(0.5, 0, 0))
    else:
        p.couple_rigid(bore, (0, 0, 0.003), moment_Nm=(0, 0, 1))
    return p, stiffness_matrix(m, MAT)


def _both(p, K, monkeypatch):
    monkeypatch.setattr(bc, "REDUCE_COMPILED", False)
    old = p.reduced_system(K)
    monkeypatch.setattr(bc, "REDUCE_COMPILED", True)
    return old, p.reduced_system(K)


@pytest.mark.parametrize("cells,two,prescribed", [((3, 24, 2), False, False), ((3, 24, 2), True, True),
                                                   ((5, 40, 4), True, False)])
def test_reduced_system_equals_the_scipy_products(cells, two, prescribed, monkeypatch):
    p, K = _problem(cells, two, prescribed)
    old, new = _both(p, K, monkeypatch)
    assert new.A.shape == old.A.shape and new.A.has_sorted_indices
    scale = abs(old.A).max()
    assert abs(new.A - old.A).max() <= 1e-13 * scale
    assert abs(new.A - new.A.T).max() <= 1e-13 * scale                # symmetric as Tᵀ K T
    assert np.allclose(new.b, old.b, rtol=1e-12, atol=1e-12 * np.abs(old.b).max())
    assert np.array_equal(new.fixed_q, old.fixed_q) and np.array_equal(new.B, old.B)
    assert abs(new.coarse - old.coarse).max() == 0 and np.array_equal(new.B_coarse, old.B_coarse)
    assert new.ref_slices == old.ref_slices
    # the same solution (direct) to round-off
    q_old = sp.linalg.spsolve(old.A.tocsc(), old.b)
    q_new = sp.linalg.spsolve(new.A.tocsc(), new.b)
    assert np.allclose(q_new, q_old, rtol=1e-9, atol=1e-12 * np.abs(q_old).max())


def test_unsorted_stiffness_is_accepted(monkeypatch):
    p, K = _problem((3, 24, 2), False, False)
    rng = np.random.default_rng(0)
    Ku = K.tocsr(copy=True)
    for i in range(0, Ku.shape[0], 7):                    # shuffle some rows' entries
        a, b = Ku.indptr[i], Ku.indptr[i + 1]
        perm = a + rng.permutation(b - a)
        Ku.indices[a:b], Ku.data[a:b] = Ku.indices[perm], Ku.data[perm]
    Ku.has_sorted_indices = False
    old, new = _both(p, K, monkeypatch)
    _, new_u = _both(p, Ku, monkeypatch)
    assert abs(new_u.A - old.A).max() <= 1e-13 * abs(old.A).max()
    S = new_u.A.copy()
    S.has_sorted_indices = False
    S.sort_indices()                                      # the flag is true: sorting changes nothing
    assert new_u.A.has_sorted_indices and np.array_equal(S.indices, new_u.A.indices)


def test_same_bits_for_one_and_two_threads(monkeypatch):
    from flexure import threads

    p, K = _problem((3, 24, 2), True, False)
    with threads.limited(1):
        a = p.reduced_system(K).A
    with threads.limited(2):
        b = p.reduced_system(K).A
    assert np.array_equal(a.indptr, b.indptr) and np.array_equal(a.indices, b.indices)
    assert np.array_equal(a.data, b.data)


def test_block_diagonal_inverse_compiled_equals_the_diagonals(monkeypatch):
    from flexure import solve as fsolve

    p, K = _problem((3, 24, 2), True, True)
    A = p.reduced_system(K).A
    A = A[:A.shape[0] - A.shape[0] % 3][:, :A.shape[0] - A.shape[0] % 3]
    monkeypatch.setattr(fsolve, "BLOCKS_COMPILED", False)
    ref = fsolve.block_diagonal_inverse(A)
    monkeypatch.setattr(fsolve, "BLOCKS_COMPILED", True)
    new = fsolve.block_diagonal_inverse(A)
    assert np.array_equal(new, ref)
