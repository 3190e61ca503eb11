"""Files of a simulated log: the sensor log CSV (docs/conventions.md format), its truth
(t,link,alpha,Fx,Fz,px,pz) and its sensor-timing declaration ``LOG.timing.toml`` (estimator.timing).

How our simulator samples its force channels (estimator.sim.core, estimator.sim.sensors): the
state is integrated and read at each sample time t_k; the joint torque is the controller's torque
at t_k (continuous control: τ(q(t_k), q̇(t_k)); zero-order hold: the value set at the tick t_k and
held over the step); the mount wrench is the spring-damper force at t_k; the sensor models add
white noise, round to encoder counts, or pass τ(t_k) through the bridge/ADC chain sample by sample
(no averaging filter, no group delay). Every channel is therefore an instantaneous value at t_k:
``instant``, which selects the observer's trapezoid quadrature.
"""

from __future__ import annotations

import io
from pathlib import Path

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


def timing_toml(log: SensorLog) -> str:
    """The ``LOG.timing.toml`` text for a log of our simulator (module doc: every force channel is
    instantaneous); a log carrying its own declaration (``log.timing``) writes that one."""
    from estimator.timing import channel_names, describe

    spec = getattr(log, "timing", None)
    lines = ["# Sensor timing of this log (estimator/timing.py, docs/conventions.md), written by",
             "# torquebench's simulator: Fx, Fz, My and tau1..tauN are instantaneous values at the",
             "# sample time t (no averaging filter, no group delay in its sensor models).",
             "[timing]"]
    if spec is None or describe(spec) == "instant":
        lines.append('default = "instant"')
    else:
        texts = [k if k != "delay" else f"delay:{d:.10g}" for k, d in spec]
        lines += [f'{name} = "{text}"' for name, text in zip(channel_names(log.n_links), texts)]
    return "\n".join(lines) + "\n"


def timing_path(log_path) -> Path:
    """``LOG.timing.toml`` beside ``LOG.csv``."""
    from estimator.timing import side_file

    return side_file(log_path)


def log_files(out, log: SensorLog, truth: dict, truth_path, noise=None) -> list[tuple[Path, str]]:
    """[(path, text)] of a simulated log: the log, its truth, its timing declaration and (with a
    NoiseModel ``noise``) its noise declaration, for userio.files.write_files_atomic (all or
    nothing)."""
    from estimator.noise import noise_side_file, noise_toml

    out = Path(out)
    files = [(out, log_csv(log)), (Path(truth_path), truth_csv(truth)),
             (timing_path(out), timing_toml(log))]
    return files + ([(noise_side_file(out), noise_toml(noise))] if noise is not None else [])
