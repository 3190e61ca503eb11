"""CSV text of a simulated log (DESIGN.md format) and of its truth (t,link,alpha,Fx,Fz,px,pz)."""

from __future__ import annotations

import io

import numpy as np

from estimator.log import SensorLog, log_columns

TRUTH_COLUMNS = ["t", "link", "alpha", "Fx", "Fz", "px", "pz"]


def _csv(header: list[str], table: np.ndarray, fmt: list[str]) -> str:
    buf = io.StringIO()
    np.savetxt(buf, table, delimiter=",", fmt=fmt, header=",".join(header), comments="")
    return buf.getvalue().replace("nan", "nan")


def log_csv(log: SensorLog) -> str:
    """Rows t, [x, z, θ], q…, [ẋ, ż, θ̇], q̇…, τ…, Fx, Fz, My (base columns only if floating)."""
    b = 0 if log.floating else 3
    table = np.column_stack([log.t, log.q[:, b:], log.dq[:, b:], log.tau_Nm, log.wrench])
    return _csv(log_columns(log.n_links, log.floating), table, ["%.10g"] * table.shape[1])


def truth_csv(truth: dict) -> str:
    table = np.column_stack([truth[c] for c in TRUTH_COLUMNS])
    fmt = ["%.10g", "%d"] + ["%.10g"] * 5
    return _csv(TRUTH_COLUMNS, table, fmt)
