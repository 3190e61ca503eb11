"""Dynamics against finite differences of the Lagrangian (independent of how M, C, G are built)."""

import numpy as np
import pytest

from estimator import dynamics as D
from estimator.robot import paper_leg

H = 1e-6


def _grad(f, q):
    eye = np.eye(q.shape[-1])
    return np.stack([(f(q + H * e) - f(q - H * e)) / (2 * H) for e in eye], axis=-1)


@pytest.mark.parametrize("floating", [True, False])
def test_lagrange_terms_match_finite_differences(floating):
    robot = paper_leg(floating)
    rng = np.random.default_rng(1)
    q = rng.uniform(-np.pi, np.pi, (6, robot.n_coords))
    dq = rng.normal(0, 2, (6, robot.n_coords))
    M = D.mass_matrix(robot, q)
    Mdot = (D.mass_matrix(robot, q + H * dq) - D.mass_matrix(robot, q - H * dq)) / (2 * H)
    C = D.coriolis_matrix(robot, q, dq)
    S = Mdot - 2 * C
    assert np.abs(S + np.swapaxes(S, -1, -2)).max() < 1e-8          # Ṁ − 2C skew
    dT_dq = _grad(lambda x: D.energy(robot, x, dq)[0], q)
    lagrange = np.einsum("...kl,...l->...k", Mdot, dq) - dT_dq       # d/dt ∂T/∂q̇ − ∂T/∂q − M q̈
    np.testing.assert_allclose(np.einsum("...kl,...l->...k", C, dq), lagrange, atol=1e-7)
    np.testing.assert_allclose(D.gravity_vector(robot, q),
                               _grad(lambda x: D.energy(robot, x, 0 * x)[1], q), atol=1e-7)
    assert np.all(np.linalg.eigvalsh(M) > 0)


def test_point_jacobian_matches_finite_differences():
    robot = paper_leg()
    q = np.random.default_rng(2).normal(size=(3, 5))
    for link, alpha in [(1, 0.0), (1, 0.7), (2, 0.4), (2, 1.0)]:
        J = D.point_jacobian(robot, q, link, alpha)
        J_fd = _grad(lambda x: D.contact_point(robot, x, link, alpha), q)
        np.testing.assert_allclose(J, J_fd, atol=1e-8)


def test_kinematics_follow_the_conventions():
    """q = 0 hangs the leg straight down; +q1 swings the foot toward +x (counterclockwise)."""
    robot = paper_leg()
    joints, _ = D.forward_kinematics(robot, np.zeros(5))
    np.testing.assert_allclose(joints[-1], [0.0, -0.42], atol=1e-15)
    joints, _ = D.forward_kinematics(robot, np.array([0, 0, 0, np.pi / 2, 0]))
    np.testing.assert_allclose(joints[-1], [0.42, 0.0], atol=1e-15)
