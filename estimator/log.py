"""Sensor logs: the estimator's input (DESIGN.md, "Sensor log").

CSV header ``t,x,z,theta,q1,q2,dx,dz,dtheta,dq1,dq2,tau1,tau2,Fx,Fz,My`` (q3…, dq3…, tau3… for
longer chains; a fixed-base log omits x, z, theta and their rates). SI units throughout.
In memory, coordinates are always the floating ones [x, z, θ, q_1…q_N]: a fixed-base log is
padded with a zero base, and the base wrench enters on the base rows (DESIGN.md).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from estimator.errors import InputError


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


# ----------------------------------------------------------------------------- reading / writing
def _line(row_index: int) -> int:
    """1-based file line of data row ``row_index`` (the header is line 1)."""
    return int(row_index) + 2


def _layout(columns: list[str], source: str, n_links: int | None):
    """(n_links, floating) from a header, or an InputError naming the missing/misspelled column."""
    import difflib
    import re

    taus = sorted(int(m.group(1)) for c in columns if (m := re.fullmatch(r"tau(\d+)", c)))
    qs = sorted(int(m.group(1)) for c in columns if (m := re.fullmatch(r"q(\d+)", c)))
    n_log = max(taus + qs, default=0)
    floating = any(c in columns for c in ("x", "z", "theta", "dx", "dz", "dtheta"))
    n = n_log if n_log else (n_links or 0)
    if n == 0:
        raise InputError(f"{source}: header has no joint columns (q1…, dq1…, tau1…); "
                         f"expected {','.join(log_columns(n_links or 2, True))}")
    if n_links is not None and n_log and n_log != n_links:
        raise InputError(f"{source}: the log has {n_log} joint column set(s) (up to q{n_log}/tau{n_log}) "
                         f"but the robot has {n_links} links; expected columns "
                         f"{','.join(log_columns(n_links, floating))}")
    expected = log_columns(n, floating)
    extra = [c for c in columns if c not in expected]
    for col in expected:
        if col not in columns:
            hint = difflib.get_close_matches(col, extra, n=1, cutoff=0.6)
            did = f" (found '{hint[0]}': misspelled?)" if hint else ""
            raise InputError(f"{source}: line 1: missing column '{col}'{did}; expected header "
                             f"{','.join(expected)}")
    return n, floating


def _read_text_values(path, source: str, names: list[str], cols: list[str]) -> np.ndarray:
    """Slow path: parse as text to name the first non-numeric field (line, column)."""
    import pandas as pd

    try:
        frame = pd.read_csv(path, dtype=str, keep_default_na=False, skipinitialspace=True)
    except (pd.errors.ParserError, UnicodeDecodeError) as exc:
        msg = str(exc).strip().splitlines()[-1] if str(exc).strip() else type(exc).__name__
        raise InputError(f"{source}: not a readable CSV log: {msg}") from None
    frame.columns = names
    values = np.empty((len(frame), len(cols)))
    for j, col in enumerate(cols):
        text = frame[col].str.strip()
        num = pd.to_numeric(text, errors="coerce").to_numpy(dtype=float)
        bad = np.isnan(num) & ~text.str.lower().isin(["", "nan", "-nan", "+nan", "na", "null"]).to_numpy()
        if bad.any():
            i = int(np.flatnonzero(bad)[0])
            raise InputError(f"{source}: line {_line(i)}, column '{col}': "
                             f"{frame[col].iloc[i]!r} is not a number")
        values[:, j] = num
    return values


def read_log(path, robot=None, *, max_jitter: float = 0.01) -> SensorLog:
    """Read and validate a sensor log (DESIGN.md format): CSV, or Parquet for ``.parquet``.

    Rows with a NaN/inf (or empty) field are skipped and counted (``skipped_lines``, ``valid_mask``);
    a non-numeric field, a non-increasing time or a step that is not a whole number of sample
    periods (±``max_jitter``) raises InputError naming the file, line and column. With ``robot``,
    the number of joints must match its links.
    """
    from pathlib import Path

    path = Path(path)
    source = str(path)
    if not path.exists():
        raise InputError(f"{source}: no such file")
    if path.is_dir():
        raise InputError(f"{source}: is a directory, expected a CSV log")
    if path.suffix.lower() == ".parquet":
        names, values, n, floating = _read_parquet(path, source, robot)
    else:
        names, values, n, floating = _read_csv(path, source, robot)
    return _from_values(path, source, values, n, floating, max_jitter)


def _read_parquet(path, source, robot):
    """(names, values in log_columns order, n_links, floating) of a Parquet log (pyarrow)."""
    import pandas as pd

    try:
        frame = pd.read_parquet(path)
    except ImportError:
        raise InputError(f"{source}: reading Parquet needs pyarrow (pip install pyarrow)") from None
    except Exception as exc:                   # pyarrow raises several types for a bad file
        raise InputError(f"{source}: not a readable Parquet log: {str(exc).splitlines()[0]}") from None
    names = [str(c).strip() for c in frame.columns]
    n, floating = _layout(names, source, None if robot is None else robot.n_links)
    cols = log_columns(n, floating)
    frame.columns = names
    try:
        values = frame[cols].to_numpy(dtype=float)
    except (ValueError, TypeError):
        bad = next(c for c in cols if not pd.api.types.is_numeric_dtype(frame[c]))
        raise InputError(f"{source}: column '{bad}' is not numeric") from None
    return names, values, n, floating


def _read_csv(path, source, robot):
    import pandas as pd

    try:
        header = pd.read_csv(path, nrows=0, skipinitialspace=True)
    except pd.errors.EmptyDataError:
        raise InputError(f"{source}: empty file (expected a CSV header and samples)") from None
    except (pd.errors.ParserError, UnicodeDecodeError) as exc:
        msg = str(exc).strip().splitlines()[-1] if str(exc).strip() else type(exc).__name__
        raise InputError(f"{source}: not a readable CSV log: {msg}") from None
    names = [str(c).strip() for c in header.columns]
    dup = [c for i, c in enumerate(names) if c in names[:i]]
    if dup:
        raise InputError(f"{source}: line 1: column '{dup[0]}' appears twice")
    n, floating = _layout(names, source, None if robot is None else robot.n_links)
    cols = log_columns(n, floating)
    try:                                        # fast path: every field numeric (or NaN/inf/empty)
        frame = pd.read_csv(path, skipinitialspace=True, dtype=float, engine="c",
                            na_values=["nan", "-nan", "+nan", "NaN", "NA", "null", ""])
        frame.columns = names
        values = frame[cols].to_numpy(dtype=float)
    except (ValueError, TypeError, pd.errors.ParserError, UnicodeDecodeError):
        values = _read_text_values(path, source, names, cols)
    return names, values, n, floating


def _from_values(path, source, values, n, floating, max_jitter):
    if len(values) == 0:
        raise InputError(f"{source}: no samples after the header")
    valid = np.all(np.isfinite(values), axis=1)
    if not valid.any():
        raise InputError(f"{source}: every sample has a NaN/inf field; nothing to estimate")
    data = values[valid]
    rows = np.flatnonzero(valid)
    t = data[:, 0]
    steps = np.diff(t)
    if np.any(steps <= 0):
        k = int(np.flatnonzero(steps <= 0)[0])
        raise InputError(f"{source}: line {_line(rows[k + 1])}, column 't': time {t[k + 1]:g} s does not "
                         f"increase (previous sample {t[k]:g} s at line {_line(rows[k])})")
    if len(t) > 2:
        dt = float(np.median(steps))
        # a step may span skipped rows: it must then be a whole number of periods
        skipped = np.diff(rows) - 1
        ratio = steps / dt
        off = np.abs(ratio - np.maximum(np.round(ratio), 1)) > max_jitter
        off |= np.round(ratio) != skipped + 1
        if off.any():
            k = int(np.flatnonzero(off)[0])
            raise InputError(f"{source}: line {_line(rows[k + 1])}, column 't': irregular sampling, step "
                             f"{steps[k]:.6g} s where the log's period is {dt:.6g} s "
                             f"(±{100 * max_jitter:g}%)")
    base = 3 if floating else 0
    T = len(t)
    q = np.zeros((T, n + 3))
    dq = np.zeros((T, n + 3))
    q[:, 3 - base:] = data[:, 1:1 + base + n]
    dq[:, 3 - base:] = data[:, 1 + base + n:1 + 2 * (base + n)]
    i0 = 1 + 2 * (base + n)
    log = SensorLog(t=t, q=q, dq=dq, tau_Nm=data[:, i0:i0 + n], wrench=data[:, i0 + n:i0 + n + 3],
                    floating=floating)
    log.source = source
    log.valid_mask = valid
    log.skipped_lines = rows_to_lines(np.flatnonzero(~valid))
    from estimator.timing import read_declaration
    log.timing = read_declaration(path, n)       # LOG.timing.toml beside the log, if any
    from estimator.plausibility import check_log

    check_log(log)                              # units and sampling plausible
    return log


def rows_to_lines(rows: np.ndarray) -> np.ndarray:
    return np.asarray(rows, dtype=int) + 2


def log_to_frame(log: SensorLog):
    """A pandas DataFrame with DESIGN.md's columns in order (a fixed base omits the base columns)."""
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
