"""Static-loading sessions: the CSV format, validation, and writing.

CSV: optional leading ``# key=value; key=value`` metadata lines (``reading_unit=mV``,
``simulated=...``), then a header with required columns ``mass_g,reading`` and optional
``direction`` (``load``/``unload``), ``repeat``, ``lever_arm_m``, ``timestamp`` (s),
``sensor_id``. Units are in the column names (g, m, s); the reading's unit is the
``reading_unit`` metadata (mV for the paper's eqs. 12–13, or ``counts``).
Torque of a dead weight on a horizontal lever: τ = m g L (m in kg, g = 9.81 m/s², the workbench's
gravity, as ``bridge.chain`` uses).
"""

from __future__ import annotations

import hashlib
import io
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from userio.errors import InputError
from userio.ranges import Range

G_STANDARD_M_PER_S2 = 9.81
# physical ranges of a static-loading session (userio.ranges.Range: checked where read)
LEVER_ARM_RANGE_M = Range(1e-3, 10.0, "m", low="a calibration lever is at least a millimetre long",
                          high="a calibration lever is at most a few metres: mm typed as m?")
MASS_RANGE_G = Range(0.0, 1e7, "g", high="ten tonnes on a calibration lever: kg typed as g, or mg?")
READING_LIMIT = 1e12                 # |reading| above this is no ADC code or voltage (counts ≤ 2³², mV ≤ 1e5)
MAX_SESSION_BYTES = 64 << 20
REQUIRED = ("mass_g", "reading")
OPTIONAL = ("direction", "repeat", "lever_arm_m", "timestamp", "sensor_id")


@dataclass
class Session:
    """A loading session. Arrays have one entry per reading."""

    mass_g: np.ndarray
    reading: np.ndarray
    direction: np.ndarray                       # "load" / "unload"
    repeat: np.ndarray                          # int
    timestamp_s: np.ndarray                     # NaN if unknown
    lever_arm_m: float | None = None
    sensor_id: str = "sensor"
    reading_unit: str = "mV"
    meta: dict = field(default_factory=dict)
    source: str = "<memory>"
    sha256: str = ""

    @property
    def unload(self) -> np.ndarray:
        """Boolean mask of unloading-branch readings."""
        return self.direction == "unload"

    @property
    def torque_Nm(self) -> np.ndarray:
        """τ = m g L of each reading (needs a lever arm)."""
        if self.lever_arm_m is None:
            raise InputError(f"{self.source}: no lever_arm_m; cannot convert mass to torque")
        return self.mass_g * 1e-3 * G_STANDARD_M_PER_S2 * self.lever_arm_m

    def __len__(self) -> int:
        return int(self.mass_g.size)

    def to_csv_text(self) -> str:
        """The session as CSV text (metadata line, header, rows)."""
        meta = {"reading_unit": self.reading_unit, **{k: v for k, v in self.meta.items()
                                                     if k != "reading_unit"}}
        lines = ["# " + "; ".join(f"{k}={v}" for k, v in meta.items())]
        cols = ["mass_g", "reading", "direction", "repeat", "timestamp", "sensor_id"]
        if self.lever_arm_m is not None:
            cols.insert(4, "lever_arm_m")
        lines.append(",".join(cols))
        for i in range(len(self)):
            row = [f"{self.mass_g[i]:.6g}", f"{self.reading[i]:.9g}", str(self.direction[i]),
                   str(int(self.repeat[i]))]
            if self.lever_arm_m is not None:
                row.append(f"{self.lever_arm_m:.9g}")
            ts = self.timestamp_s[i]
            row += [f"{ts:.6f}" if np.isfinite(ts) else "", self.sensor_id]
            lines.append(",".join(row))
        return "\n".join(lines) + "\n"


def write_session(session: Session, path, *, overwrite: bool = False) -> Path:
    """Write a session CSV atomically (never replaces an existing file unless ``overwrite``)."""
    from userio.files import write_text_atomic
    return write_text_atomic(path, session.to_csv_text(), overwrite=overwrite)


def _parse_meta(lines: list[str]) -> dict:
    meta = {}
    for line in lines:
        for part in line.lstrip("#").split(";"):
            if "=" in part:
                k, v = part.split("=", 1)
                meta[k.strip()] = v.strip()
    return meta


def read_session(path, *, reading_unit: str | None = None) -> Session:
    """Read and validate a session CSV; errors name the file, line and column."""
    import pandas as pd

    from userio.files import check_input

    path = check_input(path, max_bytes=MAX_SESSION_BYTES, what="session CSV")
    raw = path.read_bytes()
    text = raw.decode("utf-8", errors="replace").lstrip("\ufeff")
    lines = text.splitlines()
    n_meta = 0
    while n_meta < len(lines) and lines[n_meta].startswith("#"):
        n_meta += 1
    meta = _parse_meta(lines[:n_meta])
    body = "\n".join(lines[n_meta:])
    if not body.strip():
        raise InputError(f"{path}: empty file (need a header with columns mass_g,reading)")
    try:
        df = pd.read_csv(io.StringIO(body), dtype=str, skip_blank_lines=False,
                         keep_default_na=False)
    except pd.errors.ParserError as exc:
        raise InputError(f"{path}: not a valid CSV: {str(exc).splitlines()[0]}") from None
    df.columns = [c.strip() for c in df.columns]
    header_line = n_meta + 1
    for col in REQUIRED:
        if col not in df.columns:
            raise InputError(f"{path}: line {header_line}: missing required column {col!r} "
                             f"(header has {', '.join(df.columns)})")
    # drop fully blank rows but remember file line numbers (header is line n_meta+1)
    lineno = np.arange(len(df)) + header_line + 1
    blank = (df.apply(lambda s: s.str.strip()) == "").all(axis=1).to_numpy()
    df, lineno = df[~blank].reset_index(drop=True), lineno[~blank]
    if len(df) == 0:
        raise InputError(f"{path}: no data rows after the header")

    def numeric(col, *, integer=False, allow_empty=False):
        s = df[col].str.strip()
        vals = pd.to_numeric(s, errors="coerce").to_numpy(dtype=float)
        bad = ~np.isfinite(vals)
        if allow_empty:
            bad &= (s != "").to_numpy()
        if bad.any():
            i = int(np.argmax(bad))
            raise InputError(f"{path}: line {lineno[i]}: column {col!r}: "
                             f"{s.iloc[i]!r} is not a finite number")
        if integer and np.any(vals[~bad] != np.round(vals[~bad])):
            i = int(np.argmax(vals != np.round(vals)))
            raise InputError(f"{path}: line {lineno[i]}: column {col!r}: "
                             f"{s.iloc[i]!r} is not an integer")
        return vals

    mass_g = numeric("mass_g")
    if np.any(mass_g < 0):
        i = int(np.argmax(mass_g < 0))
        raise InputError(f"{path}: line {lineno[i]}: column 'mass_g': negative mass {mass_g[i]:g}")
    for i in np.flatnonzero(mass_g > MASS_RANGE_G.hi)[:1]:
        MASS_RANGE_G.check(mass_g[i], f"{path}: line {lineno[i]}: column 'mass_g'")
    reading = numeric("reading")
    big = np.flatnonzero(np.abs(reading) > READING_LIMIT)
    if big.size:
        i = int(big[0])
        raise InputError(f"{path}: line {lineno[i]}: column 'reading': {reading[i]:g} is larger than "
                         f"any ADC code or voltage (|reading| ≤ {READING_LIMIT:g}); check the export")
    n = mass_g.size
    if "direction" in df.columns:
        direction = df["direction"].str.strip().str.lower().to_numpy(dtype=object)
        direction[direction == ""] = "load"
        bad = ~np.isin(direction, ["load", "unload"])
        if bad.any():
            i = int(np.argmax(bad))
            raise InputError(f"{path}: line {lineno[i]}: column 'direction': "
                             f"{df['direction'].iloc[i]!r} is not 'load' or 'unload'")
        direction = direction.astype(str)
    else:
        direction = np.full(n, "load")
    repeat = numeric("repeat", integer=True).astype(int) if "repeat" in df.columns \
        else np.zeros(n, int)
    timestamp = (numeric("timestamp", allow_empty=True) if "timestamp" in df.columns
                 else np.full(n, np.nan))
    lever = None
    if "lever_arm_m" in df.columns:
        arm = numeric("lever_arm_m")
        if np.any(arm <= 0):
            i = int(np.argmax(arm <= 0))
            raise InputError(f"{path}: line {lineno[i]}: column 'lever_arm_m': "
                             f"must be > 0, got {arm[i]:g}")
        for i in np.flatnonzero(arm > LEVER_ARM_RANGE_M.hi)[:1]:
            LEVER_ARM_RANGE_M.check(arm[i], f"{path}: line {lineno[i]}: column 'lever_arm_m'")
        if np.ptp(arm) > 1e-9 * arm.max():
            i = int(np.argmax(np.abs(arm - arm[0]) > 1e-9 * arm.max()))
            raise InputError(f"{path}: line {lineno[i]}: column 'lever_arm_m': differs from "
                             f"line {lineno[0]} ({arm[i]:g} vs {arm[0]:g}); one lever arm per session")
        lever = float(arm[0])
    sensor_id = "sensor"
    if "sensor_id" in df.columns:
        ids = sorted(set(df["sensor_id"].str.strip()) - {""})
        if len(ids) > 1:
            raise InputError(f"{path}: column 'sensor_id': several sensors {ids}; "
                             "one sensor per session file")
        sensor_id = ids[0] if ids else sensor_id
    if np.unique(mass_g).size < 2:
        raise InputError(f"{path}: line {lineno[0]}: column 'mass_g': a single load level "
                         f"({mass_g[0]:g} g); a calibration needs at least two")
    unit = reading_unit or meta.get("reading_unit", "mV")
    return Session(mass_g=mass_g, reading=reading, direction=direction, repeat=repeat,
                   timestamp_s=timestamp, lever_arm_m=lever, sensor_id=sensor_id,
                   reading_unit=unit, meta=meta, source=str(path),
                   sha256=hashlib.sha256(raw).hexdigest())
