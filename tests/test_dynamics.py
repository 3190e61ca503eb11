"""Rigid-body dynamics against independent references: the skew-symmetry property, energy
conservation of a free swing (scipy DOP853), finite-difference Jacobians, and pinocchio."""

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from estimator import dynamics as D
from estimator.robot import Robot, paper_leg


def three_link(floating=True):
    return Robot(lengths_m=np.array([0.3, 0.25, 0.2]), com_m=np.array([0.12, 0.1, 0.15]),
                 masses_kg=np.array([1.2, 0.7, 0.4]), inertias_kgm2=np.array([0.01, 0.005, 0.002]),
                 base_mass_kg=2.0, base_inertia_kgm2=0.03, floating=floating)


def offset_link(floating=True):
    """Centres of mass off the link axis (com_perp_m), both signs: a real robot's CAD."""
    return Robot(lengths_m=np.array([0.3, 0.25, 0.2]), com_m=np.array([0.12, 0.1, 0.15]),
                 com_perp_m=np.array([0.025, -0.04, 0.012]),
                 masses_kg=np.array([1.2, 0.7, 0.4]), inertias_kgm2=np.array([0.01, 0.005, 0.002]),
                 base_mass_kg=2.0, base_inertia_kgm2=0.03, floating=floating)


ROBOTS = [paper_leg(True), paper_leg(False), three_link(True), three_link(False), offset_link(True),
          offset_link(False)]
IDS = ["leg-floating", "leg-fixed", "3link-floating", "3link-fixed", "offset-floating", "offset-fixed"]


def _states(robot, n=20, seed=0):
    rng = np.random.default_rng(seed)
    return rng.uniform(-np.pi, np.pi, (n, robot.n_coords)), rng.normal(0, 3, (n, robot.n_coords))


@pytest.mark.parametrize("robot", ROBOTS, ids=IDS)
def test_mdot_minus_2c_is_skew(robot):
    q, dq = _states(robot)
    h = 1e-6
    Mdot = (D.mass_matrix(robot, q + h * dq) - D.mass_matrix(robot, q - h * dq)) / (2 * h)
    S = Mdot - 2 * D.coriolis_matrix(robot, q, dq)
    assert np.abs(S + np.swapaxes(S, -1, -2)).max() < 1e-8
    # and the exact identity xᵀ(Ṁ − 2C)x = 0 for any x
    x = np.random.default_rng(3).normal(size=q.shape)
    assert np.abs(np.einsum("tk,tkl,tl->t", x, S, x)).max() < 1e-8


@pytest.mark.parametrize("robot", ROBOTS, ids=IDS)
def test_free_swing_conserves_energy(robot):
    """No actuation, no damping, gravity on: T + V constant along a DOP853 trajectory."""
    n = robot.n_coords
    rng = np.random.default_rng(7)
    q0 = rng.uniform(-1.5, 1.5, n)
    dq0 = rng.normal(0, 1.5, n)

    def f(_t, y):
        return np.concatenate([y[n:], D.forward_dynamics(robot, y[:n], y[n:], np.zeros(n))])

    sol = solve_ivp(f, (0.0, 1.0), np.concatenate([q0, dq0]), method="DOP853", rtol=1e-11,
                    atol=1e-12, dense_output=False, t_eval=np.linspace(0, 1, 101))
    assert sol.success
    T, V = D.energy(robot, sol.y[:n].T, sol.y[n:].T)
    E = T + V
    scale = np.abs(T).max() + np.abs(V - V.mean()).max()
    drift = np.abs(E - E[0]).max() / scale
    print(f"{robot.name} floating={robot.floating}: relative energy drift {drift:.2e}")
    assert drift < 1e-8
    assert np.ptp(T) > 0.05 * scale          # the swing really exchanges energy


@pytest.mark.parametrize("robot", ROBOTS, ids=IDS)
def test_point_jacobian_finite_differences(robot):
    q, _ = _states(robot, 5, seed=2)
    h = 1e-6
    for link in range(1, robot.n_links + 1):
        for alpha in (0.0, 0.35, 1.0):
            J = D.point_jacobian(robot, q, link, alpha)
            J_fd = np.stack([(D.contact_point(robot, q + h * e, link, alpha)
                              - D.contact_point(robot, q - h * e, link, alpha)) / (2 * h)
                             for e in np.eye(robot.n_coords)], axis=-1)
            np.testing.assert_allclose(J, J_fd, atol=1e-8)


# ----------------------------------------------------------------------------- pinocchio
def pinocchio_model(robot):
    """The planar chain in pinocchio. Our counterclockwise angle (x right, z up) is a rotation
    about −y (a rotation about +y maps z → x), so revolute joints use the axis (0, −1, 0); the
    links hang along −z at zero angle (a body's +x then maps to n = (cos φ, sin φ), so the centre
    of mass sits at (com_perp_m, 0, −com_m) in the joint frame). Floating base: prismatic x,
    prismatic z, revolute −y."""
    pin = pytest.importorskip("pinocchio")
    model = pin.Model()
    axis = np.array([0.0, -1.0, 0.0])
    parent = 0
    if robot.floating:
        parent = model.addJoint(parent, pin.JointModelPX(), pin.SE3.Identity(), "x")
        parent = model.addJoint(parent, pin.JointModelPZ(), pin.SE3.Identity(), "z")
        parent = model.addJoint(parent, pin.JointModelRevoluteUnaligned(axis), pin.SE3.Identity(),
                                "theta")
        Ib = robot.base_inertia_kgm2
        model.appendBodyToJoint(parent, pin.Inertia(robot.base_mass_kg, np.zeros(3),
                                                    np.diag([Ib, Ib, Ib])), pin.SE3.Identity())
    offset = 0.0
    for i in range(robot.n_links):
        placement = pin.SE3(np.eye(3), np.array([0.0, 0.0, -offset]))
        parent = model.addJoint(parent, pin.JointModelRevoluteUnaligned(axis), placement, f"q{i + 1}")
        I = robot.inertias_kgm2[i]
        model.appendBodyToJoint(parent, pin.Inertia(robot.masses_kg[i],
                                                    np.array([robot.com_perp_m[i], 0.0, -robot.com_m[i]]),
                                                    np.diag([I, I, I])), pin.SE3.Identity())
        offset = robot.lengths_m[i]
    model.gravity.linear = np.array([0.0, 0.0, -robot.gravity_m_per_s2])
    return model


@pytest.mark.parametrize("robot", ROBOTS, ids=IDS)
def test_agrees_with_pinocchio(robot):
    pin = pytest.importorskip("pinocchio")
    model = pinocchio_model(robot)
    data = model.createData()
    q, dq = _states(robot, 25, seed=11)
    M, C, G = D.mass_matrix(robot, q), D.coriolis_matrix(robot, q, dq), D.gravity_vector(robot, q)
    for k in range(len(q)):
        Mp = pin.crba(model, data, q[k])
        Mp = np.triu(Mp) + np.triu(Mp, 1).T
        Cp = pin.computeCoriolisMatrix(model, data, q[k], dq[k])
        Gp = pin.computeGeneralizedGravity(model, data, q[k])
        np.testing.assert_allclose(M[k], Mp, atol=1e-10)
        np.testing.assert_allclose(C[k] @ dq[k], Cp @ dq[k], atol=1e-10)
        np.testing.assert_allclose(C[k], Cp, atol=1e-10)
        np.testing.assert_allclose(G[k], Gp, atol=1e-10)
        # and the whole equation of motion through RNEA with an arbitrary acceleration
        ddq = np.sin(np.arange(robot.n_coords) + k)
        np.testing.assert_allclose(M[k] @ ddq + C[k] @ dq[k] + G[k],
                                   pin.rnea(model, data, q[k], dq[k], ddq), atol=1e-10)
    # forward kinematics of the foot as a further check of the frame mapping
    pin.forwardKinematics(model, data, q[0])
    joints, _ = D.forward_kinematics(robot, q[0])
    last = data.oMi[model.njoints - 1]
    tip = last.act(np.array([0.0, 0.0, -robot.lengths_m[-1]]))
    np.testing.assert_allclose(tip[[0, 2]], joints[-1], atol=1e-12)


@pytest.mark.parametrize("robot", ROBOTS, ids=IDS)
def test_fast_chain_terms_match_matrices(robot):
    """observer.chain_terms (O(N) suffix sums, used on the hot path) = M q̇, Cᵀq̇, C q̇, G."""
    from estimator.observer import chain_terms

    full = robot.with_base(True)
    q, dq = _states(full, 30, seed=5)
    if not robot.floating:
        q[:, :3] = dq[:, :3] = 0.0
    t = chain_terms(robot, q, dq, want=("P", "CTdq", "Cdq", "G"))
    M, C = D.mass_matrix(full, q), D.coriolis_matrix(full, q, dq)
    np.testing.assert_allclose(t["P"], np.einsum("tkl,tl->tk", M, dq), atol=1e-12)
    np.testing.assert_allclose(t["CTdq"], np.einsum("tlk,tl->tk", C, dq), atol=1e-12)
    np.testing.assert_allclose(t["Cdq"], np.einsum("tkl,tl->tk", C, dq), atol=1e-12)
    np.testing.assert_allclose(t["G"], D.gravity_vector(full, q), atol=1e-12)
