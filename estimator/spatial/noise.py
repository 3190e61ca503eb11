"""The residual's no-contact covariance for any RobotModel (here: a URDF robot), and the
chi-square detector's pieces.

As estimator.noise for the planar chain: sensor noise e_k enters the step drive as
d_k = B0 e_{k+1} + B1 e_k (linearized at the posture), and the exact observer's stationary
covariance is R_ij = b_i b_j (S0_ij + a_j S1_ij + a_i S1_ji) / (1 − a_i a_j) with S0 = B0B0ᵀ +
B1B1ᵀ, S1 = B1B0ᵀ (σ folded into B). Channels: the six FT wrench components (sensor frame; they
reach the base rows through the posture-dependent map of ``UrdfModel.base_rows_from_ft``), the
sensed joint torques, joint-rate noise and encoder quantization (∂P/∂q̇, ∂u/∂q̇, ∂P/∂q, ∂u/∂q of
the joint coordinates by central differences of ``momentum_terms``) and, on a floating base, the
measured base state (``base_jacobians``). Only the rows that are equations
(``observer.used_rows``) are kept.

Base state noise (white, per sample; SpatialNoise.base_sigma): x = [δθ, δṗ, δω], the orientation
error a rotation vector in the base frame (R_meas = R exp([δθ]×)), ṗ in the world, ω in the base
frame. It enters P = M v (∂P/∂ṗ, ∂P/∂ω: the mass matrix's base columns; ∂P/∂θ: the bodies'
world velocities turn with R) and u = τ_meas + Cᵀv − G: the FT force row f_w = R f_b turns with
the orientation error (∂f_w/∂δθ = −R [f_b]×, so the measured wrench is a linearization point,
``wrench``), and Cᵀv, G through the posture and the twist. As for the joints:
B0 += (∂P/∂x/Δt − ½ ∂u/∂x) diag σ_x, B1 += (−∂P/∂x/Δt − ½ ∂u/∂x) diag σ_x, the derivatives by
central differences on the manifold (checked against pinocchio's mass matrix and gravity
derivatives in tests/test_spatial_base_noise.py). The base position enters nothing:
∂P/∂p = ∂u/∂p = 0 (every position is relative to p; uniform gravity).
"""

from __future__ import annotations

import numpy as np

from estimator import observer as obs
from estimator.spatial.logs import SpatialNoise
from estimator.spatial.observer import gains, used_rows


def _joint_jacobians(model, q, v, h=1e-6):
    """∂P/∂x, ∂u/∂x for x = joint rates (which=1) and joint angles (which=0): (B, nv, n) each."""
    B = len(q)
    n = len(model.joint_names)
    out = {}
    for which, arr in ((0, q), (1, v)):
        off = 7 if which == 0 else 6
        qq = np.repeat(q[:, None], 2 * n, axis=1)
        vv = np.repeat(v[:, None], 2 * n, axis=1)
        tgt = qq if which == 0 else vv
        for i in range(n):
            tgt[:, i, off + i] += h
            tgt[:, n + i, off + i] -= h
        P, u = model.momentum_terms(qq.reshape(B * 2 * n, -1), vv.reshape(B * 2 * n, -1),
                                    np.zeros((B * 2 * n, model.n_v)))
        P, u = P.reshape(B, 2 * n, -1), u.reshape(B, 2 * n, -1)
        out[which] = (((P[:, :n] - P[:, n:]) / (2 * h)).transpose(0, 2, 1),
                      ((u[:, :n] - u[:, n:]) / (2 * h)).transpose(0, 2, 1))
    return out[0], out[1]


def quat_times_exp(quat, dtheta):
    """quat ⊗ exp(δθ/2) (x, y, z, w): the orientation turned by δθ (base frame), (B, 4)."""
    quat = np.atleast_2d(quat)
    dtheta = np.atleast_2d(dtheta)
    ang = np.linalg.norm(dtheta, axis=1, keepdims=True)
    axis = np.divide(dtheta, ang, out=np.zeros_like(dtheta), where=ang > 0)
    d = np.c_[axis * np.sin(ang / 2), np.cos(ang / 2)]
    x1, y1, z1, w1 = quat.T
    x2, y2, z2, w2 = d.T
    return np.stack([w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2, w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
                     w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2, w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2], axis=1)


def static_wrench(model, q, v) -> np.ndarray:
    """The FT wrench (sensor frame) that holds the robot with no contact and Ṗ = 0: τ_base = −u
    (the base rows of u at τ = 0), (B, 6); the linearization point when no measurement is given."""
    q = np.atleast_2d(q)
    _, u0 = model.momentum_terms(q, np.atleast_2d(v), np.zeros((len(q), model.n_v)))
    return model.ft_from_base_rows(q, -u0[:, :6])


def base_jacobians(model, q, v, wrench=None, h=1e-6):
    """∂P/∂x, ∂u/∂x for x = [δθ (base frame), ṗ (world), ω (base frame)]: (B, nv, 9) each, by
    central differences (module doc); ``wrench`` (B, 6) the measured FT wrench (sensor frame;
    default ``static_wrench``), held fixed while the orientation turns its force row."""
    q = np.atleast_2d(np.asarray(q, float))
    v = np.atleast_2d(np.asarray(v, float))
    B, nv = len(q), model.n_v
    w = static_wrench(model, q, v) if wrench is None else np.atleast_2d(np.asarray(wrench, float))
    qq = np.repeat(q[:, None], 18, axis=1)
    vv = np.repeat(v[:, None], 18, axis=1)
    E = np.eye(3) * h
    for i in range(3):
        qq[:, i, 3:7] = quat_times_exp(q[:, 3:7], np.broadcast_to(E[i], (B, 3)))
        qq[:, 9 + i, 3:7] = quat_times_exp(q[:, 3:7], np.broadcast_to(-E[i], (B, 3)))
    for i in range(6):
        vv[:, 3 + i, i] += h
        vv[:, 12 + i, i] -= h
    qf, vf = qq.reshape(B * 18, -1), vv.reshape(B * 18, -1)
    tau = np.zeros((B * 18, nv))
    tau[:, :6] = model.base_rows_from_ft(qf, np.repeat(w, 18, axis=0))
    P, u = model.momentum_terms(qf, vf, tau)
    P, u = P.reshape(B, 18, nv), u.reshape(B, 18, nv)
    return (((P[:, :9] - P[:, 9:]) / (2 * h)).transpose(0, 2, 1),
            ((u[:, :9] - u[:, 9:]) / (2 * h)).transpose(0, 2, 1))


def filter_terms(model, q, v, noise: SpatialNoise, gain_per_s, dt_s: float, timing=None,
                 wrench=None):
    """(a, b, B0, B1): a, b (nv,), B0, B1 (B, nv, m) of d_k = B0 e_{k+1} + B1 e_k (module doc);
    ``wrench``: the measured FT wrench at each posture (base-state noise only; default: static)."""
    q = np.atleast_2d(np.asarray(q, float))
    v = np.atleast_2d(np.asarray(v, float))
    Bn, nv = len(q), model.n_v
    n = len(model.joint_names)
    K = gains(model, gain_per_s)
    a, b = obs.coefficients(K, dt_s, "exact")
    mean = np.zeros(nv, bool) if timing is None else np.array([k == "mean" for k, _ in timing])
    c1 = np.where(mean, 1.0, 0.5)
    c0 = np.where(mean, 0.0, 0.5)
    # FT channels → base rows (linear in the wrench: the map's columns at each posture)
    Bft = model.ft_map(q)
    sens = np.flatnonzero(model.sensed_joints)
    blocks0, blocks1 = [], []
    W = np.zeros((Bn, nv, 6))
    W[:, :6] = Bft * noise.ft_sigma
    blocks0.append(-c1[None, :, None] * W)
    blocks1.append(-c0[None, :, None] * W)
    Tj = np.zeros((nv, len(sens)))
    Tj[6 + sens, np.arange(len(sens))] = noise.torque_sigma_Nm
    blocks0.append(np.broadcast_to(-c1[:, None] * Tj, (Bn, nv, len(sens))))
    blocks1.append(np.broadcast_to(-c0[:, None] * Tj, (Bn, nv, len(sens))))
    sig_v = noise.velocity_sigma_rad_per_s
    sig_q = (2 * np.pi / noise.encoder_counts) / np.sqrt(12) if noise.encoder_counts else 0.0
    if sig_v > 0 or sig_q > 0:
        (JPq, Juq), (JPv, Juv) = _joint_jacobians(model, q, v)
        for sig, JP, Ju in ((sig_v, JPv, Juv), (sig_q, JPq, Juq)):
            if sig > 0:
                blocks0.append((JP / dt_s - 0.5 * Ju) * sig)
                blocks1.append((-JP / dt_s - 0.5 * Ju) * sig)
    sig_b = noise.base_sigma
    if np.any(sig_b > 0) and model.robot.floating:
        keep = np.flatnonzero(sig_b > 0)
        JP, Ju = base_jacobians(model, q, v, wrench)
        JP, Ju = JP[:, :, keep], Ju[:, :, keep]
        blocks0.append((JP / dt_s - 0.5 * Ju) * sig_b[keep])
        blocks1.append((-JP / dt_s - 0.5 * Ju) * sig_b[keep])
    return a, b, np.concatenate(blocks0, axis=2), np.concatenate(blocks1, axis=2)


def residual_moments(model, q, v, noise: SpatialNoise, gain_per_s, dt_s: float, timing=None,
                     wrench=None):
    """(R, Ω) on the used rows, each (B, n_used, n_used): the residual's no-contact covariance
    (module doc) and its drive's long-run covariance Ω = S0 + S1 + S1ᵀ (the drive
    x_k = (r_k − A r_{k−1})/b = d_{k−1}: lag-zero S0, lag-one S1 = Cov(x_k, x_{k−1});
    estimator.bounds.ResidualNoise, what the release test weighs with)."""
    a, b, B0, B1 = filter_terms(model, q, v, noise, gain_per_s, dt_s, timing, wrench)
    rows = used_rows(model)
    a, b, B0, B1 = a[rows], b[rows], B0[:, rows], B1[:, rows]
    S0 = B0 @ B0.transpose(0, 2, 1) + B1 @ B1.transpose(0, 2, 1)
    S1 = B1 @ B0.transpose(0, 2, 1)
    num = S0 + S1 * a[None, None, :] + S1.transpose(0, 2, 1) * a[None, :, None]
    return np.outer(b, b) * num / (1.0 - np.outer(a, a)), S0 + S1 + S1.transpose(0, 2, 1)


def residual_covariance(model, q, v, noise: SpatialNoise, gain_per_s, dt_s: float, timing=None,
                        wrench=None):
    """No-contact covariance of the residual's used rows, (B, n_used, n_used)."""
    return residual_moments(model, q, v, noise, gain_per_s, dt_s, timing, wrench)[0]


def default_noise(model, source="default noise (τ σ 0.005 N·m, FT σ 0.1 N, 0.01 N·m)") -> SpatialNoise:
    """The paper leg's sensors: joint torque σ 0.005 N·m, force σ 0.1 N, moment σ 0.01 N·m."""
    from estimator.spatial.logs import make_noise

    return make_noise(0.005, [0.1, 0.01], int(sum(model.sensed_joints)), source=source)
