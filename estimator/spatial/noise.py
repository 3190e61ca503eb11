"""The residual's no-contact covariance for any RobotModel (here: a URDF robot), and the
chi-square detector's pieces.

As estimator.noise for the planar chain: sensor noise e_k enters the step drive as
d_k = B0 e_{k+1} + B1 e_k (linearized at the posture), and the exact observer's stationary
covariance is R_ij = b_i b_j (S0_ij + a_j S1_ij + a_i S1_ji) / (1 − a_i a_j) with S0 = B0B0ᵀ +
B1B1ᵀ, S1 = B1B0ᵀ (σ folded into B). Channels: the six FT wrench components (sensor frame; they
reach the base rows through the posture-dependent map of ``UrdfModel.base_rows_from_ft``), the
sensed joint torques, joint-rate noise and encoder quantization (∂P/∂q̇, ∂u/∂q̇, ∂P/∂q, ∂u/∂q of
the joint coordinates by central differences of ``momentum_terms``; the base pose and twist are
taken as exact). Only the rows that are equations (``observer.used_rows``) are kept.
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


def filter_terms(model, q, v, noise: SpatialNoise, gain_per_s, dt_s: float, timing=None):
    """(a, b, B0, B1): a, b (nv,), B0, B1 (B, nv, m) of d_k = B0 e_{k+1} + B1 e_k (module doc)."""
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
    return a, b, np.concatenate(blocks0, axis=2), np.concatenate(blocks1, axis=2)


def residual_covariance(model, q, v, noise: SpatialNoise, gain_per_s, dt_s: float, timing=None):
    """No-contact covariance of the residual's used rows, (B, n_used, n_used)."""
    a, b, B0, B1 = filter_terms(model, q, v, noise, gain_per_s, dt_s, timing)
    rows = used_rows(model)
    a, b, B0, B1 = a[rows], b[rows], B0[:, rows], B1[:, rows]
    S0 = B0 @ B0.transpose(0, 2, 1) + B1 @ B1.transpose(0, 2, 1)
    S1 = B1 @ B0.transpose(0, 2, 1)
    num = S0 + S1 * a[None, None, :] + S1.transpose(0, 2, 1) * a[None, :, None]
    return np.outer(b, b) * num / (1.0 - np.outer(a, a))


def default_noise(model, source="default noise (τ σ 0.005 N·m, FT σ 0.1 N, 0.01 N·m)") -> SpatialNoise:
    """The paper leg's sensors: joint torque σ 0.005 N·m, force σ 0.1 N, moment σ 0.01 N·m."""
    from estimator.spatial.logs import make_noise

    return make_noise(0.005, [0.1, 0.01], int(sum(model.sensed_joints)), source=source)
