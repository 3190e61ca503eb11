"""Static equilibria, vectorized: the sensor readings of a leg held still under a point force.

With q̇ = q̈ = 0 the equation of motion's rows give, in floating coordinates with the base at rest
at the origin (fixed base / FT mount):

    τ_joint = G_joint(q) − J_joint(q)ᵀ F,        W = G_base(q) − J_base(q)ᵀ F,

τ the joint torques the servos hold and W the wrench the mount exerts ON the base. One call
handles any batch of postures, contact points and forces (no loop over points).
"""

from __future__ import annotations

import numpy as np

from estimator import dynamics as dyn
from estimator.robot import Robot


def static_readings(robot: Robot, q_joint_rad, link, alpha, force_N):
    """(τ (B, N), W (B, 3)) for postures q_joint (B, N), contacts (link (B,), α (B,)), F (B, 2)."""
    full = robot.with_base(True)
    q_joint = np.atleast_2d(np.asarray(q_joint_rad, float))
    B = q_joint.shape[0]
    link = np.broadcast_to(np.asarray(link, int), (B,))
    alpha = np.broadcast_to(np.asarray(alpha, float), (B,))
    force = np.broadcast_to(np.asarray(force_N, float), (B, 2))
    q = np.concatenate([np.zeros((B, 3)), q_joint], axis=1)
    G = dyn.gravity_vector(full, q)
    tau_ext = np.zeros_like(G)
    for c in np.unique(link):
        if c == 0:
            continue
        rows = link == c
        J = dyn.point_jacobian(full, q[rows], int(c), alpha[rows])
        tau_ext[rows] = np.einsum("bak,ba->bk", J, force[rows])
    gen = G - tau_ext
    return gen[:, 3:], gen[:, :3]


def static_hold_log(robot: Robot, q_joint_rad, link, alpha, force_N, sensors, hold_s: float,
                    tare_s: float = 0.0):
    """A fixed-base log holding each point for ``hold_s`` (points one after the other).

    ``tare_s`` > 0 prepends a no-load hold at the first posture (as on the bench: the estimator
    learns its noise floors from contact-free samples). Returns (SensorLog, truth dict
    t/link/alpha/Fx/Fz/px/pz, point index per sample (T,), −1 during the tare).
    """
    from estimator.log import SensorLog
    from estimator.sim.sensors import measure

    q_joint = np.atleast_2d(np.asarray(q_joint_rad, float))
    P, N = q_joint.shape
    link = np.broadcast_to(np.asarray(link, int), (P,))
    alpha = np.broadcast_to(np.asarray(alpha, float), (P,))
    force = np.broadcast_to(np.asarray(force_N, float), (P, 2))
    n_tare = int(round(tare_s * sensors.sample_rate_Hz))
    if n_tare:
        q_joint = np.concatenate([q_joint[:1], q_joint])
        link = np.concatenate([[0], link])
        alpha = np.concatenate([[np.nan], alpha])
        force = np.concatenate([np.zeros((1, 2)), force])
    tau, W = static_readings(robot, q_joint, link, alpha, force)
    per = max(1, int(round(hold_s * sensors.sample_rate_Hz)))
    idx = np.repeat(np.arange(P), per) + (1 if n_tare else 0)
    if n_tare:
        idx = np.concatenate([np.zeros(n_tare, dtype=int), idx])
    T = idx.size
    t = np.arange(T) / sensors.sample_rate_Hz
    q = np.concatenate([np.zeros((T, 3)), q_joint[idx]], axis=1)
    dq = np.zeros_like(q)
    qm, dqm, taum, Wm = measure(sensors, q, dq, tau[idx], W[idx], 3)
    qm[:, :3] = 0.0
    log = SensorLog(t=t, q=qm, dq=dqm, tau_Nm=taum, wrench=Wm, floating=False)
    full = robot.with_base(True)
    px = np.full(T, np.nan)
    pz = np.full(T, np.nan)
    for c in np.unique(link):
        if c == 0:
            continue
        rows = link[idx] == c
        pt = dyn.contact_point(full, q[rows], int(c), alpha[idx][rows])
        px[rows], pz[rows] = pt[:, 0], pt[:, 1]
    truth = {"t": t, "link": link[idx].copy(), "alpha": np.where(link[idx] > 0, alpha[idx], np.nan),
             "Fx": force[idx, 0].copy(), "Fz": force[idx, 1].copy(), "px": px, "pz": pz}
    return log, truth, idx - (1 if n_tare else 0)
