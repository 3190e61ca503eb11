"""Rigid-body dynamics of a planar serial chain on a floating or fixed base.

Equation of motion (De Luca & Mattone convention, forces acting ON the robot):

    M(q) q̈ + C(q, q̇) q̇ + G(q) = τ + τ_ext,        τ_ext = J_c(q)ᵀ F_c for a contact force F_c.

Coordinates: floating [x, z, θ, q_1…q_N], fixed [q_1…q_N]. Internally everything is computed in
the floating coordinates (a fixed base is the floating one with x = z = θ = 0) and then restricted.
Every function is vectorized over leading axes: ``q`` has shape (..., n).

With φ_i = θ + Σ_{j≤i} q_j, e_i = (sin φ_i, −cos φ_i) and ⊥(a) = (−a_z, a_x) (a rotated +90°):

    p_{i+1} = p_i + l_i e_i,    c_i = p_i + r_i e_i + s_i n_i,   n_i = ⊥e_i = (cos φ_i, sin φ_i),
    ∂P/∂x = (1, 0), ∂P/∂z = (0, 1), ∂P/∂(θ or q_k) = ⊥(P − o_k) for every angle upstream of P,

where o_θ = o_{q_1} = p_1 and o_{q_k} = p_k. Then

    M = m_b E_xzᵀE_xz + I_b a_bᵀa_b + Σ_i (m_i J_iᵀ J_i + I_i a_iᵀ a_i),
    C = Σ_i m_i J_iᵀ J̇_i          (so Ṁ − 2C = Σ m_i (J̇_iᵀJ_i − J_iᵀJ̇_i) is skew-symmetric),
    G = g (m_b e_z + Σ_i m_i J_{i,z})ᵀ,

with a_i the angular-velocity row of link i (ones on θ, q_1…q_i) and J_{i,z} the z-row of J_i.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:                  # annotations only: robot.py's methods call this module
    from estimator.robot import Robot


def _perp(a: np.ndarray) -> np.ndarray:
    """⊥(a) = (−a_z, a_x): a rotated by +90° (counterclockwise)."""
    return np.stack([-a[..., 1], a[..., 0]], axis=-1)


def to_full(robot: Robot, q: np.ndarray) -> np.ndarray:
    """Pad fixed-base coordinates (or rates) with x = z = θ = 0 to floating coordinates."""
    q = np.asarray(q, dtype=float)
    if robot.floating:
        return q
    return np.concatenate([np.zeros(q.shape[:-1] + (3,)), q], axis=-1)


def _restrict(robot: Robot, a: np.ndarray, axes: int) -> np.ndarray:
    """Keep the joint block of the last ``axes`` axes for a fixed base."""
    if robot.floating:
        return a
    index = (Ellipsis,) + (slice(3, None),) * axes
    return a[index]


def link_angles(robot: Robot, q: np.ndarray) -> np.ndarray:
    """Absolute link angles φ_i = θ + q_1 + … + q_i, shape (..., N)."""
    qf = to_full(robot, q)
    return qf[..., 2:3] + np.cumsum(qf[..., 3:], axis=-1)


def forward_kinematics(robot: Robot, q: np.ndarray):
    """Joint positions p_1…p_{N+1} (..., N+1, 2) and link centres of mass (..., N, 2)."""
    qf = to_full(robot, q)
    phi = link_angles(robot, q)
    e = np.stack([np.sin(phi), -np.cos(phi)], axis=-1)
    base = qf[..., None, 0:2]
    joints = np.concatenate([base, base + np.cumsum(robot.lengths_m[:, None] * e, axis=-2)], axis=-2)
    n = np.stack([np.cos(phi), np.sin(phi)], axis=-1)
    coms = joints[..., :-1, :] + robot.com_m[:, None] * e + robot.com_perp_m[:, None] * n
    return joints, coms


def contact_point(robot: Robot, q: np.ndarray, link: int, alpha) -> np.ndarray:
    """p = p_c + α (p_{c+1} − p_c) on link ``link`` (1-based), shape (..., 2)."""
    joints, _ = forward_kinematics(robot, q)
    alpha = np.asarray(alpha, dtype=float)[..., None]
    return joints[..., link - 1, :] + alpha * (joints[..., link, :] - joints[..., link - 1, :])


def _upstream_mask(n_links: int) -> np.ndarray:
    """mask[c, k]: angle k (0 = θ, k = q_k) moves link c (0-based): k ≤ c + 1."""
    return (np.arange(n_links + 1)[None, :] <= np.arange(n_links)[:, None] + 1).astype(float)


def _jacobian_full(points, joints, mask_rows, shape_tail):
    """Full-coordinate Jacobians of ``points`` (..., K, 2) given which angles move each point."""
    origins = np.concatenate([joints[..., :1, :], joints[..., :-1, :]], axis=-2)  # (..., N+1, 2)
    ang = _perp(points[..., :, None, :] - origins[..., None, :, :]) * mask_rows[..., None]
    ang = np.swapaxes(ang, -1, -2)                                               # (..., K, 2, N+1)
    trans = np.broadcast_to(np.eye(2), ang.shape[:-1] + (2,))
    return np.concatenate([trans, ang], axis=-1)


def com_jacobians_full(robot: Robot, q: np.ndarray):
    """Centre-of-mass Jacobians in floating coordinates, (..., N, 2, N+3), and the positions."""
    joints, coms = forward_kinematics(robot, q)
    return _jacobian_full(coms, joints, _upstream_mask(robot.n_links), None), joints, coms


def point_jacobian(robot: Robot, q: np.ndarray, link: int, alpha) -> np.ndarray:
    """Jacobian of the contact point (link, α), shape (..., 2, n): ṗ = J q̇, τ_ext = Jᵀ F."""
    joints, _ = forward_kinematics(robot, q)
    alpha = np.asarray(alpha, dtype=float)
    point = joints[..., link - 1, :] + alpha[..., None] * (joints[..., link, :] - joints[..., link - 1, :])
    mask = _upstream_mask(robot.n_links)[link - 1]
    J = _jacobian_full(point[..., None, :], joints, mask[None, :], None)[..., 0, :, :]
    return J if robot.floating else J[..., 3:]


def _angular_rows(robot: Robot) -> np.ndarray:
    """a_i: link i's angular velocity φ̇_i = a_i · q̇_full, shape (N, N+3)."""
    n = robot.n_links
    a = np.zeros((n, n + 3))
    a[:, 2] = 1.0
    a[:, 3:] = np.tril(np.ones((n, n)))
    return a


def mass_matrix(robot: Robot, q: np.ndarray) -> np.ndarray:
    """M(q), shape (..., n, n), symmetric positive definite."""
    J, _, _ = com_jacobians_full(robot, q)
    a = _angular_rows(robot)
    M = np.einsum("i,...iak,...ial->...kl", robot.masses_kg, J, J)
    M = M + np.einsum("i,ik,il->kl", robot.inertias_kgm2, a, a)
    M[..., 0, 0] += robot.base_mass_kg
    M[..., 1, 1] += robot.base_mass_kg
    M[..., 2, 2] += robot.base_inertia_kgm2
    return _restrict(robot, M, 2)


def _com_jacobian_rates(robot: Robot, q, dq, J, joints, coms):
    """J̇_i for every centre of mass, from the point velocities: d/dt ⊥(P − o) = ⊥(Ṗ − ȯ)."""
    dqf = to_full(robot, dq)
    vel_coms = np.einsum("...iak,...k->...ia", J, dqf)
    phi = link_angles(robot, q)
    dphi = dqf[..., 2:3] + np.cumsum(dqf[..., 3:], axis=-1)
    n_vec = np.stack([np.cos(phi), np.sin(phi)], axis=-1)
    vel_base = dqf[..., None, 0:2]
    vel_joints = np.concatenate(
        [vel_base, vel_base + np.cumsum((robot.lengths_m * dphi)[..., None] * n_vec, axis=-2)], axis=-2)
    zero_trans = np.zeros(J.shape[:-1] + (2,))
    Jdot = _jacobian_full(vel_coms, vel_joints, _upstream_mask(robot.n_links), None)
    Jdot[..., :2] = zero_trans
    return Jdot


def coriolis_matrix(robot: Robot, q: np.ndarray, dq: np.ndarray) -> np.ndarray:
    """C(q, q̇) with Ṁ − 2C skew-symmetric, shape (..., n, n)."""
    J, joints, coms = com_jacobians_full(robot, q)
    Jdot = _com_jacobian_rates(robot, q, dq, J, joints, coms)
    C = np.einsum("i,...iak,...ial->...kl", robot.masses_kg, J, Jdot)
    return _restrict(robot, C, 2)


def gravity_vector(robot: Robot, q: np.ndarray) -> np.ndarray:
    """G(q) = ∂V/∂q, shape (..., n)."""
    J, _, _ = com_jacobians_full(robot, q)
    g = robot.gravity_m_per_s2
    G = g * np.einsum("i,...ik->...k", robot.masses_kg, J[..., 1, :])
    G[..., 1] += g * robot.base_mass_kg
    return _restrict(robot, G, 1)


def energy(robot: Robot, q: np.ndarray, dq: np.ndarray):
    """Kinetic and potential energy (T, V), each of shape (...)."""
    M = mass_matrix(robot, q)
    dq = np.asarray(dq, dtype=float)
    T = 0.5 * np.einsum("...k,...kl,...l->...", dq, M, dq)
    _, coms = forward_kinematics(robot, q)
    z_base = to_full(robot, q)[..., 1]
    V = robot.gravity_m_per_s2 * (robot.base_mass_kg * z_base
                                  + np.einsum("i,...i->...", robot.masses_kg, coms[..., 1]))
    return T, V


def forward_dynamics(robot: Robot, q, dq, tau) -> np.ndarray:
    """q̈ = M⁻¹ (τ − C q̇ − G), with τ the total generalized force (actuation + external)."""
    M = mass_matrix(robot, q)
    C = coriolis_matrix(robot, q, dq)
    rhs = np.asarray(tau, float) - np.einsum("...kl,...l->...k", C, dq) - gravity_vector(robot, q)
    return np.linalg.solve(M, rhs[..., None])[..., 0]
