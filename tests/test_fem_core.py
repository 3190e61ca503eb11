"""FEM core: mesh utilities, assembly invariants, patch tests, boundary conditions, errors."""

import numpy as np
import pytest

from flexure.bc import Problem, face_set_properties, traction_load
from userio.errors import InputError
from flexure.fem import element_stiffness, rigid_body_modes, stiffness_matrix
from flexure.material import ALUMINIUM_6061_T6, Material
from flexure.mesh import Mesh, box_mesh, cylinder_mesh, quality, to_linear, to_quadratic, unique_edges
from flexure.post import (displacement_at, element_nodal_strains, element_strains, max_shear_strain, nodal_strains,
                          strain_at, von_mises)
from flexure.solve import solve

MAT = Material(70e9, 0.3, 250e6, "test")


def distorted_box(n=3, seed=0):
    """Unit box mesh with interior vertices moved randomly (irregular, still valid)."""
    m = box_mesh(n, n, n)
    rng = np.random.default_rng(seed)
    inner = np.all((m.points > 1e-9) & (m.points < 1 - 1e-9), axis=1)
    pts = m.points.copy()
    pts[inner] += rng.uniform(-0.25, 0.25, (inner.sum(), 3)) / n
    return Mesh(pts, m.tets)


def test_to_quadratic_dedups_edges_and_orders_like_vtk():
    m1 = box_mesh(2, 2, 2)
    m2 = to_quadratic(m1)
    edges, _ = unique_edges(m1.tets, m1.n_nodes)
    assert m2.n_nodes == m1.n_nodes + len(edges)
    # every mid node is the midpoint of its VTK edge (0,1),(1,2),(0,2),(0,3),(1,3),(2,3)
    pairs = [(0, 1), (1, 2), (0, 2), (0, 3), (1, 3), (2, 3)]
    for k, (a, b) in enumerate(pairs):
        mid = 0.5 * (m2.points[m2.tets[:, a]] + m2.points[m2.tets[:, b]])
        np.testing.assert_allclose(m2.points[m2.tets[:, 4 + k]], mid, atol=1e-15)
    assert np.array_equal(to_linear(m2).tets, m1.tets)


def test_quality_regular_tet_and_boundary_orientation():
    reg = Mesh(np.array([[1, 1, 1], [1, -1, -1], [-1, 1, -1], [-1, -1, 1.0]]), np.array([[0, 1, 2, 3]]))
    if reg.signed_volumes()[0] < 0:
        reg = Mesh(reg.points, np.array([[0, 2, 1, 3]]))
    q = quality(reg)
    assert q["min_dihedral_deg"] == pytest.approx(np.degrees(np.arccos(1 / 3)), rel=1e-12)
    assert q["max_aspect_ratio"] == pytest.approx(1.0, rel=1e-12)
    # divergence theorem on the outward boundary: ∮ x·n dA = 3 V, ∮ n dA = 0
    for m in (distorted_box(), to_quadratic(cylinder_mesh(0.5, 1.0, 2.0, 2, 12, 3))):
        f = traction_load(m, m.boundary_faces(), lambda x: x)          # ∫ N_a x dA
        from flexure.bc import face_quadrature
        _, x, nda = face_quadrature(m, m.boundary_faces())
        assert np.einsum("kqi,kqi->", x, nda) == pytest.approx(3 * m.signed_volumes().sum(), rel=1e-9)
        np.testing.assert_allclose(nda.sum(axis=(0, 1)), 0, atol=1e-12)
        assert np.isfinite(f).all()


@pytest.mark.parametrize("order", [1, 2])
def test_stiffness_symmetric_psd_with_rigid_nullspace(order):
    m = distorted_box(2)
    m = to_quadratic(m) if order == 2 else m
    K = stiffness_matrix(m, MAT)
    assert K.indices.dtype == np.int32
    assert abs(K - K.T).max() <= 1e-14 * abs(K).max()
    B = rigid_body_modes(m.points)
    assert np.abs(K @ B).max() <= 1e-12 * abs(K).max() * np.abs(B).max()
    w = np.linalg.eigvalsh(K.toarray())
    assert np.sum(np.abs(w) < 1e-9 * w.max()) == 6 and w.min() > -1e-9 * w.max()
    # global K equals the sum of element matrices (scatter check)
    Ke = element_stiffness(m, MAT.lame_lambda_Pa, MAT.shear_modulus_Pa)
    dofs = (3 * m.tets[:, :, None] + np.arange(3)).reshape(len(m.tets), -1)
    Kd = np.zeros(K.shape)
    np.add.at(Kd, (dofs[:, :, None], dofs[:, None, :]), Ke)
    np.testing.assert_allclose(K.toarray(), Kd, atol=1e-12 * abs(Kd).max())


def test_strain_energy_of_homogeneous_field():
    """½ uᵀK u = ½ ∫ σ:ε dV = ½ V (λ tr ε² + 2μ ε:ε) for u = A x (any mesh, P1 and P2)."""
    A = np.array([[1e-3, 2e-4, -3e-4], [5e-4, -2e-3, 1e-4], [0, 3e-4, 1.5e-3]])
    eps = 0.5 * (A + A.T)
    for m in (distorted_box(), to_quadratic(distorted_box())):
        u = m.points @ A.T
        K = stiffness_matrix(m, MAT)
        W = 0.5 * u.ravel() @ (K @ u.ravel())
        W_ex = 0.5 * m.signed_volumes().sum() * (MAT.lame_lambda_Pa * np.trace(eps) ** 2
                                                  + 2 * MAT.shear_modulus_Pa * np.sum(eps * eps))
        assert W == pytest.approx(W_ex, rel=1e-12)


@pytest.mark.parametrize("order", [1, 2])
def test_patch_test_linear_field_machine_precision(order):
    """Boundary nodes prescribed u = A x + c ⇒ interior nodes and all strains exact."""
    m = distorted_box(3, seed=order)
    m = to_quadratic(m) if order == 2 else m
    A = np.array([[1e-3, 2e-4, -3e-4], [5e-4, -2e-3, 1e-4], [0, 3e-4, 1.5e-3]])
    c = np.array([1e-4, -2e-4, 3e-4])
    u_ex = m.points @ A.T + c
    bnd = m.boundary_nodes()
    p = Problem(m, MAT).fix(bnd, value_m=u_ex[bnd])
    interior = np.setdiff1d(np.arange(m.n_nodes), bnd)
    assert len(interior) > 0
    s = solve(p, method="direct")
    scale = np.abs(u_ex).max()
    assert np.abs(s.u - u_ex).max() <= 1e-12 * scale
    eps = element_strains(m, s.u)
    assert np.abs(eps - 0.5 * (A + A.T)).max() <= 1e-11 * np.abs(A).max()
    pts = np.random.default_rng(1).uniform(0.05, 0.95, (50, 3))
    assert np.abs(strain_at(m, s.u, pts) - 0.5 * (A + A.T)).max() <= 1e-11 * np.abs(A).max()
    np.testing.assert_allclose(displacement_at(m, s.u, pts), pts @ A.T + c, atol=1e-12 * scale)
    assert np.abs(nodal_strains(m, s.u) - 0.5 * (A + A.T)).max() <= 1e-11 * np.abs(A).max()
    # and with AMG-CG
    s2 = solve(p, method="amg", rtol=1e-13)
    assert np.abs(s2.u - u_ex).max() <= 1e-9 * scale


def test_p2_reproduces_quadratic_field_pure_bending():
    """P2 is exact for the quadratic pure-bending field of a free beam under end moments."""
    m = to_quadratic(distorted_box(2, seed=3))
    E, nu = MAT.E_Pa, MAT.nu
    k = 1e-3   # curvature 1/m: σ_xx = −E k z, ε_yy = ε_zz = ν k z, no shear
    x, y, z = m.points.T
    u_ex = np.stack([-k * x * z, nu * k * y * z, 0.5 * k * (x ** 2 + nu * (z ** 2 - y ** 2))], axis=1)
    bnd = m.boundary_nodes()
    s = solve(Problem(m, MAT).fix(bnd, value_m=u_ex[bnd]))
    assert np.abs(s.u - u_ex).max() <= 1e-11 * np.abs(u_ex).max()
    e = element_strains(m, s.u)
    q = m.points[m.tets]   # check σ_xx = −E k z at element quadrature points via strain_at
    pts = np.random.default_rng(2).uniform(0.1, 0.9, (20, 3))
    eps = strain_at(m, s.u, pts)
    np.testing.assert_allclose(eps[:, 0, 0], -k * pts[:, 2], atol=1e-12)
    assert np.isfinite(e).all() and q.shape[1] == 10


def test_element_nodal_strains_compiled_pass_equals_numpy_on_curved_elements(monkeypatch):
    """The one-pass compiled strains at the elements' own nodes equal numpy's gradient arrays and
    einsum on curved P2 elements, give a quadratic field's exact
    strain on straight ones (a curved map makes it quartic in ξ), and name an inverted element."""
    m = to_quadratic(distorted_box(3, seed=5))
    pts = m.points.copy()
    pts[m.tets[:, 4:].ravel()] += np.random.default_rng(7).uniform(-0.02, 0.02, (m.tets[:, 4:].size, 3)) / 3
    m = Mesh(pts, m.tets)
    u = np.random.default_rng(8).normal(size=(m.n_nodes, 3))
    from flexure import stiffness_assembly

    assert stiffness_assembly.available()            # numba is a dependency: the compiled pass runs
    one = element_nodal_strains(m, u)
    with monkeypatch.context() as mp:
        mp.setattr(stiffness_assembly, "available", lambda: False)
        ref = element_nodal_strains(m, u)
    assert np.abs(one - ref).max() <= 1e-12 * np.abs(ref).max()
    k, nu = 1e-3, 0.3                                # pure bending: ε_xx = −k z, ε_yy = ε_zz = ν k z
    straight = to_quadratic(distorted_box(3, seed=5))
    x, y, z = straight.points.T
    u_ex = np.stack([-k * x * z, nu * k * y * z, 0.5 * k * (x ** 2 + nu * (z ** 2 - y ** 2))], axis=1)
    e = element_nodal_strains(straight, u_ex)
    zn = straight.points[straight.tets][:, :, 2]
    np.testing.assert_allclose(e[:, :, 0, 0], -k * zn, atol=1e-14)
    np.testing.assert_allclose(e[:, :, 1, 1], nu * k * zn, atol=1e-14)
    np.testing.assert_allclose(e[:, :, 0, 1], 0.0, atol=1e-14)
    bad = Mesh(m.points, m.tets.copy())
    bad.tets[7, [1, 2]] = bad.tets[7, [2, 1]]
    bad.tets[7, [4, 6, 8, 9]] = bad.tets[7, [6, 4, 9, 8]]
    with pytest.raises(InputError, match="element 7 is inverted"):
        element_nodal_strains(bad, u)


def test_reactions_balance_and_coupling_statics():
    m = to_quadratic(cylinder_mesh(0.005, 0.01, 0.03, 1, 12, 4))
    top = m.select_faces(lambda x: x[:, 2] > 0.03 - 1e-9)
    F, M = np.array([3.0, -2.0, 5.0]), np.array([0.1, -0.2, 0.4])
    ref = np.array([0.001, 0.0, 0.04])
    # distributed: the nodal forces are statically equivalent to (F, M about ref)
    p = Problem(m, MAT)
    p.couple_rigid(top, ref, F, M, kind="distributed")
    f = p.force_N
    np.testing.assert_allclose(f.sum(axis=0), F, rtol=1e-12)
    np.testing.assert_allclose(np.cross(m.points - ref, f).sum(axis=0), M, rtol=1e-10, atol=1e-14)
    bottom = m.select_nodes(lambda x: x[:, 2] < 1e-9)
    for kind in ("distributed", "kinematic"):
        p = Problem(m, MAT).fix(bottom)
        nodes_or_faces = top if kind == "distributed" else np.unique(top)
        p.couple_rigid(nodes_or_faces, ref, F, M, kind=kind)
        s = solve(p, keep_K=True)
        r = (s.K @ s.u.ravel()).reshape(-1, 3)          # internal forces = reactions + loads
        np.testing.assert_allclose(r[bottom].sum(axis=0), -F, rtol=1e-8, atol=1e-8 * np.abs(F).max())
        mom = np.cross(m.points[bottom] - ref, r[bottom]).sum(axis=0)
        np.testing.assert_allclose(mom, -M, rtol=1e-7, atol=1e-8)
        if kind == "kinematic":   # coupled nodes move rigidly with the reference point
            U, th = s.reference[0]["U_m"], s.reference[0]["theta_rad"]
            nodes = np.unique(top)
            u_rigid = U + np.cross(th, m.points[nodes] - ref)
            np.testing.assert_allclose(s.u[nodes], u_rigid, atol=1e-12 * np.abs(s.u).max())


def test_input_errors():
    m = box_mesh(1, 1, 1)
    with pytest.raises(InputError, match="tets"):
        Mesh(m.points, m.tets[:, :3])
    with pytest.raises(InputError, match="node"):
        Mesh(m.points, m.tets + 100)
    bad = m.tets.copy()
    bad[0] = bad[0][[1, 0, 2, 3]]
    with pytest.raises(InputError, match="element 0 is inverted"):
        stiffness_matrix(Mesh(m.points, bad), MAT)
    with pytest.raises(InputError, match="rigid-body"):
        solve(Problem(m, MAT).fix([0]))           # one fixed node leaves rotations free
    with pytest.raises(InputError, match="nu"):
        Material(70e9, 0.5)
    with pytest.raises(InputError, match="face"):
        Problem(m, MAT).add_traction(np.zeros((2, 6), int), (1, 0, 0))
    p = Problem(m, MAT).fix([0])
    with pytest.raises(InputError, match="fixed and rigidly coupled"):
        p.couple_rigid([0, 1], (0, 0, 0))
        solve(p)


def test_max_shear_strain_is_half_the_principal_spread():
    """The closed form equals ½ (λ_max − λ_min) of numpy's eigvalsh on random tensors at strain scale,
    with the degenerate cases: isotropic (0), two equal principal values, pure shear."""
    rng = np.random.default_rng(7)
    M = rng.standard_normal((2000, 3, 3)) * 1e-4
    E = 0.5 * (M + np.swapaxes(M, -1, -2))
    Q = np.linalg.qr(rng.standard_normal((3, 3)))[0]
    E = np.concatenate([E, [np.eye(3) * 3e-4, Q @ np.diag([2e-4, 2e-4, -1e-4]) @ Q.T,
                            Q @ np.diag([1e-4, -1e-4, -1e-4]) @ Q.T, [[0, 5e-5, 0], [5e-5, 0, 0], [0, 0, 0]]]])
    ev = np.linalg.eigvalsh(E)
    ref = 0.5 * (ev[:, 2] - ev[:, 0])
    got = max_shear_strain(E)
    assert np.abs(got - ref).max() <= 1e-7 * np.abs(E).max()
    assert got[-4] == 0.0 and got[-1] == pytest.approx(5e-5, rel=1e-9)
    assert got[-3] == pytest.approx(1.5e-4, rel=1e-7) and got[-2] == pytest.approx(1e-4, rel=1e-7)


def test_stress_measures_in_one_pass_equal_the_numpy_forms():
    """post.stress_measures (one compiled pass: von Mises from the strain's deviator, 2μ √(3/2 d:d), and
    the closed-form max shear) equals von_mises(stress_from_strain(ε)) and max_shear_strain(ε) on
    element-nodal shaped tensors (m, nn, 3, 3), the isotropic and pure-shear cases included."""
    from flexure.post import stress_from_strain, stress_measures

    rng = np.random.default_rng(11)
    M = rng.standard_normal((300, 10, 3, 3)) * 1e-4
    E = 0.5 * (M + np.swapaxes(M, -1, -2))
    E[0, 0] = np.eye(3) * 3e-4
    E[0, 1] = [[0, 5e-5, 0], [5e-5, 0, 0], [0, 0, 0]]
    vm, gmax = stress_measures(E, MAT)
    assert vm.shape == gmax.shape == (300, 10)
    ref_vm = von_mises(stress_from_strain(E, MAT))
    assert np.abs(vm - ref_vm).max() <= 1e-12 * ref_vm.max()
    assert np.abs(gmax - max_shear_strain(E)).max() <= 1e-12 * np.abs(E).max()
    assert vm[0, 0] <= 1e-9 * ref_vm.max() and gmax[0, 1] == pytest.approx(5e-5, rel=1e-12)
    assert vm[0, 1] == pytest.approx(2 * MAT.shear_modulus_Pa * np.sqrt(3) * 5e-5, rel=1e-12)


def test_material_default_and_von_mises():
    assert ALUMINIUM_6061_T6.E_Pa == 68.9e9 and ALUMINIUM_6061_T6.nu == 0.33
    assert ALUMINIUM_6061_T6.yield_Pa == 276e6
    s = np.zeros((3, 3)); s[0, 0] = 100.0
    assert von_mises(s) == pytest.approx(100.0)
    t = np.zeros((3, 3)); t[0, 1] = t[1, 0] = 50.0
    assert von_mises(t) == pytest.approx(50.0 * np.sqrt(3))
    assert von_mises(np.eye(3) * 7.0) == pytest.approx(0.0, abs=1e-12)


def test_several_load_cases_share_one_solver():
    from flexure.solve import solve_reduced

    m = to_quadratic(cylinder_mesh(0.005, 0.01, 0.03, 1, 12, 4))
    p = Problem(m, MAT).fix(m.select_nodes(lambda x: x[:, 2] < 1e-9))
    p.couple_rigid(m.select_nodes(lambda x: x[:, 2] > 0.03 - 1e-9), (0, 0, 0.03))
    system = p.reduced_system(stiffness_matrix(m, MAT))
    rhs = np.zeros((system.A.shape[0], 6))
    rhs[system.ref_slices[0], :] = np.eye(6)        # unit F_x, F_y, F_z, M_x, M_y, M_z
    qd, infod = solve_reduced(system, rhs, method="direct")
    qa, infoa = solve_reduced(system, rhs, method="amg")
    assert len(infoa["iterations"]) == 6 and "p-multigrid" in infoa["solver"]
    np.testing.assert_allclose(qa, qd, atol=1e-8 * np.abs(qd).max())
    # the reference-point compliance matrix is symmetric (Maxwell–Betti reciprocity)
    C = qd[system.ref_slices[0], :]
    np.testing.assert_allclose(C, C.T, rtol=1e-8, atol=1e-10 * np.abs(C).max())
