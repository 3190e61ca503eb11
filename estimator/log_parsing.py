"""A log file's bytes into rows of floats, the same numbers whichever parser reads them.

pyarrow's multithreaded CSV parser works on byte blocks cut at line ends (``byte_blocks``); a
block it cannot take exactly as pandas would (a parse error, a field it reads as NaN/inf that is
not one of pandas' NA spellings) returns None from ``arrow_values`` and goes to pandas, which
names a bad field's line and column (``read_text_values``). Both parsers round decimal strings
correctly (``pandas_kw``). Parquet columns are read from their Arrow buffers (``fill_floats``).
The header is sized before any parser sees it (``check_header``). Used by estimator.log_reader.
"""

from __future__ import annotations

import numpy as np

from userio.errors import InputError


def file_line(row_index: int) -> int:
    """1-based file line of data row ``row_index`` (the header is line 1)."""
    return int(row_index) + 2


NA_VALUES = ["nan", "-nan", "+nan", "NaN", "NA", "null", ""]
# pandas' default NA spellings (keep_default_na) and ours: a field pyarrow reads as null is one of these
PANDAS_NA = sorted(set(NA_VALUES) | {"#N/A", "#N/A N/A", "#NA", "-1.#IND", "-1.#QNAN", "-NaN", "1.#IND",
                                    "1.#QNAN", "<NA>", "N/A", "NULL", "None", "n/a"})
CSV_BLOCK_BYTES = 1 << 23            # at most 8 MiB of CSV text per pyarrow parse (~40 k rows, 2 links)
CSV_MIN_BLOCK_BYTES = 1 << 16        # and at least 64 KiB
CSV_THREADS = True                   # pyarrow parses a block on its thread pool


def read_text_values(path, source: str, names: list[str], cols: list[str], row0: int = 0,
                      nrows: int | None = None) -> np.ndarray:
    """Slow path: parse data rows row0 … row0 + nrows as text to name the first non-numeric
    field (line, column)."""
    import pandas as pd

    try:
        frame = pd.read_csv(path, dtype=str, keep_default_na=False, skipinitialspace=True,
                            skiprows=range(1, 1 + row0), nrows=nrows)
    except (pd.errors.ParserError, UnicodeDecodeError) as exc:
        msg = str(exc).strip().splitlines()[-1] if str(exc).strip() else type(exc).__name__
        raise InputError(f"{source}: not a readable CSV log: {msg}") from None
    frame.columns = names
    values = np.empty((len(frame), len(cols)))
    for j, col in enumerate(cols):
        text = frame[col].str.strip()
        num = pd.to_numeric(text, errors="coerce").to_numpy(dtype=float)
        bad = np.isnan(num) & ~text.isin(PANDAS_NA).to_numpy()      # what pandas reads as NaN
        if bad.any():
            i = int(np.flatnonzero(bad)[0])
            raise InputError(f"{source}: line {file_line(row0 + i)}, column '{col}': "
                             f"{frame[col].iloc[i]!r} is not a number")
        values[:, j] = num
    return values


def pandas_kw() -> dict:
    """pandas.read_csv options of a log: floats correctly rounded (pandas ≥ 3 by default; before,
    ``float_precision="round_trip"``), as pyarrow parses them."""
    import pandas as pd

    kw = dict(skipinitialspace=True, dtype=float, engine="c", na_values=NA_VALUES)
    if int(pd.__version__.split(".")[0]) < 3:
        kw["float_precision"] = "round_trip"
    return kw


def reblock(blocks, size: int | None):
    """Arrays of rows re-cut into arrays of ``size`` rows (the last shorter); None: one array."""
    held, n_held = [], 0
    for values in blocks:
        held.append(values)
        n_held += len(values)
        while size is not None and n_held >= size:
            block = np.concatenate(held) if len(held) > 1 else held[0]
            yield block[:size]
            rest = block[size:]
            held, n_held = ([rest] if len(rest) else []), len(rest)
    if held:
        yield np.concatenate(held) if len(held) > 1 else held[0]


MAX_HEADER_BYTES = 1 << 16          # a log header: ≤ 64 KiB (a 100-joint robot's needs ~3 KiB)
MAX_LOG_COLUMNS = 1024               # ≤ 1 + 2·(N+3) + N + 3 columns for N ≤ ~250 joints


def check_header(path, source: str) -> None:
    """Size the header before any parser sees it: the first line must end within
    MAX_HEADER_BYTES and hold at most MAX_LOG_COLUMNS fields (a 120k-column or binary file is
    refused in one line instead of being parsed)."""
    with open(path, "rb") as f:
        line = f.readline(MAX_HEADER_BYTES + 1)
    if not line:
        return
    n = line.count(b",") + 1
    more = "more than " if len(line) > MAX_HEADER_BYTES else ""
    if n > MAX_LOG_COLUMNS:
        raise InputError(f"{source}: line 1 has {more}{n} columns, above the {MAX_LOG_COLUMNS} of any "
                         "robot's log (t, base, joints, rates, torques, wrench); is it the right file?")
    if more:
        raise InputError(f"{source}: line 1 is longer than {MAX_HEADER_BYTES // 1024} KiB: not a log "
                         "header (a binary file, or every sample on one line?)")


def simple_header(path):
    """(first line, names) if the file's first line is plain comma-separated names (letters,
    digits, _; spaces around commas; distinct), which pandas reads as the same names; else None."""
    import re

    with open(path, "rb") as f:
        line = f.readline(1 << 16)
    if not re.fullmatch(rb" *[A-Za-z_]\w*(?: *, *[A-Za-z_]\w*)* *\r?\n", line):
        return None
    names = [c.strip() for c in line.decode("ascii").split(",")]
    return (line, names) if len(set(names)) == len(names) else None


def byte_blocks(path, offset: int, size: int | None = None):
    """The file's bytes from ``offset`` in blocks (bytes or memoryview) of about ``size``
    (CSV_BLOCK_BYTES), each ending at a line end (the last: at the end of the file)."""
    size = size or CSV_BLOCK_BYTES
    with open(path, "rb") as f:
        f.seek(offset)
        rest = b""
        while True:
            data = f.read(size)
            if not data:
                break
            cut = data.rfind(b"\n") + 1
            if cut == 0:                        # no line end in this read: keep reading
                rest += data
                continue
            yield rest + data[:cut] if rest else memoryview(data)[:cut]     # no copy
            rest = data[cut:]
        if rest:
            yield rest


def arrow_values(body, names: list[str], cols: list[str]) -> np.ndarray | None:
    """The rows of a block of CSV data lines as floats (rows, ``cols``) parsed by pyarrow, or
    None where pandas might read it differently: any parse error (a non-numeric field, a row
    with too few or too many fields, a whitespace-only line), or a field pyarrow reads as NaN/inf
    that is not one of pandas' NA spellings (``nan(1)``, ``NAN``, ``inf`` ...: pandas decides)."""
    import pyarrow as pa
    import pyarrow.csv as pc

    f64 = pa.float64()
    try:
        table = pc.read_csv(
            pa.BufferReader(pa.py_buffer(body)),
            read_options=pc.ReadOptions(column_names=names, use_threads=CSV_THREADS, block_size=1 << 20),
            parse_options=pc.ParseOptions(ignore_empty_lines=True),
            convert_options=pc.ConvertOptions(column_types={c: f64 for c in names},
                                              null_values=PANDAS_NA, strings_can_be_null=True,
                                              quoted_strings_can_be_null=True))
    except (pa.ArrowInvalid, pa.ArrowNotImplementedError, pa.ArrowTypeError, ValueError):
        return None
    out = np.empty((len(cols), table.num_rows)).T          # column-major: columns copied whole
    nulls = None
    for j, c in enumerate(cols):
        column = table.column(c)
        fill_floats(out[:, j], column)                   # an NA spelling (null): NaN, as pandas reads it
        if column.null_count:
            nulls = np.zeros(out.shape, bool) if nulls is None else nulls
            fill_floats(nulls[:, j], column, null_mask=True)
    with np.errstate(all="ignore"):
        suspect = not np.isfinite(out.sum(axis=0)).all()     # a NaN/inf (or a sum overflowing)
    if suspect:
        weird = ~np.isfinite(out)
        if nulls is not None:
            weird &= ~nulls
        if weird.any():
            return None
    for c in names:                                 # pandas refuses any non-numeric column
        if c not in cols and not pa.types.is_floating(table.column(c).type):
            return None
    return out


def fill_floats(dst: np.ndarray, column, null_mask: bool = False) -> None:
    """dst[:] = a float64 pyarrow ChunkedArray's values (nulls as NaN), or its null mask, read
    from the Arrow buffers chunk by chunk (pyarrow's to_numpy would import pandas)."""
    i = 0
    for chunk in getattr(column, "chunks", [column]):          # a ChunkedArray or an Array
        n, off = len(chunk), chunk.offset
        validity, data = chunk.buffers()[:2]
        invalid = None
        if chunk.null_count:
            bits = np.unpackbits(np.frombuffer(validity, np.uint8), bitorder="little", count=off + n)
            invalid = bits[off:] == 0
        if null_mask:
            dst[i:i + n] = False if invalid is None else invalid
        else:
            dst[i:i + n] = np.frombuffer(data, np.float64, count=n, offset=8 * off)
            if invalid is not None:
                dst[i:i + n][invalid] = np.nan
        i += n
