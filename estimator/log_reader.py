"""Reading and validating a sensor log (docs/conventions.md, "Sensor log CSV"), whole
(``read_log``) or in chunks (``LogReader``), CSV or Parquet.

Rows with a NaN/inf (or empty) field are skipped and counted; a non-numeric field, a missing or
misspelled column, a non-increasing time or an irregular step raises InputError naming the file,
line and column. The rows of a block are split into the log's arrays and their time steps
checked in one compiled pass (``split_rows``, ``check_steps``; numba) when it is available, else
by the numpy forms (``LogReader._validate``, ``check_steps_numpy``). The bytes are parsed by
estimator.log_parsing.
"""

from __future__ import annotations

import math

import numpy as np

from estimator import compiled
from estimator import log_parsing as parsing
from userio.errors import InputError
from estimator.log import log_columns, SensorLog
from estimator.log_parsing import file_line

DEFAULT_CHUNK_SAMPLES = 65536
KEEP_SKIPPED_LINES = 1000            # a streamed log keeps the first lines skipped (and a count)


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


def read_log(path, robot=None, *, max_jitter: float = 0.01) -> SensorLog:
    """Read and validate a sensor log (docs/conventions.md format): CSV, or Parquet for ``.parquet``.

    Rows with a NaN/inf (or empty) field are skipped and counted (``skipped_lines``, ``valid_mask``);
    a non-numeric field, a non-increasing time or a step that is not a whole number of sample
    periods (±``max_jitter``; the period is ``observer.regular_period``: the median of the first
    1024 steps) raises InputError naming the file, line and column. With ``robot``, the number of
    joints must match its links. The whole file as one chunk of ``LogReader``.
    """
    reader = LogReader(path, robot, chunk_samples=None, max_jitter=max_jitter, keep_valid_mask=True)
    (log,) = list(reader)
    log.skipped_lines = reader.skipped_lines
    log.valid_mask = np.concatenate(reader.valid_masks)
    log.plausibility_warnings = reader.finish()
    return log


class LogReader:
    """A sensor log read in chunks of ``chunk_samples`` file rows (None: the whole file at once),
    each validated as ``read_log`` validates a whole log, with the state that spans chunks carried
    over: the previous valid row (time order, whole periods across skipped rows), the sampling
    period (from the head: the first 1025 valid rows are read before the first chunk is yielded),
    the plausibility sums (estimator.plausibility.Checker). Iterating yields ``SensorLog`` chunks
    (attribute ``row0``: the file's data-row index of the chunk's first row). ``finish()`` runs the
    whole-log checks once every chunk has been seen and returns the warnings.

    Attributes after the header: ``n_links``, ``floating``, ``source``, ``timing``; while reading:
    ``n_samples``, ``n_skipped``, ``skipped_lines`` (the first ``KEEP_SKIPPED_LINES``), ``period_s``.
    """

    def __init__(self, path, robot=None, chunk_samples: int | None = DEFAULT_CHUNK_SAMPLES,
                 max_jitter: float = 0.01, keep_valid_mask: bool = False):
        from pathlib import Path

        from estimator.plausibility import Checker
        from estimator.log_declarations import read_declaration

        from userio.files import check_input

        path = Path(path)
        self.path, self.source = path, str(path)
        check_input(path, max_bytes=None, what="log (CSV or Parquet)")   # a regular file: no device
        if not path.exists():
            raise InputError(f"{self.source}: no such file")
        if chunk_samples is not None and (int(chunk_samples) != chunk_samples or chunk_samples < 1):
            raise InputError(f"chunk size: must be a whole number of samples ≥ 1, got {chunk_samples}")
        self.chunk_samples = chunk_samples
        self.parquet = path.suffix.lower() == ".parquet"
        self.max_jitter = max_jitter
        n_links = None if robot is None else robot.n_links
        self.names = self._parquet_names() if self.parquet else self._csv_names()
        self.n_links, self.floating = _layout(self.names, self.source, n_links)
        self.cols = log_columns(self.n_links, self.floating)
        self.timing = read_declaration(path, self.n_links)     # LOG.timing.toml beside the log, if any
        self.checker = Checker(self.source, self.floating, self.n_links)
        self.n_rows = self.n_samples = self.n_skipped = 0
        self.skipped_lines = np.zeros(0, dtype=int)
        self.period_s = None
        self._last = None                      # (t, file row) of the last valid row
        self.keep_valid_mask = keep_valid_mask
        self.valid_masks: list[np.ndarray] = []

    # ------------------------------------------------------------------ header
    def _csv_names(self):
        parsing.check_header(self.path, self.source)
        self._simple_header = parsing.simple_header(self.path)
        if self._simple_header is not None:       # plain names: no need to import pandas
            return self._simple_header[1]
        import pandas as pd

        try:
            header = pd.read_csv(self.path, nrows=0, skipinitialspace=True)
        except pd.errors.EmptyDataError:
            raise InputError(f"{self.source}: empty file (expected a CSV header and samples)") from None
        except (pd.errors.ParserError, UnicodeDecodeError) as exc:
            msg = str(exc).strip().splitlines()[-1] if str(exc).strip() else type(exc).__name__
            raise InputError(f"{self.source}: not a readable CSV log: {msg}") from None
        names = [str(c).strip() for c in header.columns]
        dup = [c for i, c in enumerate(names) if c in names[:i]]
        if dup:
            raise InputError(f"{self.source}: line 1: column '{dup[0]}' appears twice")
        return names

    def _parquet_file(self):
        try:
            import pyarrow.parquet as pq
        except ImportError:
            raise InputError(f"{self.source}: reading Parquet needs pyarrow (pip install pyarrow)") from None
        try:
            return pq.ParquetFile(self.path)
        except Exception as exc:               # pyarrow raises several types for a bad file
            raise InputError(f"{self.source}: not a readable Parquet log: {str(exc).splitlines()[0]}") from None

    def _parquet_names(self):
        return [str(c).strip() for c in self._parquet_file().schema_arrow.names]

    # ------------------------------------------------------------------ raw blocks
    def _blocks(self):
        """Arrays (rows, columns in ``log_columns`` order) of up to ``chunk_samples`` file rows."""
        if self.parquet:
            yield from self._parquet_blocks()
        else:
            yield from self._csv_blocks()

    def _parquet_blocks(self):
        import pyarrow as pa

        f = self._parquet_file()
        index = {c: i for i, c in enumerate(self.names)}
        for name in self.cols:
            typ = f.schema_arrow.field(index[name]).type
            if not (pa.types.is_floating(typ) or pa.types.is_integer(typ) or pa.types.is_null(typ)):
                raise InputError(f"{self.source}: column '{name}' is not numeric")
        raw = [f.schema_arrow.names[index[c]] for c in self.cols]
        size = self.chunk_samples or max(f.metadata.num_rows, 1)

        def batches():
            # a row group at a time (iter_batches over the whole file buffers more and more of it)
            for g in range(f.num_row_groups):
                for batch in f.iter_batches(batch_size=size, columns=raw, row_groups=[g]):
                    out = np.empty((len(raw), batch.num_rows)).T   # column-major: columns whole
                    for j in range(len(raw)):
                        column = batch.column(j)
                        if column.type == pa.float64():
                            parsing.fill_floats(out[:, j], column)
                        else:                      # integers, float32, null: numpy converts
                            out[:, j] = column.to_numpy(zero_copy_only=False)
                    yield out

        try:
            yield from parsing.reblock(batches(), self.chunk_samples)
        except (OSError, ValueError) as exc:
            raise InputError(f"{self.source}: not a readable Parquet log: {str(exc).splitlines()[0]}") from None

    def _csv_blocks(self):
        """Blocks of the CSV's data rows: pyarrow's multithreaded parser on byte blocks of about
        ``chunk_samples`` rows of text (64 KiB–8 MiB, cut at line ends), re-blocked into
        ``chunk_samples`` rows. A byte block pyarrow cannot take exactly as pandas would (a parse
        error, a field it reads as NaN/inf that is not one of the NA spellings) is parsed by
        pandas (``_pandas_values``), which names a bad field's line; both parsers round decimal
        strings correctly (``log_parsing.pandas_kw``), so the values do not depend on which one read them."""
        header = self._csv_header_line()
        try:
            import pyarrow.csv  # noqa: F401
        except ImportError:
            header = None
        if header is None:                 # a header pyarrow's split would not reproduce
            yield from self._pandas_blocks()
            return
        size = self.chunk_samples
        # about chunk_samples rows of text per parse (24 bytes a field), so memory follows the chunk
        nbytes = None if size is None else int(np.clip(size * 24 * len(self.names),
                                                       parsing.CSV_MIN_BLOCK_BYTES,
                                                       parsing.CSV_BLOCK_BYTES))

        def parsed():
            row0 = 0
            for body in parsing.byte_blocks(self.path, len(header), nbytes):
                values = parsing.arrow_values(body, self.names, self.cols)
                if values is None:
                    values = self._pandas_values(header + bytes(body), row0)
                row0 += len(values)
                yield values

        yield from parsing.reblock(parsed(), size)

    def _csv_header_line(self) -> bytes | None:
        """The file's first line (bytes, with its line end) if pandas reads the same column names
        from it alone as from the file, else None."""
        if self._simple_header is not None:
            return self._simple_header[0]
        import io

        import pandas as pd

        with open(self.path, "rb") as f:
            line = f.readline()
        try:
            names = [str(c).strip() for c in
                     pd.read_csv(io.BytesIO(line), nrows=0, skipinitialspace=True).columns]
        except Exception:                  # noqa: BLE001 — the whole-file path decides
            return None
        return line if names == self.names and line.endswith(b"\n") else None

    def _pandas_values(self, text: bytes, row0: int) -> np.ndarray:
        """The data rows of ``text`` (the header line and a byte block starting at data row
        ``row0``) parsed by pandas; a bad field raises InputError naming its file line."""
        import io

        import pandas as pd

        try:
            frame = pd.read_csv(io.BytesIO(text), **parsing.pandas_kw())
            frame.columns = self.names
            return frame[self.cols].to_numpy(dtype=float)
        except (ValueError, TypeError, pd.errors.ParserError, UnicodeDecodeError):
            self._name_bad_field(row0, text.count(b"\n") + 1)

    def _name_bad_field(self, row0: int, nrows: int | None):
        """Raise InputError naming the first non-numeric field from data row ``row0`` on."""
        parsing.read_text_values(self.path, self.source, self.names, self.cols, row0, nrows)
        raise InputError(f"{self.source}: not a readable CSV log after line {file_line(row0)}")

    def _pandas_blocks(self):
        """The whole file through pandas' chunked reader (headers pyarrow's split cannot take)."""
        import pandas as pd

        kw = parsing.pandas_kw()
        row0 = 0
        try:
            if self.chunk_samples is None:
                frames = iter([pd.read_csv(self.path, **kw)])
            else:
                frames = pd.read_csv(self.path, chunksize=self.chunk_samples, **kw)
            while True:
                try:
                    frame = next(frames)
                except StopIteration:
                    return
                frame.columns = self.names
                values = frame[self.cols].to_numpy(dtype=float)
                row0 += len(values)
                yield values
        except (ValueError, TypeError, pd.errors.ParserError, UnicodeDecodeError):
            # a non-numeric field in the rows from row0 on: name it (line, column)
            self._name_bad_field(row0, self.chunk_samples)

    # ------------------------------------------------------------------ validated chunks
    def __iter__(self):
        from estimator.observer import PERIOD_HEAD_STEPS

        head, head_valid = [], 0
        for values in self._blocks():
            if self.period_s is None:
                head.append(values)
                head_valid += int(np.all(np.isfinite(values), axis=1).sum())
                if head_valid <= PERIOD_HEAD_STEPS:
                    continue
                values = np.concatenate(head) if len(head) > 1 else head[0]
                head = None
            chunk = self._validate(values)
            if chunk is not None:
                yield chunk
        if head:                                # a log shorter than the head
            chunk = self._validate(np.concatenate(head))
            if chunk is not None:
                yield chunk
        if self.n_rows == 0:
            raise InputError(f"{self.source}: no samples after the header")
        if self.n_samples == 0:
            raise InputError(f"{self.source}: every sample has a NaN/inf field; nothing to estimate")

    def _validate(self, values):
        from estimator.observer import regular_period

        row0 = self.n_rows
        self.n_rows += len(values)
        n, base = self.n_links, 3 if self.floating else 0
        fast = compiled.available()
        if fast:                                   # one compiled pass: the mask and the split
            valid, t, q, dq, tau, wrench, rows = split_rows(values, base, n)
            rows += row0
        else:
            valid = np.all(np.isfinite(values), axis=1)
        if self.keep_valid_mask:
            self.valid_masks.append(valid)
        bad_rows = np.flatnonzero(~valid) if not fast or len(t) < len(values) else np.zeros(0, int)
        if bad_rows.size:
            self.n_skipped += bad_rows.size
            room = KEEP_SKIPPED_LINES - len(self.skipped_lines)
            if room > 0 or self.keep_valid_mask:
                extra = bad_rows if self.keep_valid_mask else bad_rows[:room]
                self.skipped_lines = np.concatenate([self.skipped_lines, rows_to_lines(row0 + extra)])
        if not valid.any():
            return None
        if not fast:
            data = values[valid] if bad_rows.size else values
            rows = row0 + np.flatnonzero(valid)
            t = np.ascontiguousarray(data[:, 0])
            T = len(t)
            q = np.zeros((T, n + 3))
            dq = np.zeros((T, n + 3))
            q[:, 3 - base:] = data[:, 1:1 + base + n]
            dq[:, 3 - base:] = data[:, 1 + base + n:1 + 2 * (base + n)]
            i0 = 1 + 2 * (base + n)
            tau, wrench = data[:, i0:i0 + n].copy(), data[:, i0 + n:i0 + n + 3].copy()
        if self.period_s is None:
            tt = t if self._last is None else np.r_[self._last[0], t]
            self.period_s = regular_period(tt)
            if len(tt) > 1:
                self.checker.period(self.period_s)
        dt = self.period_s
        regular = self._last is not None or len(t) > 2
        if fast:
            kind, k = check_steps(t, rows, self._last, dt, self.max_jitter, regular)
        else:
            kind, k = check_steps_numpy(t, rows, self._last, dt, self.max_jitter, regular)
        if kind:
            tt = t if self._last is None else np.r_[self._last[0], t]
            rr = rows if self._last is None else np.r_[self._last[1], rows]
            if kind == 1:
                raise InputError(f"{self.source}: line {file_line(rr[k + 1])}, column 't': time {tt[k + 1]:g} s "
                                 f"does not increase (previous sample {tt[k]:g} s at line {file_line(rr[k])})")
            raise InputError(f"{self.source}: line {file_line(rr[k + 1])}, column 't': irregular "
                             f"sampling, step {tt[k + 1] - tt[k]:.6g} s where the log's period is "
                             f"{dt:.6g} s (±{100 * self.max_jitter:g}%)")
        self._last = (t[-1], rows[-1])
        T = len(t)
        log = SensorLog(t=t, q=q, dq=dq, tau_Nm=tau, wrench=wrench, floating=self.floating,
                        source=self.source, timing=self.timing)
        log.row0 = int(row0)
        log.period_s = dt
        self.checker.rows(t, q, dq)
        self._track_constant(wrench, tau)
        self.n_samples += T
        return log

    def _track_constant(self, wrench, tau):
        """Running min/max of every force channel [Fx, Fz, My, τ…] (a dead channel is constant)."""
        block = np.concatenate([wrench, tau], axis=1)
        lo, hi = block.min(0), block.max(0)
        if getattr(self, "_lo", None) is None:
            self._lo, self._hi = lo, hi
        else:
            self._lo, self._hi = np.minimum(self._lo, lo), np.maximum(self._hi, hi)

    def constant_channels(self) -> list[str]:
        """Warnings for force channels that are exactly constant over the whole log."""
        if getattr(self, "_lo", None) is None or self.n_samples < 16:
            return []
        names = ["Fx", "Fz", "My", *[f"tau{i}" for i in range(1, self.n_links + 1)]]
        return [f"{self.source}: column '{names[j]}' is exactly {self._lo[j]:g} in all {self.n_samples} "
                "samples: a dead or unplugged channel? (a sensor's reading carries noise)"
                for j in np.flatnonzero(self._hi == self._lo)]

    def finish(self) -> list[str]:
        """The whole-log plausibility checks (velocity scale); warnings issued and returned.
        ``constant_channels()`` lists the force channels constant over the whole log."""
        self.plausibility_warnings = self.checker.finish()
        return self.plausibility_warnings


def check_steps_numpy(t, rows, last, dt, max_jitter, regular):
    """The numpy form of ``check_steps``: (1, k) for the first non-increasing step k of
    tt = [last t] + t, else (2, k) for the first step (if ``regular``) that is not a whole number
    of periods (±max_jitter) or spans another number of rows, else (0, −1)."""
    tt, rr = (t, rows) if last is None else (np.r_[last[0], t], np.r_[last[1], rows])
    steps = np.diff(tt)
    if np.any(steps <= 0):
        return 1, int(np.flatnonzero(steps <= 0)[0])
    if regular:
        # a step may span skipped rows: it must then be a whole number of periods
        skipped = np.diff(rr) - 1
        ratio = steps / dt
        off = np.abs(ratio - np.maximum(np.round(ratio), 1)) > max_jitter
        off |= np.round(ratio) != skipped + 1
        if off.any():
            return 2, int(np.flatnonzero(off)[0])
    return 0, -1


def rows_to_lines(rows: np.ndarray) -> np.ndarray:
    return np.asarray(rows, dtype=int) + 2


def _split_rows_py(values, base, n, valid, t_o, q_o, dq_o, tau_o, w_o, rows_o):
    """One pass over a block of a log (rows, columns in ``log_columns`` order): valid[i] =
    every field of row i finite; the valid rows' fields copied, in order, into t, q and q̇
    (floating coordinates: a fixed base's three columns zero), τ, wrench and their row
    indices. Returns the number of valid rows."""
    T, C = values.shape
    pad = 3 - base
    i0 = 1 + 2 * (base + n)
    k = 0
    for i in range(T):
        ok = True
        for j in range(C):
            if not math.isfinite(values[i, j]):
                ok = False
                break
        valid[i] = ok
        if not ok:
            continue
        t_o[k] = values[i, 0]
        for j in range(pad):
            q_o[k, j] = 0.0
            dq_o[k, j] = 0.0
        for j in range(base + n):
            q_o[k, pad + j] = values[i, 1 + j]
            dq_o[k, pad + j] = values[i, 1 + base + n + j]
        for j in range(n):
            tau_o[k, j] = values[i, i0 + j]
        for j in range(3):
            w_o[k, j] = values[i, i0 + n + j]
        rows_o[k] = i
        k += 1
    return k


def _check_steps_py(t, rows, has_last, last_t, last_row, dt, max_jitter, regular):
    """The time steps of tt = [last_t if has_last] + t (file rows rr likewise): (1, k) if step k
    (tt[k] → tt[k+1]) does not increase (the first such); else, if ``regular``, (2, k) for the
    first step that is not a whole number of periods dt (±max_jitter) or whose number of periods
    is not the rows it spans; else (0, −1). The tests of ``LogReader._validate``."""
    off0 = 1 if has_last else 0
    m = len(t) + off0 - 1
    for k in range(m):
        a = last_t if (has_last and k == 0) else t[k - off0]
        if t[k + 1 - off0] - a <= 0:
            return 1, k
    if regular:
        for k in range(m):
            a = last_t if (has_last and k == 0) else t[k - off0]
            ra = last_row if (has_last and k == 0) else rows[k - off0]
            ratio = (t[k + 1 - off0] - a) / dt
            r = np.rint(ratio)
            if abs(ratio - max(r, 1.0)) > max_jitter or r != rows[k + 1 - off0] - ra:
                return 2, k
    return 0, -1


def split_rows(values, base, n):
    """(valid, t, q, q̇, τ, wrench, rows) of a log block with the compiled ``_split_rows_py``."""
    k = _LOOPS.get()
    values = np.asarray(values, float)        # any layout: row- or column-major, or a slice
    T = len(values)
    valid = np.empty(T, np.bool_)
    t, rows = np.empty(T), np.empty(T, np.int64)
    q, dq = np.empty((T, n + 3)), np.empty((T, n + 3))
    tau, w = np.empty((T, n)), np.empty((T, 3))
    m = k["split"](values, base, n, valid, t, q, dq, tau, w, rows)
    if m < T:
        t, q, dq, tau, w, rows = t[:m], q[:m], dq[:m], tau[:m], w[:m], rows[:m]
    return valid, t, q, dq, tau, w, rows


def check_steps(t, rows, last, dt, max_jitter, regular):
    """``_check_steps_py`` compiled; ``last``: (t, row) of the previous valid row or None."""
    k = _LOOPS.get()
    has = last is not None
    return k["steps"](t, rows, has, float(last[0]) if has else 0.0, int(last[1]) if has else 0,
                      float(dt), float(max_jitter), bool(regular))


_LOOPS = compiled.Loops(lambda: {"split": compiled.jit(_split_rows_py),
                                 "steps": compiled.jit(_check_steps_py)})


def prefetch(chunks, depth: int = 2):
    """Iterate ``chunks`` (e.g. a LogReader) in a background thread, up to ``depth`` chunks
    ahead, so that parsing the next chunk overlaps the work on this one (the C parser and
    numpy release the GIL). Exceptions (an InputError naming a line) are re-raised here, in
    order; memory stays bounded by ``depth`` chunks. Closing the generator stops the thread."""
    import queue
    import threading

    q: queue.Queue = queue.Queue(maxsize=depth)
    stop = threading.Event()
    done = object()

    def work():
        try:
            for chunk in chunks:
                while not stop.is_set():
                    try:
                        q.put((chunk, None), timeout=0.1)
                        break
                    except queue.Full:
                        continue
                if stop.is_set():
                    return
            q.put((done, None))
        except BaseException as exc:          # noqa: BLE001 — handed to the consumer
            q.put((None, exc))

    thread = threading.Thread(target=work, name="log-prefetch", daemon=True)
    thread.start()
    try:
        while True:
            item, exc = q.get()
            if exc is not None:
                raise exc
            if item is done:
                return
            yield item
    finally:
        stop.set()
