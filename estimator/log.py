"""Sensor logs: the estimator's input (docs/conventions.md, "Sensor log CSV").

CSV header ``t,x,z,theta,q1,q2,dx,dz,dtheta,dq1,dq2,tau1,tau2,Fx,Fz,My`` (q3…, dq3…, tau3… for
longer chains; a fixed-base log omits x, z, theta and their rates). SI units throughout.
In memory, coordinates are always the floating ones [x, z, θ, q_1…q_N]: a fixed-base log is
padded with a zero base, and the base wrench enters on the base rows (docs/conventions.md).
This module: the in-memory log, its columns and writing it; reading and validating a file is
estimator.log_reader.
"""

from __future__ import annotations

from dataclasses import dataclass, field

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
    source: str = "log"         # file name, for messages
    valid_mask: np.ndarray | None = None      # over the file's data rows: False = skipped (NaN/inf)
    skipped_lines: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=int))
    expected_contacts: tuple = ()   # ((link, α), …) the robot expects, e.g. ((N, 1.0),) stance foot
    timing: list | None = None      # per force channel [(kind, delay_s)] (estimator.timing); None: instant

    @property
    def n_skipped(self) -> int:
        """Rows of the file skipped for a NaN/inf field."""
        return int(len(self.skipped_lines))

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


def log_to_frame(log: SensorLog):
    """A pandas DataFrame with the columns of docs/conventions.md in order (a fixed base omits the base columns)."""
    import pandas as pd

    n = log.n_links
    base = slice(0, 3) if log.floating else slice(3, 3)
    parts = [log.t[:, None], log.q[:, base], log.q[:, 3:], log.dq[:, base], log.dq[:, 3:],
             log.tau_Nm, log.wrench]
    return pd.DataFrame(np.concatenate(parts, axis=1), columns=log_columns(n, log.floating))


def write_log(log: SensorLog, path) -> None:
    """Write a log atomically (temp file beside ``path`` + rename): Parquet for ``.parquet``,
    else CSV at full precision."""
    from pathlib import Path

    from userio.files import atomic_write

    if Path(path).suffix.lower() == ".parquet":
        atomic_write(path, lambda tmp: log_to_frame(log).to_parquet(tmp, index=False))
    else:
        atomic_write(path, lambda tmp: log_to_frame(log).to_csv(tmp, index=False, float_format="%.17g"))
