"""Sensor logs: the estimator's input (DESIGN.md, "Sensor log").

CSV header ``t,x,z,theta,q1,q2,dx,dz,dtheta,dq1,dq2,tau1,tau2,Fx,Fz,My`` (q3…, dq3…, tau3… for
longer chains; a fixed-base log omits x, z, theta and their rates). SI units throughout.
In memory, coordinates are always the floating ones [x, z, θ, q_1…q_N]: a fixed-base log is
padded with a zero base, and the base wrench enters on the base rows (DESIGN.md).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class SensorLog:
    """A sampled log. Shapes: t (T,), q and dq (T, N+3), tau_Nm (T, N), wrench (T, 3)."""

    t: np.ndarray
    q: np.ndarray
    dq: np.ndarray
    tau_Nm: np.ndarray
    wrench: np.ndarray          # [Fx, Fz, My] exerted by the mount ON the base (world frame)
    floating: bool = True       # False: the log had no base columns (fixed base)

    @property
    def n_links(self) -> int:
        return self.tau_Nm.shape[1]

    @property
    def tau_meas(self) -> np.ndarray:
        """Measured generalized force [Fx, Fz, My, τ_1…τ_N], shape (T, N+3)."""
        return np.concatenate([self.wrench, self.tau_Nm], axis=1)


def log_columns(n_links: int, floating: bool = True) -> list[str]:
    """The CSV header of a log for ``n_links`` joints."""
    base = ["x", "z", "theta"] if floating else []
    qs = [f"q{i}" for i in range(1, n_links + 1)]
    rates = (["dx", "dz", "dtheta"] if floating else []) + [f"d{c}" for c in qs]
    return ["t", *base, *qs, *rates, *[f"tau{i}" for i in range(1, n_links + 1)], "Fx", "Fz", "My"]
