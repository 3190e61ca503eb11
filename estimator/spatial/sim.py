"""A simulator for URDF robots: a test rig's base on mount springs (or welded), PD-tracked joint
trajectories, pokes at points on link surfaces, sensors sampled with declared noise.

Rigid-body dynamics by pinocchio (ABA; RK4 with ``substeps`` steps per sample, on the Lie group
through ``pinocchio.integrate``):

* floating: the mount is a spring-damper between the world and the FT sensor frame at its rest
  pose: f = −R₀(K_p ∘ R₀ᵀ(p_s − p_s0) + D_p ∘ R₀ᵀṗ_s), m = −R₀(K_r ∘ log(R₀ᵀR_s) + D_r ∘ R₀ᵀω_s)
  at the sensor origin (world axes); the sensor reads that wrench in its own frame.
* fixed: the base is held at the mount pose; the joints follow M_jj q̈ = τ + τ_ext − h (joint
  rows) and the sensor reads the constraint wrench, the base rows of M a + h − τ_ext.

A poke is a force F (world) at a point on a link (link frame), on for [t_on, t_off) with an
optional smooth ramp; its generalized force is J_pᵀF. Every channel is read at the sample time
(timing "instant"); the truth per sample is the applied force and point.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from userio.errors import InputError
from estimator.spatial.logs import SpatialLog, SpatialNoise
from estimator.spatial.robot import SpatialRobot


@dataclass(frozen=True)
class Poke:
    link: str                    # URDF link name
    point_m: np.ndarray          # in the link frame
    force_N: np.ndarray          # world frame, ON the robot
    t_on_s: float
    t_off_s: float
    ramp_s: float = 0.0

    def scale(self, t: float) -> float:
        if t < self.t_on_s or t >= self.t_off_s:
            return 0.0
        if self.ramp_s <= 0:
            return 1.0
        x = min((t - self.t_on_s) / self.ramp_s, (self.t_off_s - t) / self.ramp_s, 1.0)
        return x * x * (3 - 2 * x)


@dataclass
class SimSpec:
    duration_s: float = 1.0
    sample_rate_Hz: float = 1000.0
    substeps: int = 10
    q0_rad: np.ndarray | None = None          # joint set points (default 0)
    kp: float = 60.0                          # N·m/rad (N/m for prismatic)
    kd: float = 1.5
    amplitude_rad: np.ndarray | None = None   # sine tracking amplitude per joint (default 0)
    frequency_Hz: float = 1.0
    pokes: list = field(default_factory=list)
    noise: SpatialNoise | None = None
    seed: int = 0
    start_at_rest: bool = True                # start from the static equilibrium (no transient)


RAMP_S = 0.25          # the sine trajectory's smooth start


def _log3(R):
    import pinocchio as pin

    return np.array(pin.log3(R))


class _Sim:
    def __init__(self, robot: SpatialRobot, spec: SimSpec):
        import pinocchio as pin

        self.pin, self.robot, self.spec = pin, robot, spec
        self.model = robot.model
        self.data = self.model.createData()
        n = robot.n_joints
        self.n = n
        self.q0 = np.zeros(n) if spec.q0_rad is None else np.asarray(spec.q0_rad, float)
        self.amp = np.zeros(n) if spec.amplitude_rad is None else np.asarray(spec.amplitude_rad, float)
        if self.q0.shape != (n,) or self.amp.shape != (n,):
            raise InputError(f"simulation: q0_rad and amplitude_rad need {n} values (joints "
                             f"{', '.join(robot.joint_names)})")
        self.fid = self.model.getFrameId(robot.ft_frame)
        Rbs, pbs = robot.ft_placement()
        self.X_bs = pin.SE3(Rbs, pbs)
        R0, p0 = robot.mount_pose()
        self.M_s0 = pin.SE3(R0, p0) * self.X_bs          # rest pose of the sensor frame
        self.pokes = []
        for pk in spec.pokes:
            if not self.model.existFrame(pk.link):
                raise InputError(f"poke: no link '{pk.link}' in {robot.source}")
            fr = self.model.frames[self.model.getFrameId(pk.link)]
            self.pokes.append((pk, fr.parentJoint, fr.placement.act(np.asarray(pk.point_m, float))))

    def reference(self, t):
        """q0 + e(t) A sin(ωt) with a smooth envelope e (0 → 1 over ``RAMP_S``), so that the
        set point starts at rest from the static equilibrium (no start-up transient)."""
        w = 2 * np.pi * self.spec.frequency_Hz
        x = min(t / RAMP_S, 1.0)
        e, de = x * x * (3 - 2 * x), (6 * x * (1 - x) / RAMP_S if x < 1 else 0.0)
        return (self.q0 + e * self.amp * np.sin(w * t),
                self.amp * (de * np.sin(w * t) + e * w * np.cos(w * t)))

    def joint_torque(self, q, v, t):
        qr, dqr = self.reference(t)
        return self.spec.kp * (qr - q[7:]) + self.spec.kd * (dqr - v[6:])

    def external(self, q, t):
        """τ_ext (pinocchio coordinates) of the pokes on at t, and their (link, point, force)."""
        pin, model, data = self.pin, self.model, self.data
        tau = np.zeros(model.nv)
        active = None
        for pk, j, p_joint in self.pokes:
            s = pk.scale(t)
            if s == 0.0:
                continue
            oMi = data.oMi[j]
            p_w = oMi.act(p_joint)
            J = pin.getJointJacobian(model, data, j, pin.LOCAL_WORLD_ALIGNED)
            Jp = J[:3] + _skew(oMi.translation - p_w) @ J[3:]      # v_p = v_o + ω × (p − o)
            F = s * np.asarray(pk.force_N, float)
            tau += Jp.T @ F
            active = (pk.link, np.asarray(pk.point_m, float), p_w, F)
        return tau, active

    def mount(self, q, v):
        """The spring-damper wrench ON the robot at the sensor origin, world axes (f, m)."""
        pin, model, data = self.pin, self.model, self.data
        M_s = data.oMf[self.fid]
        R0 = self.M_s0.rotation
        dp = M_s.translation - self.M_s0.translation
        vel = pin.getFrameVelocity(model, data, self.fid, pin.LOCAL_WORLD_ALIGNED)
        K, D = self.robot.mount_stiffness, self.robot.mount_damping
        f = -R0 @ (K[:3] * (R0.T @ dp) + D[:3] * (R0.T @ np.array(vel.linear)))
        m = -R0 @ (K[3:] * _log3(R0.T @ M_s.rotation) + D[3:] * (R0.T @ np.array(vel.angular)))
        return f, m

    def accel(self, q, v, t):
        """(a, sensor-frame wrench, joint torques, active poke) at (q, v) pinocchio coordinates."""
        pin, model, data = self.pin, self.model, self.data
        pin.forwardKinematics(model, data, q, v)
        pin.updateFramePlacements(model, data)
        pin.computeJointJacobians(model, data, q)
        tau_j = self.joint_torque(q, v, t)
        tau_ext, active = self.external(q, t)
        if self.robot.floating:
            f, m = self.mount(q, v)
            Jf = pin.getFrameJacobian(model, data, self.fid, pin.LOCAL_WORLD_ALIGNED)
            tau = tau_ext + Jf.T @ np.concatenate((f, m))
            tau[6:] += tau_j
            a = pin.aba(model, data, q, v, tau)
            R_s = data.oMf[self.fid].rotation
            wrench = np.concatenate((R_s.T @ f, R_s.T @ m))
        else:
            M = pin.crba(model, data, q)
            M = np.triu(M) + np.triu(M, 1).T
            h = pin.nonLinearEffects(model, data, q, v)
            a = np.zeros(model.nv)
            a[6:] = np.linalg.solve(M[6:, 6:], tau_j + tau_ext[6:] - h[6:])
            w_b = (M @ a + h - tau_ext)[:6]                # the mount's wrench ON the base (base frame)
            ws = self.X_bs.actInv(pin.Force(w_b[:3], w_b[3:]))
            wrench = np.concatenate((ws.linear, ws.angular))
        return a, wrench, tau_j, active

    def equilibrium(self, q):
        """The static equilibrium near q (PD set points at t = 0, no poke): Newton on the
        tangent space, g(q) = τ_mount + τ_PD, with a finite-difference Jacobian."""
        pin, model = self.pin, self.model
        nv = model.nv
        free = np.arange(nv) if self.robot.floating else np.arange(6, nv)
        pokes, self.pokes = self.pokes, []

        def f(dx):
            qq = pin.integrate(model, q, dx)
            a = self.accel(qq, np.zeros(nv), 0.0)[0]
            return a[free]

        dx = np.zeros(nv)
        for _ in range(20):
            r = f(dx)
            if np.abs(r).max() < 1e-10:
                break
            J = np.empty((len(free), len(free)))
            for i, c in enumerate(free):
                e = np.zeros(nv)
                e[c] = 1e-7
                J[:, i] = (f(dx + e) - r) / 1e-7
            dx[free] -= np.linalg.solve(J, r)
        self.pokes = pokes
        return pin.integrate(model, q, dx)

    def run(self):
        pin, model = self.pin, self.model
        spec = self.spec
        dt_s = 1.0 / spec.sample_rate_Hz
        T = int(round(spec.duration_s * spec.sample_rate_Hz)) + 1
        h = dt_s / spec.substeps
        q = self.robot.rest_q()
        q[7:] = self.reference(0.0)[0]
        if spec.start_at_rest:
            q = self.equilibrium(q)
        v = np.zeros(model.nv)
        v[6:] = self.reference(0.0)[1]
        n = self.n
        out_q, out_v = np.empty((T, model.nq)), np.empty((T, model.nv))
        out_tau, out_w = np.empty((T, n)), np.empty((T, 6))
        truth = []
        fixed = not self.robot.floating
        for k in range(T):
            t = k * dt_s
            a, wrench, tau_j, active = self.accel(q, v, t)
            R = _quat_R(q[3:7])
            out_q[k] = q
            out_v[k, :3], out_v[k, 3:] = R @ v[:3], v[3:]
            out_tau[k], out_w[k] = tau_j, wrench
            truth.append((t, active))
            if k == T - 1:
                break
            for i in range(spec.substeps):
                ts = t + i * h
                k1v, k1a = v, a if i == 0 else self.accel(q, v, ts)[0]
                q2 = pin.integrate(model, q, 0.5 * h * k1v)
                k2v = v + 0.5 * h * k1a
                k2a = self.accel(q2, k2v, ts + 0.5 * h)[0]
                q3 = pin.integrate(model, q, 0.5 * h * k2v)
                k3v = v + 0.5 * h * k2a
                k3a = self.accel(q3, k3v, ts + 0.5 * h)[0]
                q4 = pin.integrate(model, q, h * k3v)
                k4v = v + h * k3a
                k4a = self.accel(q4, k4v, ts + h)[0]
                q = pin.integrate(model, q, h / 6 * (k1v + 2 * k2v + 2 * k3v + k4v))
                v = v + h / 6 * (k1a + 2 * k2a + 2 * k3a + k4a)
                if fixed:
                    q[:7], v[:6] = self.robot.rest_q()[:7], 0.0
        return out_q, out_v, out_tau, out_w, truth, dt_s


def _skew(a):
    return np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])


def _quat_R(quat):
    from estimator.spatial.tree import quat_matrix

    return quat_matrix(np.asarray(quat, float))


def simulate(robot: SpatialRobot, spec: SimSpec):
    """(SpatialLog, truth DataFrame, noise or None). The log's torques are zero on unsensed joints
    (no column is written for them); noise is drawn with ``spec.noise`` and ``spec.seed`` (the
    base state's last: orientation R exp([δθ]×), ṗ and ω; the truth is the noise-free state)."""
    import pandas as pd

    q, v, tau, wrench, truth, dt = _Sim(robot, spec).run()
    T = len(q)
    t = np.arange(T) * dt
    tau = tau * np.asarray(robot.sensed, float)
    if spec.noise is not None:
        rng = np.random.default_rng(spec.seed)
        sens = np.flatnonzero(robot.sensed)
        tau[:, sens] += rng.normal(size=(T, len(sens))) * spec.noise.torque_sigma_Nm
        wrench = wrench + rng.normal(size=(T, 6)) * spec.noise.ft_sigma
        if spec.noise.velocity_sigma_rad_per_s > 0:
            v[:, 6:] += rng.normal(size=(T, robot.n_joints)) * spec.noise.velocity_sigma_rad_per_s
        sig_b = spec.noise.base_sigma
        if robot.floating and np.any(sig_b > 0):      # the measured base state (SpatialNoise)
            from estimator.spatial.noise import quat_times_exp

            e = rng.normal(size=(T, 9)) * sig_b
            q[:, 3:7] = quat_times_exp(q[:, 3:7], e[:, :3])
            v[:, :6] += e[:, 3:]
    log = SpatialLog(t=t, q=q, v=v, tau_Nm=tau, wrench=wrench, floating=robot.floating,
                     source="simulation")
    log.period_s = dt
    rows = []
    for tk, act in truth:
        if act is None:
            rows.append((tk, "", *[np.nan] * 9))
        else:
            link, pl, pw, F = act
            rows.append((tk, link, *pl, *pw, *F))
    frame = pd.DataFrame(rows, columns=TRUTH_COLUMNS)
    return log, frame, spec.noise


TRUTH_COLUMNS = ["t", "link", "lx", "ly", "lz", "px", "py", "pz", "Fx", "Fy", "Fz"]
