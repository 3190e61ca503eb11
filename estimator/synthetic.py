"""Synthetic, noise-free logs built by inverse dynamics (no simulator): a prescribed motion q(t),
its analytic q̇, q̈, and the measured generalized force that realizes it under a known contact,

    τ_meas = M(q) q̈ + C(q, q̇) q̇ + G(q) − J_c(q)ᵀ F          (rows: [Fx, Fz, My, τ_1…τ_N]),

so that M q̈ + C q̇ + G = τ_meas + J_cᵀ F exactly (estimator.dynamics convention). Used by the
tests, the benchmark and the report.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from estimator import dynamics as dyn
from estimator.log import SensorLog
from estimator.robot import Robot


@dataclass
class Truth:
    """The applied contact per sample: link (0 = none), α, F (T, 2), p (T, 2)."""

    link: np.ndarray
    alpha: np.ndarray
    force_N: np.ndarray
    point_m: np.ndarray


def inverse_dynamics_log(robot: Robot, t, q, dq, ddq, link: int, alpha: float, force_N,
                         active=None, chunk: int = 65536):
    """A SensorLog realizing (q, q̇, q̈) with a contact (link, α, F) where ``active`` (T,) is True.

    q, dq, ddq in floating coordinates (T, N+3); a fixed base keeps x = z = θ = 0.
    """
    rob = robot.with_base(True)
    T = len(t)
    active = np.ones(T, bool) if active is None else np.asarray(active, bool)
    F = np.broadcast_to(np.asarray(force_N, float), (T, 2)) * active[:, None]
    tau = np.empty((T, rob.n_coords))
    point = np.empty((T, 2))
    for s in range(0, T, chunk):
        sl = slice(s, s + chunk)
        M = dyn.mass_matrix(rob, q[sl])
        C = dyn.coriolis_matrix(rob, q[sl], dq[sl])
        G = dyn.gravity_vector(rob, q[sl])
        J = dyn.point_jacobian(rob, q[sl], link, alpha)
        tau[sl] = (np.einsum("tkl,tl->tk", M, ddq[sl]) + np.einsum("tkl,tl->tk", C, dq[sl]) + G
                   - np.einsum("tak,ta->tk", J, F[sl]))
        point[sl] = dyn.contact_point(rob, q[sl], link, alpha)
    log = SensorLog(t=np.asarray(t, float), q=q, dq=dq, tau_Nm=tau[:, 3:], wrench=tau[:, :3],
                    floating=robot.floating)
    truth = Truth(link=np.where(active, link, 0), alpha=np.where(active, alpha, np.nan),
                  force_N=np.where(active[:, None], F, np.nan),
                  point_m=np.where(active[:, None], point, np.nan))
    return log, truth


def sinusoidal_motion(robot: Robot, t, q0=(0.7, -1.3), amplitude_rad=(0.35, 0.3),
                      frequency_Hz=0.5, phase_rad=(0.0, 0.8), base_amplitude=(0.0, 0.0, 0.0)):
    """q(t) = q0 + A sin(ω t + φ) per joint (and an optional base sway), with exact q̇, q̈."""
    t = np.asarray(t, float)
    N = robot.n_links
    w = 2 * np.pi * frequency_Hz
    q0 = np.resize(np.asarray(q0, float), N)
    A = np.concatenate([np.asarray(base_amplitude, float), np.resize(np.asarray(amplitude_rad, float), N)])
    ph = np.concatenate([np.zeros(3), np.resize(np.asarray(phase_rad, float), N)])
    arg = w * t[:, None] + ph
    q = A * np.sin(arg)
    q[:, 3:] += q0
    dq = A * w * np.cos(arg)
    ddq = -A * w * w * np.sin(arg)
    if not robot.floating:
        q[:, :3] = dq[:, :3] = ddq[:, :3] = 0.0
    return q, dq, ddq


def moving_leg_poke(robot: Robot, duration_s=3.0, rate_Hz=1000.0, link=2, alpha=0.5,
                    force_N=5.0 * np.array([np.cos(-np.pi / 3), np.sin(-np.pi / 3)]),
                    t_on_s=0.5, **motion):
    """The leg swinging sinusoidally with a constant poke from ``t_on_s`` to the end."""
    t = np.arange(int(round(duration_s * rate_Hz))) / rate_Hz
    q, dq, ddq = sinusoidal_motion(robot, t, **motion)
    return inverse_dynamics_log(robot, t, q, dq, ddq, link, alpha, force_N, active=t >= t_on_s)
