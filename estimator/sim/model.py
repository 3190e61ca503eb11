"""The simulated plant: rigid-body dynamics + base mount + PD + pokes + ground, as an ODE.

State y = [q (n), q̇ (n), s (1 if a ground is present)], batched over a leading axis (B, ·).
q is [x, z, θ, q_1…q_N] for a floating base or a spring-emulated fixed base, and [q_1…q_N] for a
rigid weld. The equation integrated is

    M(q) q̈ = τ_PD + W_mount + Σ_p J_p(q)ᵀ F_p(t) + J_foot(q)ᵀ F_ground − C(q, q̇) q̇ − G(q),

with W_mount = −K_b q_base − D_b q̇_base on the base rows (the wrench the mount exerts ON the base).
"""

from __future__ import annotations

import numpy as np

from estimator import dynamics as dyn
from estimator.sim.config import SimConfig


class Plant:
    """Vectorized right-hand side of one configuration."""

    def __init__(self, config: SimConfig):
        self.config = config
        self.rigid = config.base == "rigid"
        self.robot = config.robot.with_base(not self.rigid)
        self.full_robot = config.robot.with_base(True)
        self.n_links = self.robot.n_links
        self.n = self.robot.n_coords
        self.n_base = 0 if self.rigid else 3
        self.K_b, self.D_b = config.mount()
        self.has_ground = config.ground is not None
        self.n_state = 2 * self.n + (1 if self.has_ground else 0)
        c = config.controller
        self.kp, self.kd = float(c.kp), float(c.kd)
        self.pokes = tuple(p for p in config.pokes)
        self._a = dyn._angular_rows(self.full_robot)
        self.nfev = 0
        from estimator.sim.fast import FastRHS
        self.rhs1 = FastRHS(self)   # one state, plain floats: what the integrators call

    # ---------------------------------------------------------------- rigid-body terms
    def terms(self, q, dq):
        """M (B, n, n), C q̇ (B, n), G (B, n) from one evaluation of the centre-of-mass Jacobians."""
        robot = self.robot
        J, joints, coms = dyn.com_jacobians_full(robot, q)
        m = robot.masses_kg
        M = np.einsum("i,...iak,...ial->...kl", m, J, J)
        M = M + np.einsum("i,ik,il->kl", robot.inertias_kgm2, self._a, self._a)
        M[..., 0, 0] += robot.base_mass_kg
        M[..., 1, 1] += robot.base_mass_kg
        M[..., 2, 2] += robot.base_inertia_kgm2
        Jdot = dyn._com_jacobian_rates(robot, q, dq, J, joints, coms)
        dqf = dyn.to_full(robot, dq)
        acc = np.einsum("...iak,...k->...ia", Jdot, dqf)
        Cdq = np.einsum("i,...iak,...ia->...k", m, J, acc)
        g = robot.gravity_m_per_s2
        G = g * np.einsum("i,...ik->...k", m, J[..., 1, :])
        G[..., 1] += g * robot.base_mass_kg
        if self.rigid:
            return M[..., 3:, 3:], Cdq[..., 3:], G[..., 3:]
        return M, Cdq, G

    # ---------------------------------------------------------------- forces
    def control(self, t, q, dq):
        """PD torque τ = K_P (q_d − q) + K_D (q̇_d − q̇) [+ G_joint], shape (B, N)."""
        c = self.config.controller
        qd, dqd = c.reference(t)
        qj, dqj = q[..., self.n_base:], dq[..., self.n_base:]
        tau = self.kp * (qd - qj) + self.kd * (dqd - dqj)
        if c.gravity_compensation:
            tau = tau + dyn.gravity_vector(self.robot, q)[..., self.n_base:]
        return tau

    def mount_wrench(self, q, dq):
        """W = −K_b q_base − D_b q̇_base, shape (B, 3) (zeros for a rigid weld: see constraint)."""
        if self.rigid:
            return np.zeros(q.shape[:-1] + (3,))
        return -self.K_b * q[..., :3] - self.D_b * dq[..., :3]

    def poke_forces(self, t):
        """Per poke F_p(t), each of shape t.shape + (2,)."""
        return [np.asarray(p.profile(t))[..., None] * p.force_N for p in self.pokes]

    def external(self, t, q, dq, s=None):
        """Generalized external force Σ J_pᵀ F_p + J_footᵀ F_ground (B, n), ground force (B, 2), ṡ."""
        tau = np.zeros(q.shape)
        for p, F in zip(self.pokes, self.poke_forces(t)):
            if np.any(F != 0.0):
                J = dyn.point_jacobian(self.robot, q, p.link, p.alpha)
                tau += np.einsum("...ak,...a->...k", J, F)
        if not self.has_ground:
            return tau, np.zeros(q.shape[:-1] + (2,)), None
        F, ds = self.ground_force(q, dq, s)
        J = dyn.point_jacobian(self.robot, q, self.n_links, 1.0)
        tau += np.einsum("...ak,...a->...k", J, F)
        return tau, F, ds

    def ground_force(self, q, dq, s):
        """Spring-damper normal force and Dahl-type bristle friction (see config.Ground)."""
        g = self.config.ground
        foot = dyn.contact_point(self.robot, q, self.n_links, 1.0)
        J = dyn.point_jacobian(self.robot, q, self.n_links, 1.0)
        v = np.einsum("...ak,...k->...a", J, dq)
        depth = g.height_m - foot[..., 1]
        touching = depth > 0
        Fn = np.where(touching, np.maximum(0.0, g.stiffness_N_per_m * depth
                                           - g.damping_Ns_per_m * v[..., 1]), 0.0)
        s_max = g.friction_coefficient * Fn / g.tangential_stiffness_N_per_m
        vt = v[..., 0]
        ratio = np.where(s_max > 0, s / np.where(s_max > 0, s_max, 1.0), 0.0)
        ratio = np.clip(ratio, -1.0, 1.0)
        ds = np.where(Fn > 0, vt * (1.0 - np.sign(vt) * ratio), -s / 1e-3)
        Ft = np.clip(-g.tangential_stiffness_N_per_m * s, -g.friction_coefficient * Fn,
                     g.friction_coefficient * Fn)
        return np.stack([Ft, Fn], axis=-1), ds

    # ---------------------------------------------------------------- ODE
    def split(self, y):
        n = self.n
        s = y[..., 2 * n] if self.has_ground else None
        return y[..., :n], y[..., n:2 * n], s

    def rhs(self, t, y, tau_hold=None):
        """ẏ for states y (B, n_state); ``tau_hold`` (B, N) replaces the PD law (zero-order hold)."""
        self.nfev += 1
        q, dq, s = self.split(y)
        M, Cdq, G = self.terms(q, dq)
        tau_ext, _, ds = self.external(t, q, dq, s)
        tau_j = self.control(t, q, dq) if tau_hold is None else tau_hold
        gen = tau_ext - Cdq - G
        gen[..., self.n_base:] += tau_j
        if not self.rigid:
            gen[..., :3] += self.mount_wrench(q, dq)
        ddq = np.linalg.solve(M, gen[..., None])[..., 0]
        parts = [dq, ddq] + ([ds[..., None]] if ds is not None else [])
        return np.concatenate(parts, axis=-1)

    def initial_state(self, batch: int = 1) -> np.ndarray:
        """At rest at the reference posture q_d(0), base at the mount's rest position; a fixed base
        (a stiff mount the log does not record) starting still starts at its static equilibrium."""
        qd, dqd = self.config.controller.reference(0.0)
        y = np.zeros((batch, self.n_state))
        y[:, self.n_base:self.n] = qd
        y[:, self.n + self.n_base:2 * self.n] = dqd
        if self.config.base == "fixed" and not self.has_ground and not np.any(dqd):
            y[:, :self.n] = self.static_equilibrium(y[0, :self.n])
        return y

    def static_equilibrium(self, q0: np.ndarray) -> np.ndarray:
        """q with q̈ = 0 at q̇ = 0 and t = 0: W_mount(q) + τ_PD(q) + τ_ext − G(q) = 0 (Newton from
        q0). Started from the undeflected mount instead, the base rings at the mount's frequency
        (≈ 900 rad/s) for a few ms — motion a fixed-base log does not record, so the estimator
        would read it as a contact."""
        from scipy.optimize import root

        def accel(q):
            y = np.zeros((1, self.n_state))
            y[0, :self.n] = q
            return self.rhs(0.0, y)[0, self.n:2 * self.n]

        sol = root(accel, q0, method="hybr", options={"xtol": 1e-13})
        if not sol.success or not np.all(np.isfinite(sol.x)) or np.max(np.abs(accel(sol.x))) > 1e-6:
            return q0                                   # no equilibrium found: start as before
        return sol.x

    # ---------------------------------------------------------------- sampled outputs
    def constraint_wrench(self, t, q, dq, tau_j):
        """Rigid weld: W = M_bj q̈_j + (C q̇)_b + G_b − τ_ext,b (full equation's base rows)."""
        zeros = np.zeros(q.shape[:-1] + (3,))
        qf, dqf = np.concatenate([zeros, q], -1), np.concatenate([zeros, dq], -1)
        y = np.concatenate([q, dq], -1)
        if self.has_ground:
            raise NotImplementedError
        ddq = self.rhs(t, y, tau_hold=tau_j)[..., self.n:]
        full = Plant.__new__(Plant)
        full.__dict__.update(self.__dict__)
        full.robot, full.rigid = self.full_robot, False
        M, Cdq, G = full.terms(qf, dqf)
        tau_ext, _, _ = full.external(t, qf, dqf)
        return (np.einsum("...bk,...k->...b", M[..., :3, 3:], ddq) + Cdq[..., :3] + G[..., :3]
                - tau_ext[..., :3])
