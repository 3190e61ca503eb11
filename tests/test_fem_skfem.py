"""Cross-check against scikit-fem (independent implementation) on the same P2 mesh."""

import numpy as np
import pytest

from flexure.bc import Problem
from flexure.fem import stiffness_matrix
from flexure.material import Material
from flexure.mesh import cylinder_mesh, to_quadratic
from flexure.post import strain_at
from flexure.solve import solve

skfem = pytest.importorskip("skfem")
MAT = Material(68.9e9, 0.33, 276e6, "6061")


def skfem_p2(mesh1):
    """scikit-fem P2 vector basis on our P1 mesh and the permutation our dof → skfem dof."""
    sm = skfem.MeshTet(mesh1.points.T.copy(), mesh1.tets.T.astype(np.int64).copy())
    basis = skfem.Basis(sm, skfem.ElementVector(skfem.ElementTetP2()))
    ours = to_quadratic(mesh1)
    nv = mesh1.n_nodes
    perm = np.empty(ours.n_dofs, dtype=np.int64)
    v = np.arange(nv)
    for c in range(3):
        perm[3 * v + c] = basis.nodal_dofs[c]
    # our mid node of tet edge (a,b) ↔ skfem edge with the same vertex pair
    sk_code = np.sort(sm.edges, axis=0)
    sk_code = sk_code[0] * nv + sk_code[1]
    order = np.argsort(sk_code)
    ed = ours.tets[:, 4:].ravel()
    a = ours.tets[:, [0, 1, 0, 0, 1, 2]].ravel()
    b = ours.tets[:, [1, 2, 2, 3, 3, 3]].ravel()
    code = np.minimum(a, b).astype(np.int64) * nv + np.maximum(a, b)
    sk_edge = order[np.searchsorted(sk_code, code, sorter=order)]
    for c in range(3):
        perm[3 * ed + c] = basis.edge_dofs[c][sk_edge]
    return basis, ours, perm


def test_stiffness_and_displacements_match_scikit_fem():
    from skfem.models.elasticity import lame_parameters, linear_elasticity

    m1 = cylinder_mesh(0.004, 0.012, 0.02, 2, 16, 4)
    basis, m2, perm = skfem_p2(m1)
    K_sk = linear_elasticity(*lame_parameters(MAT.E_Pa, MAT.nu)).assemble(basis)
    K = stiffness_matrix(m2, MAT)
    Kp = K_sk[perm][:, perm]
    assert abs(K - Kp).max() <= 1e-8 * abs(Kp).max()
    # same load and constraints in both: fixed bottom, tangential nodal forces on the top edge
    p = Problem(m2, MAT).fix(m2.select_nodes(lambda x: x[:, 2] < 1e-12))
    top = m2.select_nodes(lambda x: (x[:, 2] > 0.02 - 1e-12) & (np.hypot(x[:, 0], x[:, 1]) > 0.012 - 1e-9))
    x = m2.points[top]
    p.add_nodal_force(top, np.stack([-x[:, 1], x[:, 0], 0 * x[:, 0]], axis=1) * 100.0)
    s = solve(p, method="direct")
    f_sk = np.zeros(K.shape[0])
    f_sk[perm] = p.load_vector()
    fixed_sk = perm[np.flatnonzero(p.fixed.ravel())]
    u_sk = skfem.solve(*skfem.condense(K_sk, f_sk, D=fixed_sk))
    u_ours_in_sk = np.zeros_like(u_sk)
    u_ours_in_sk[perm] = s.u.ravel()
    assert np.abs(u_ours_in_sk - u_sk).max() <= 1e-8 * np.abs(u_sk).max()
    # strains at gauge-like points: skfem's own gradient evaluation at the same points
    ang = np.array([0.3, 1.9, 4.0])
    pts = np.stack([0.0115 * np.cos(ang), 0.0115 * np.sin(ang), np.full(3, 0.0112)], axis=1)   # off element faces
    eps_ours = strain_at(m2, s.u, pts)
    sm = basis.mesh
    elems = sm.element_finder()(*pts.T)
    for k in range(len(pts)):
        X = sm.mapping().invF(pts[k][:, None, None], tind=np.array([elems[k]]))[:, 0, :]
        cb = skfem.CellBasis(sm, basis.elem, elements=np.array([elems[k]]), quadrature=(X, np.ones(1)))
        H = cb.interpolate(u_sk).grad[:, :, 0, 0]
        eps_sk = 0.5 * (H + H.T)
        assert np.abs(eps_ours[k] - eps_sk).max() <= 1e-8 * np.abs(eps_sk).max()
