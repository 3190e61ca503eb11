"""The 3-D sensor log: column contract, chunked CSV/Parquet reader, writer, timing and noise
declarations (docs/conventions.md, "3-D sensor log").

Columns (SI units, one row per sample):

    t
    x, y, z, qx, qy, qz, qw          base position (world) and orientation (unit quaternion,
                                     base → world)                      [floating base only]
    q_<joint>                         joint positions, URDF names, pinocchio's order
    vx, vy, vz, wx, wy, wz           base velocity ṗ (world) and angular velocity ω (base frame,
                                     what a gyro on the base reads)     [floating base only]
    dq_<joint>                        joint rates
    tau_<joint>                       measured joint torques, sensed joints only
    Fx, Fy, Fz, Mx, My, Mz           the wrench ON the robot at the FT sensor, in the sensor frame
                                     (moment about the sensor origin)

A fixed-base log omits the base columns: the base is at the declaration's mount pose, at rest.
The reader reuses estimator.log_reader's block parsers (pyarrow / pandas, the same rules for NaN rows,
time order, irregular steps) and yields ``SpatialLog`` chunks.
"""

from __future__ import annotations

import difflib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from userio.errors import InputError
from estimator.log_parsing import file_line
from estimator.log_reader import DEFAULT_CHUNK_SAMPLES, LogReader, check_steps_numpy, rows_to_lines

BASE_POSE = ["x", "y", "z", "qx", "qy", "qz", "qw"]
BASE_TWIST = ["vx", "vy", "vz", "wx", "wy", "wz"]
WRENCH = ["Fx", "Fy", "Fz", "Mx", "My", "Mz"]


def spatial_columns(joints, sensed, floating: bool = True) -> list[str]:
    """The header of a 3-D log for these joints (``sensed``: which carry a torque column)."""
    return (["t"] + (BASE_POSE if floating else []) + [f"q_{j}" for j in joints]
            + (BASE_TWIST if floating else []) + [f"dq_{j}" for j in joints]
            + [f"tau_{j}" for j, s in zip(joints, sensed) if s] + WRENCH)


@dataclass
class SpatialLog:
    """Shapes: t (T,), q (T, 7 + n), v (T, 6 + n), tau_Nm (T, n) (0 on unsensed joints),
    wrench (T, 6) ON the robot in the FT sensor frame."""

    t: np.ndarray
    q: np.ndarray
    v: np.ndarray
    tau_Nm: np.ndarray
    wrench: np.ndarray
    floating: bool = True
    source: str = "log"
    timing: list | None = None          # per observer row [(kind, delay_s)], None: instant
    skipped_lines: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=int))

    @property
    def n_skipped(self) -> int:
        return int(len(self.skipped_lines))

    def tau_meas(self, model) -> np.ndarray:
        """[base rows from the FT wrench (UrdfModel.base_rows_from_ft), joint torques], (T, nv)."""
        return np.concatenate([model.base_rows_from_ft(self.q, self.wrench), self.tau_Nm], axis=1)

    def slice(self, sl) -> "SpatialLog":
        return SpatialLog(self.t[sl], self.q[sl], self.v[sl], self.tau_Nm[sl], self.wrench[sl],
                          self.floating, self.source, self.timing)


def _check_header(names, robot, source):
    joints = robot.joint_names
    floating = any(c in names for c in BASE_POSE + BASE_TWIST)
    expected = spatial_columns(joints, robot.sensed, floating)
    known = set(spatial_columns(joints, [True] * len(joints), True))
    for col in expected:
        if col not in names:
            extra = [c for c in names if c not in known]
            hint = difflib.get_close_matches(col, extra, n=1, cutoff=0.6)
            did = f" (found '{hint[0]}': misspelled?)" if hint else ""
            raise InputError(f"{source}: line 1: missing column '{col}'{did}; the robot's joints "
                             f"are {', '.join(joints)}; expected header {','.join(expected)}")
    for c in names:
        for pre in ("q_", "dq_", "tau_"):
            if c.startswith(pre) and c[len(pre):] not in joints:
                raise InputError(f"{source}: line 1: column '{c}': '{c[len(pre):]}' is not a "
                                 f"joint of the robot ({', '.join(joints)})")
    return expected, floating


class SpatialLogReader(LogReader):
    """A 3-D log read in chunks (estimator.log_reader.LogReader's parsers and checks, the 3-D columns)."""

    def __init__(self, path, robot, model, chunk_samples: int | None = DEFAULT_CHUNK_SAMPLES,
                 max_jitter: float = 0.01):
        path = Path(path)
        self.path, self.source = path, str(path)
        if not path.exists():
            raise InputError(f"{self.source}: no such file")
        if path.is_dir():
            raise InputError(f"{self.source}: is a directory, expected a CSV log")
        if chunk_samples is not None and (int(chunk_samples) != chunk_samples or chunk_samples < 1):
            raise InputError(f"chunk size: must be a whole number of samples ≥ 1, got {chunk_samples}")
        self.robot, self.model = robot, model
        self.chunk_samples = chunk_samples
        self.parquet = path.suffix.lower() == ".parquet"
        self.max_jitter = max_jitter
        self.names = self._parquet_names() if self.parquet else self._csv_names()
        self.cols, self.floating = _check_header(self.names, robot, self.source)
        self.timing = read_timing(path, robot)
        self.n_rows = self.n_samples = self.n_skipped = 0
        self.skipped_lines = np.zeros(0, dtype=int)
        self.period_s = None
        self._last = None
        self.keep_valid_mask = False
        self.valid_masks = []

    def _validate(self, values):
        from estimator.observer import regular_period

        row0 = self.n_rows
        self.n_rows += len(values)
        valid = np.all(np.isfinite(values), axis=1)
        bad = np.flatnonzero(~valid)
        if bad.size:
            self.n_skipped += bad.size
            self.skipped_lines = np.concatenate([self.skipped_lines, rows_to_lines(row0 + bad)])[:1000]
        if not valid.any():
            return None
        data = values[valid] if bad.size else values
        rows = row0 + np.flatnonzero(valid)
        t = np.ascontiguousarray(data[:, 0])
        T, n = len(t), self.robot.n_joints
        col = {c: i for i, c in enumerate(self.cols)}
        q = np.empty((T, 7 + n))
        v = np.zeros((T, 6 + n))
        if self.floating:
            q[:, :7] = data[:, [col[c] for c in BASE_POSE]]
            v[:, :6] = data[:, [col[c] for c in BASE_TWIST]]
            norm = np.linalg.norm(q[:, 3:7], axis=1)
            off = np.flatnonzero(np.abs(norm - 1) > 1e-3)
            if off.size:
                k = off[0]
                raise InputError(f"{self.source}: line {file_line(rows[k])}: the base quaternion "
                                 f"(qx, qy, qz, qw) has norm {norm[k]:.6g}, expected 1")
        else:
            q[:, :7] = self.robot.rest_q()[:7]
        j = self.robot.joint_names
        q[:, 7:] = data[:, [col[f"q_{name}"] for name in j]]
        v[:, 6:] = data[:, [col[f"dq_{name}"] for name in j]]
        tau = np.zeros((T, n))
        for i, (name, s) in enumerate(zip(j, self.robot.sensed)):
            if s:
                tau[:, i] = data[:, col[f"tau_{name}"]]
        wrench = data[:, [col[c] for c in WRENCH]]
        if self.period_s is None:
            tt = t if self._last is None else np.r_[self._last[0], t]
            self.period_s = regular_period(tt)
        kind, k = check_steps_numpy(t, rows, self._last, self.period_s, self.max_jitter,
                               self._last is not None or len(t) > 2)
        if kind:
            tt = t if self._last is None else np.r_[self._last[0], t]
            rr = rows if self._last is None else np.r_[self._last[1], rows]
            what = "does not increase" if kind == 1 else "is an irregular step"
            raise InputError(f"{self.source}: line {file_line(rr[k + 1])}, column 't': time {tt[k + 1]:g} s "
                             f"{what} (previous sample {tt[k]:g} s; period {self.period_s:.6g} s)")
        self._last = (t[-1], rows[-1])
        self.n_samples += T
        log = SpatialLog(t=t, q=q, v=v, tau_Nm=tau, wrench=np.ascontiguousarray(wrench),
                         floating=self.floating, source=self.source, timing=self.timing)
        log.row0, log.period_s = int(row0), self.period_s
        return log

    def finish(self) -> list[str]:
        return []


def read_spatial_log(path, robot, model) -> SpatialLog:
    """The whole log as one SpatialLog."""
    reader = SpatialLogReader(path, robot, model, chunk_samples=None)
    parts = list(reader)
    log = parts[0] if len(parts) == 1 else _concat(parts)
    log.skipped_lines = reader.skipped_lines
    log.period_s = reader.period_s
    return log


def _concat(parts):
    cat = lambda f: np.concatenate([getattr(p, f) for p in parts])  # noqa: E731
    return SpatialLog(cat("t"), cat("q"), cat("v"), cat("tau_Nm"), cat("wrench"), parts[0].floating,
                      parts[0].source, parts[0].timing)


def log_frame(log: SpatialLog, robot):
    """A pandas DataFrame in the column contract's order."""
    import pandas as pd

    j = robot.joint_names
    cols = {"t": log.t}
    if log.floating:
        cols.update({c: log.q[:, i] for i, c in enumerate(BASE_POSE)})
    cols.update({f"q_{n}": log.q[:, 7 + i] for i, n in enumerate(j)})
    if log.floating:
        cols.update({c: log.v[:, i] for i, c in enumerate(BASE_TWIST)})
    cols.update({f"dq_{n}": log.v[:, 6 + i] for i, n in enumerate(j)})
    cols.update({f"tau_{n}": log.tau_Nm[:, i] for i, (n, s) in enumerate(zip(j, robot.sensed)) if s})
    cols.update({c: log.wrench[:, i] for i, c in enumerate(WRENCH)})
    return pd.DataFrame(cols)


def write_spatial_log(log: SpatialLog, robot, path) -> None:
    """Atomically: Parquet for ``.parquet``, else CSV at full precision."""
    from userio.files import atomic_write

    frame = log_frame(log, robot)
    if Path(path).suffix.lower() == ".parquet":
        atomic_write(path, lambda tmp: frame.to_parquet(tmp, index=False))
    else:
        atomic_write(path, lambda tmp: frame.to_csv(tmp, index=False, float_format="%.17g"))


# ----------------------------------------------------------------------------- side files
def timing_channels(robot) -> list[str]:
    return WRENCH + [f"tau_{j}" for j, s in zip(robot.joint_names, robot.sensed) if s]


def read_timing(log_path, robot):
    """``LOG.timing.toml`` (keys default, wrench, tau or channel names) → per observer row
    [(kind, delay_s)] (six base rows, then the joints; unsensed joints 'instant'), or None.
    The six wrench channels must share one timing: the sensor → base transform mixes them."""
    from estimator.log_declarations import read_side_table

    names = timing_channels(robot)
    found = read_side_table(log_path, names)
    if found is None:
        return None
    path, table = found
    default = table.get("default", ("instant", 0.0))

    def of(name, group):
        key = name if name in table else group if group in table else None
        return table[key] if key else default

    wr = [of(c, "wrench") for c in WRENCH]
    if len(set(wr)) > 1:
        raise InputError(f"{path}: timing: the six wrench channels Fx … Mz must share one timing "
                         f"(got {', '.join(f'{c}={k}' for c, (k, _) in zip(WRENCH, wr))})")
    out = wr[:1] * 6
    for j, s in zip(robot.joint_names, robot.sensed):
        out.append(of(f"tau_{j}", "tau") if s else ("instant", 0.0))
    return out


def timing_text(robot) -> str:
    return ("# How each force channel was sampled (estimator/timing.py, docs/conventions.md)\n"
            "[timing]\ndefault = \"instant\"\n")


@dataclass(frozen=True)
class SpatialNoise:
    """White noise of a 3-D log's sensors, 1σ per sample: joint torques (one per sensed joint),
    the FT wrench [Fx, Fy, Fz N, Mx, My, Mz N·m] (sensor frame), joint rates, encoders, and the
    measured base state (floating base): orientation (a rotation vector δθ in the base frame,
    R_meas = R exp([δθ]×)), ṗ (world) and ω (base frame), three values each. The base position
    is not a channel: nothing the observer computes depends on it (positions are relative to p)."""

    torque_sigma_Nm: np.ndarray
    ft_sigma: np.ndarray
    velocity_sigma_rad_per_s: float = 0.0
    encoder_counts: int = 0
    source: str = "option"
    base_orientation_sigma_rad: np.ndarray = field(default_factory=lambda: np.zeros(3))
    base_velocity_sigma_m_per_s: np.ndarray = field(default_factory=lambda: np.zeros(3))
    base_rate_sigma_rad_per_s: np.ndarray = field(default_factory=lambda: np.zeros(3))

    @property
    def base_sigma(self) -> np.ndarray:
        """[δθ (3) rad, δṗ (3) m/s, δω (3) rad/s]: the base-state channels' σ."""
        return np.r_[self.base_orientation_sigma_rad, self.base_velocity_sigma_m_per_s,
                     self.base_rate_sigma_rad_per_s]

    def describe(self) -> str:
        base = ""
        if np.any(self.base_sigma > 0):
            base = (f", base σ: orientation {np.round(self.base_orientation_sigma_rad, 6).tolist()} rad, "
                    f"ṗ {np.round(self.base_velocity_sigma_m_per_s, 6).tolist()} m/s, "
                    f"ω {np.round(self.base_rate_sigma_rad_per_s, 6).tolist()} rad/s")
        return (f"{self.source}: τ σ {np.round(self.torque_sigma_Nm, 6).tolist()} N·m, FT σ "
                f"{np.round(self.ft_sigma, 6).tolist()}, q̇ σ {self.velocity_sigma_rad_per_s:g} rad/s, "
                f"encoder {self.encoder_counts} counts/rev{base}")


def make_noise(torque_sigma, ft_sigma, n_sensed: int, velocity_sigma=0.0, encoder_counts=0,
               source="option", base_orientation_sigma=0.0, base_velocity_sigma=0.0,
               base_rate_sigma=0.0) -> SpatialNoise:
    """Validated noise: τ σ one value or one per sensed joint; FT σ 6 values or 2 (force, moment);
    the base state's σ (rad, m/s, rad/s) one value or three each (SpatialNoise)."""
    tau = np.atleast_1d(np.asarray(torque_sigma, float))
    ft = np.atleast_1d(np.asarray(ft_sigma, float))
    if ft.size == 2:
        ft = np.repeat(ft, 3)
    if tau.size not in (1, n_sensed):
        raise InputError(f"{source}: torque sigma: expected 1 or {n_sensed} values, got {tau.size}")
    if ft.size != 6:
        raise InputError(f"{source}: FT sigma: expected 6 values [Fx, Fy, Fz, Mx, My, Mz] or 2 "
                         f"[force, moment], got {ft.size}")
    for name, arr in (("torque sigma", tau), ("FT sigma", ft)):
        if not np.all(np.isfinite(arr)) or np.any(arr <= 0):
            raise InputError(f"{source}: {name}: every σ must be finite and > 0, got {arr.tolist()}")
    if not (np.isfinite(velocity_sigma) and velocity_sigma >= 0):
        raise InputError(f"{source}: velocity sigma must be finite and ≥ 0")
    base = []
    for name, val in (("base orientation sigma", base_orientation_sigma),
                      ("base velocity sigma", base_velocity_sigma), ("base rate sigma", base_rate_sigma)):
        arr = np.atleast_1d(np.asarray(val, float))
        if arr.size not in (1, 3) or not np.all(np.isfinite(arr)) or np.any(arr < 0):
            raise InputError(f"{source}: {name}: expected 1 or 3 values, each finite and ≥ 0, "
                             f"got {arr.tolist()}")
        base.append(np.broadcast_to(arr, (3,)).copy())
    return SpatialNoise(np.broadcast_to(tau, (n_sensed,)).copy(), ft, float(velocity_sigma),
                        int(encoder_counts), source, *base)


def read_noise(log_path, robot) -> SpatialNoise | None:
    """``LOG.noise.toml`` beside a 3-D log (userio.schema.logs.NoiseFile: torque_sigma_Nm one
    value or one per sensed joint, ft_sigma 6 or 2), or None."""
    from estimator.noise import noise_side_file
    from userio.files import read_toml
    from userio.schema import parse
    from userio.schema.logs import NoiseFile

    path = noise_side_file(log_path)
    if not path.exists():
        return None
    n = int(sum(robot.sensed))
    t = parse(NoiseFile, read_toml(path), path, {"torque_sizes": (1, n), "ft_sizes": (6, 2)}).noise
    return make_noise(t.torque_sigma_Nm, t.ft_sigma, n, t.velocity_sigma_rad_per_s,
                      t.encoder_counts, f"log declaration {path.name}", t.base_orientation_sigma_rad,
                      t.base_velocity_sigma_m_per_s, t.base_rate_sigma_rad_per_s)


def noise_text(noise: SpatialNoise) -> str:
    vec = lambda v: "[" + ", ".join(f"{float(x):.10g}" for x in np.atleast_1d(v)) + "]"  # noqa: E731
    return "\n".join([
        "# Sensor noise of this 3-D log (docs/conventions.md): white, 1 sigma per sample.",
        "[noise]",
        f"torque_sigma_Nm = {vec(noise.torque_sigma_Nm)}   # per sensed joint",
        f"ft_sigma = {vec(noise.ft_sigma)}   # Fx, Fy, Fz [N], Mx, My, Mz [N·m], sensor frame",
        f"velocity_sigma_rad_per_s = {noise.velocity_sigma_rad_per_s:.10g}",
        f"encoder_counts = {int(noise.encoder_counts)}",
    ] + ([f"base_orientation_sigma_rad = {vec(noise.base_orientation_sigma_rad)}   # base frame",
          f"base_velocity_sigma_m_per_s = {vec(noise.base_velocity_sigma_m_per_s)}   # ṗ, world",
          f"base_rate_sigma_rad_per_s = {vec(noise.base_rate_sigma_rad_per_s)}   # ω, base frame"]
         if np.any(noise.base_sigma > 0) else [])) + "\n"
