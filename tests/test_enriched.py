"""The enriched-space error estimate (flexure.enriched): its system against an exact energy, its
iterative solve against a direct one, and its identity J(u⁺) − J(u_h) = R*(z_h)(e_W)."""

import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from flexure import dwr, enriched
from flexure.bc import Problem
from flexure.fem import stiffness_matrix
from flexure.gauges import Gauge, functionals
from flexure.material import Material
from flexure.mesh import box_mesh, to_linear, to_quadratic
from flexure.surplus import tet_rule_degree5

AL = Material(70e9, 0.33, 270e6, "aluminium")


def _distorted_box():
    rng = np.random.default_rng(3)
    m = to_quadratic(box_mesh(3, 2, 4, size=(1.0, 0.8, 1.3)))
    m.points[:] += rng.normal(size=m.points.shape) * 0.03
    return to_quadratic(to_linear(m))


def test_enriched_system_holds_a_cubic_exact_energy():
    """A cubic field u (u_k = A_kj x_j + T_kijl x_i x_j x_l / 6) lies in V⁺ = P2 ⊕ W: its P2 nodal
    values plus the surplus coefficients of its third derivatives T (dwr.cubic_surplus). The
    assembled enriched matrix [[K, C], [Cᵀ, K_WW]] must give its energy ∫ σ(u):ε(u) dV, computed
    here from the analytic gradient (degree-5 rule, exact for this degree-4 integrand)."""
    rng = np.random.default_rng(7)
    mesh = _distorted_box()
    A = rng.normal(size=(3, 3))
    T = rng.normal(size=(3, 3, 3, 3))
    T = sum(T.transpose(0, *p) for p in ((1, 2, 3), (1, 3, 2), (2, 1, 3), (2, 3, 1), (3, 1, 2), (3, 2, 1))) / 6.0

    def grad(x):                                                       # (…,3) → (…,3,3) ∂u_k/∂x_i
        return A[None] + 0.5 * np.einsum("kijl,pj,pl->pki", T, x, x)

    def u(x):
        return x @ A.T + np.einsum("kijl,pi,pj,pl->pk", T, x, x, x) / 6.0

    n = mesh.n_nodes
    none = np.zeros(n, bool)
    K_ww, _, num = enriched.assemble(mesh, AL, np.zeros((n, 3)), none)
    C = enriched.coupling_matrix(mesh, AL, num)
    K = stiffness_matrix(mesh, AL)
    G, sign, free = num
    assert free.all()
    D3 = np.broadcast_to(T.transpose(0, 1, 2, 3)[None], (mesh.n_elements, 3, 3, 3, 3))
    ce, cf = dwr.cubic_surplus(mesh, D3)                                # (m,6,3), (m,4,3)
    coef = np.concatenate([ce, cf], axis=1) * sign[..., None]           # global orientation
    xw = np.zeros((len(free), 3))
    xw[G] = coef
    # continuity: every element gives a shared edge/face the same coefficient
    assert np.abs(xw[G] - coef).max() < 1e-9 * np.abs(coef).max()
    xh = u(mesh.points).ravel()
    xw = xw.ravel()
    energy = xh @ (K @ xh) + 2.0 * xh @ (C @ xw) + xw @ (K_ww @ xw)
    xi, wq = tet_rule_degree5()
    X = mesh.points[mesh.corner_tets]
    L = np.column_stack([1.0 - xi.sum(axis=1), xi])
    xq = np.einsum("qa,eai->eqi", L, X).reshape(-1, 3)
    H = grad(xq)
    eps = 0.5 * (H + H.swapaxes(-1, -2))
    lam, mu = AL.lame_lambda_Pa, AL.shear_modulus_Pa
    dens = 2.0 * mu * (eps * eps).sum(axis=(1, 2)) + lam * np.trace(eps, axis1=1, axis2=2) ** 2
    vol = np.abs(mesh.signed_volumes())
    exact = float((dens.reshape(len(X), -1) @ wq * 6.0 * vol).sum())
    assert energy == pytest.approx(exact, rel=1e-9)


def _bar():
    """A 10 × 10 × 30 mm bar clamped at z = 0, a unit torque through a rigid coupling of its top,
    one gauge on a side face: (mesh, problem, system, LU of A, gauge)."""
    mesh = to_quadratic(box_mesh(2, 2, 6, size=(0.01, 0.01, 0.03)))
    p = mesh.points
    fixed = np.flatnonzero(p[:, 2] < 1e-12)
    load = np.flatnonzero(p[:, 2] > 0.03 - 1e-12)
    pr = Problem(mesh, AL).fix(fixed)
    pr.couple_rigid(load, (0.005, 0.005, 0.03), moment_Nm=(0, 0, 1))
    sy = pr.reduced_system(stiffness_matrix(mesh, AL))
    g = Gauge(centre_m=(0.01, 0.005, 0.012), axis=(0.0, 0.7071067811865476, 0.7071067811865476),
              normal=(1.0, 0.0, 0.0), length_m=0.004, width_m=0.003, arm=1)
    cons = np.zeros(mesh.n_nodes, bool)
    cons[fixed] = cons[load] = True
    return mesh, pr, sy, spla.splu(sy.A.tocsc()), g, cons


def _bar_unit_rotation():
    """``_bar`` and its P2 solution under a unit load on the hub rotation θ: (… of ``_bar``, θ's reduced
    index, the reduced solution q, the nodal U)."""
    mesh, pr, sy, lu, g, cons = _bar()
    i_th = sy.ref_slices[0].start + 5
    B = np.zeros(sy.A.shape[0])
    B[i_th] = 1.0
    q = lu.solve(B)
    return mesh, pr, sy, lu, g, cons, i_th, q, pr.expand(sy, q)


def test_enriched_solve_against_a_direct_solve_and_the_dual_identity():
    """enriched_solve's block-preconditioned CG gives the direct solution of the whole enriched
    system: θ⁺ − θ_h and the gauge's J(u⁺) − J(u_h), which also equals R*(z_h)(e_W) through the
    gauge's P2 dual z_h (flexure.enriched (1)). The float64 block storage: the float32 default moves
    the converged figures by ~1e-7 (tests/test_block_sparse.py)."""
    mesh, pr, sy, lu, g, cons = _bar()
    i_th = sy.ref_slices[0].start + 5
    nq = sy.A.shape[0]
    F = functionals([g], mesh)                                           # (n,3,1)
    B = np.zeros((nq, 2))
    B[i_th, 0] = 1.0
    B[:, 1] = sy.T.T @ F.reshape(-1)
    B[sy.fixed_q] = 0.0
    Q = lu.solve(B)
    U = pr.expand(sy, Q[:, 0])
    Z = pr.expand(sy, Q[:, 1])
    d_eps, d_th, info = enriched.enriched_solve(sy, mesh, AL, [g], U, Q[:, 0], cons, lambda R: lu.solve(R),
                                                rtol=1e-12, theta_index=i_th, storage="block64")
    # the direct solve of [[A, C], [Cᵀ, K_WW]] [e_h; e_W] = [0; r_W]
    K_ww, r_w, num = enriched.assemble(mesh, AL, U, cons)
    keep = np.repeat(num[2], 3)
    C = enriched.coupling_matrix(mesh, AL, num)
    mask = np.ones(nq)
    mask[sy.fixed_q] = 0.0
    Cq = (sp.diags(mask) @ (sy.T.T @ C))[:, keep]
    full = sp.bmat([[sy.A, Cq], [Cq.T, K_ww[keep][:, keep]]]).tocsc()
    x = spla.spsolve(full, np.concatenate([B[:, 0] - sy.A @ Q[:, 0], r_w[keep]]))
    assert d_th == pytest.approx(x[i_th], rel=1e-8) and x[i_th] > 0        # the compliance only rises
    eh = pr.expand(sy, x[:nq])
    ew = np.zeros(len(keep))
    ew[keep] = x[nq:]
    coef = ew.reshape(-1, 3)[num[0]] * num[1][..., None]
    direct = float(np.einsum("ni,ni->", F[:, :, 0], eh) + dwr.gauge_indicators(mesh, [g], coef[:, :6], coef[:, 6:]).sum())
    assert d_eps[0] == pytest.approx(direct, rel=1e-8)
    # J(u⁺) − J(u_h) = J(e_W) − a(z_h, e_W): the P2 part of e⁺ enters only through the dual
    V = np.concatenate([U[:, :, None], Z[:, :, None]], axis=2)
    eta = dwr.energy_indicators(mesh, AL, V, coef[:, :6], coef[:, 6:]).sum(axis=0)
    eta[1:] += dwr.gauge_indicators(mesh, [g], coef[:, :6], coef[:, 6:]).sum(axis=0)
    assert eta[1] == pytest.approx(d_eps[0], rel=1e-6)
    assert eta[0] == pytest.approx(d_th, rel=1e-6)                       # θ: R(u_h)(e_W) = a(e⁺, e⁺)


def test_dual_corrected_estimate_equals_the_converged_and_is_closer_when_the_cg_stops_early():
    """enriched_solve with the P2 duals (``duals``): the correction z̃ᵀ ρ_h vanishes at convergence
    (the same θ⁺ − θ_h and gauge d to 1e-9). Stopped early, θ (its dual is the primal, whose enriched
    error is small) is closer to the converged value at every tolerance; the gauge's dual has a large
    enriched error on this coarse bar, so its corrected value is closer only on the whole (geometric
    mean over the tolerances; worse at 0.3, 0.1, 0.05 here). With the block-diagonal preconditioner
    ("jacobi"): the multiplicative one (the default) leaves a V_h residual that the gauge's correction
    neither helps nor harms on this bar (geometric means 3.08e-3 against 3.04e-3); θ's holds with both."""
    mesh, pr, sy, lu, g, cons = _bar()
    i_th = sy.ref_slices[0].start + 5
    nq = sy.A.shape[0]
    B = np.zeros((nq, 2))
    B[i_th, 0] = 1.0
    B[:, 1] = sy.T.T @ functionals([g], mesh).reshape(-1)
    B[sy.fixed_q] = 0.0
    Q = lu.solve(B)
    U = pr.expand(sy, Q[:, 0])

    def run(rtol, duals):
        d_eps, d_th, info = enriched.enriched_solve(sy, mesh, AL, [g], U, Q[:, 0], cons, lambda R: lu.solve(R),
                                                    rtol=rtol, theta_index=i_th, duals=duals, w_precond="jacobi")
        return np.r_[d_th, d_eps], info["pcg_iterations"]

    conv, _ = run(1e-12, None)
    assert np.allclose(run(1e-12, Q)[0], conv, rtol=1e-9, atol=0.0)
    err, err_c = [], []
    for rtol in (0.5, 0.3, 0.2, 0.1, 0.05, 0.03, 0.02, 0.01, 0.005):
        (loose, its), (loose_c, its_c) = run(rtol, None), run(rtol, Q)
        assert its == its_c and np.all(loose != conv)
        err.append(np.abs(loose / conv - 1.0))
        err_c.append(np.abs(loose_c / conv - 1.0))
    err, err_c = np.array(err), np.array(err_c)
    assert np.all(err_c[:, 0] < 0.2 * err[:, 0])
    assert np.exp(np.log(err_c[:, 1]).mean()) < 0.5 * np.exp(np.log(err[:, 1]).mean())


def _block_spd(n_blocks: int, seed: int) -> np.ndarray:
    """A dense SPD matrix of 3 × 3 blocks with a sparse block pattern: BᵀB + a small shift."""
    rng = np.random.default_rng(seed)
    B = rng.normal(size=(3 * n_blocks, 3 * n_blocks)) * (rng.random((3 * n_blocks, 3 * n_blocks)) < 0.15)
    return B.T @ B + 0.05 * np.eye(3 * n_blocks)


def test_multiplicative_preconditioner_is_spd_below_its_damping_limit_and_beats_the_block_diagonal():
    """flexure.enriched.multiplicative_preconditioner, materialised on a random two-block SPD system
    [[A, C], [Cᵀ, K]]: symmetric and positive definite at ω = 1/λ̂ (λ̂ from ``jacobi_lambda_max``, within
    [λ_max/2, λ_max] of D⁻¹K), with a smaller condition number of M S than the block-diagonal diag(A⁻¹, D⁻¹)
    gives; past ω = 2/λ_max (the damped Jacobi step no longer a convergent smoother) it is indefinite."""
    nh, nw = 10, 14
    S = _block_spd(nh + nw, 11)
    A, C, K = S[:3 * nh, :3 * nh], S[:3 * nh, 3 * nh:], S[3 * nh:, 3 * nh:]
    Ainv = np.linalg.inv(A)
    Dinv = np.array([np.linalg.inv(K[3 * i:3 * i + 3, 3 * i:3 * i + 3]) for i in range(nw)])

    def jacobi(x):
        return np.einsum("kij,kj->ki", Dinv, x.reshape(-1, 3)).ravel()

    lam = np.linalg.eigvals(np.array([jacobi(c) for c in K.T]).T).real.max()
    lam_hat = enriched.jacobi_lambda_max(lambda x: K @ x, jacobi, 3 * nw)
    assert lam / 2 <= lam_hat <= lam * (1 + 1e-9)

    def materialised(omega):
        prec = enriched.multiplicative_preconditioner(3 * nh, lambda r: Ainv @ r, jacobi, lambda x: C @ x,
                                                      lambda x: C.T @ x, lambda x: K @ x, omega)
        return np.array([prec(e) for e in np.eye(len(S))]).T

    def cond(M):
        ev = np.linalg.eigvals(M @ S).real
        return ev.max() / ev.min()

    M = materialised(1.0 / lam_hat)
    assert np.allclose(M, M.T, atol=1e-10 * np.abs(M).max())
    assert np.linalg.eigvalsh(0.5 * (M + M.T)).min() > 0
    diag = np.zeros_like(S)
    diag[:3 * nh, :3 * nh] = Ainv
    diag[3 * nh:, 3 * nh:] = np.array([jacobi(e) for e in np.eye(3 * nw)]).T
    assert cond(M) < cond(diag)
    bad = materialised(2.5 / lam)
    assert np.linalg.eigvalsh(0.5 * (bad + bad.T)).min() < 0


def test_multiplicative_enriched_solve_converges_to_the_same_estimate_in_fewer_iterations():
    """The bar: the default (multiplicative) and the block-diagonal preconditioner give the same converged
    θ⁺ − θ_h and gauge d; to the adaptive levels' RTOL the multiplicative one in fewer iterations."""
    mesh, pr, sy, lu, g, cons, i_th, q, U = _bar_unit_rotation()
    out = {(wp, rtol): enriched.enriched_solve(sy, mesh, AL, [g], U, q, cons, lambda R: lu.solve(R), rtol=rtol,
                                               theta_index=i_th, storage="block64", w_precond=wp)
           for wp in ("jacobi", "multiplicative") for rtol in (1e-12, enriched.RTOL)}
    conv_j, conv_m = out["jacobi", 1e-12], out["multiplicative", 1e-12]
    assert conv_m[0][0] == pytest.approx(conv_j[0][0], rel=1e-8)
    assert conv_m[1] == pytest.approx(conv_j[1], rel=1e-8)
    assert out["multiplicative", enriched.RTOL][2]["pcg_iterations"] < out["jacobi", enriched.RTOL][2]["pcg_iterations"]
