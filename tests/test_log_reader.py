"""The CSV log reader's two parsers give the same log: pyarrow (the fast path, on byte blocks)
and pandas (the fallback that names a bad field's line), value for value to the last bit."""

import numpy as np
import pytest

import estimator.log_parsing as P
from userio.errors import InputError
from estimator.log import log_columns
from estimator.log_reader import LogReader, read_log
from estimator.robot import paper_leg

ROBOT = paper_leg()
NAMES = log_columns(2, True)
# decimal strings at and around the halfway points between doubles, and long ones: a parser
# that is not correctly rounded gets some of these wrong in the last bit
HARD = ["1.00000000000000011102230246251565404236316680908203125",      # 1 + 2^-53: ties to even
        "1.00000000000000011102230246251565404236316680908203124",
        "1.00000000000000011102230246251565404236316680908203126",
        "0.3000000000000000166533453693773481063544750213623046875",
        "0.1234567890123456789012345678901234567890", "2.2250738585072011e-308",
        "9007199254740993", "4.9406564584124654e-324", "0.500000000000000166533453693773481",
        "-0.00000000000000000000000000000000000001234567890123456789"]


def _rows(T, seed=0, hard=True):
    """Data rows (lists of field strings) of a floating-base 2-link log, 1 kHz."""
    rng = np.random.default_rng(seed)
    rows = []
    for k in range(T):
        vals = rng.normal(0, 0.5, len(NAMES) - 1) * 10.0 ** rng.integers(-6, 1, len(NAMES) - 1)
        fields = [f"{v:.{int(rng.integers(3, 25))}g}" if rng.random() < 0.5 else repr(float(v))
                  for v in vals]
        if hard:
            j = int(rng.integers(0, len(fields)))
            if j not in (3, 4):                          # q1, q2 stay below 2π
                fields[j] = HARD[k % len(HARD)]
        rows.append([repr(k * 1e-3)] + fields)
    return rows


def _write(path, rows, header=None):
    text = ",".join(header or NAMES) + "\n" + "\n".join(",".join(r) for r in rows) + "\n"
    path.write_text(text)
    return path


def _read(path, chunk=None, mode="arrow", monkeypatch=None):
    """The log's arrays and skipped lines through one of the three parsers."""
    if mode == "pandas-blocks":          # every byte block through pandas
        monkeypatch.setattr(P, "arrow_values", lambda *a: None)
    elif mode == "pandas-file":          # the whole file through pandas' chunked reader
        monkeypatch.setattr(LogReader, "_csv_header_line", lambda self: None)
    reader = LogReader(path, ROBOT, chunk_samples=chunk)
    chunks = list(reader)
    monkeypatch.undo()
    cat = {f: np.concatenate([getattr(c, f) for c in chunks]) for f in ("t", "q", "dq", "tau_Nm", "wrench")}
    return cat, reader.skipped_lines.tolist(), [len(c.t) for c in chunks]


def _same(a, b):
    for f in a:
        assert a[f].shape == b[f].shape and np.array_equal(a[f], b[f]), f


def test_last_bit_values_equal_through_both_parsers_and_python_float(tmp_path, monkeypatch):
    rows = _rows(3000)
    path = _write(tmp_path / "bits.csv", rows)
    fast, _, _ = _read(path, 700, "arrow", monkeypatch)
    for mode in ("pandas-blocks", "pandas-file"):
        slow, _, _ = _read(path, 700, mode, monkeypatch)
        _same(fast, slow)
    ref = np.array([[float(v) for v in r] for r in rows])    # correctly rounded (Python's float)
    assert np.array_equal(fast["tau_Nm"], ref[:, 11:13]) and np.array_equal(fast["wrench"], ref[:, 13:16])
    assert np.array_equal(fast["q"], ref[:, 1:6]) and np.array_equal(fast["t"], ref[:, 0])


def test_spellings_and_padding_pandas_accepts_read_the_same(tmp_path, monkeypatch):
    """Whitespace-padded and quoted fields, every NA spelling pandas knows, inf: the same values
    and the same skipped lines through pyarrow, pandas per block and pandas on the whole file."""
    rows = _rows(2500, seed=1, hard=False)
    odd = {100: " nan", 200: "N/A", 300: "NULL", 400: "None", 500: "#N/A", 600: "inf",
           700: "-Infinity", 800: "", 900: "  ", 1000: '"nan"', 1100: "-NaN", 1200: "1e400"}
    for k, text in odd.items():
        rows[k][13] = text
    rows[50][2] = "  0.25  "
    rows[60][3] = '"0.125"'
    rows[70][4] = '" 0.5"'
    rows[80][5] = "\t-0.75"
    path = _write(tmp_path / "odd.csv", rows)
    monkeypatch.setattr(P, "CSV_MIN_BLOCK_BYTES", 512)       # many byte blocks, few fall back
    fast, skipped, sizes = _read(path, 333, "arrow", monkeypatch)
    assert skipped == [k + 2 for k in sorted(odd)] and sum(sizes) == 2500 - len(odd)
    assert fast["q"][50 - 0, 1] == 0.25 and fast["q"][60, 2] == 0.125 and fast["q"][70, 3] == 0.5
    for mode in ("pandas-blocks", "pandas-file"):
        monkeypatch.setattr(P, "CSV_MIN_BLOCK_BYTES", 512)
        slow, skipped_slow, sizes_slow = _read(path, 333, mode, monkeypatch)
        _same(fast, slow)
        assert skipped_slow == skipped and sizes_slow == sizes


@pytest.mark.parametrize("text", ["NAN", "nan(1)", "abc", "1.5.5", "0x10"])
def test_fields_pandas_refuses_name_their_line_on_the_fast_path(tmp_path, monkeypatch, text):
    """pyarrow reads 'NAN' and 'nan(1)' as NaN but pandas refuses them: the block goes to pandas,
    which names the line and column, with small byte blocks (the row is deep in the file)."""
    rows = _rows(3000, seed=2, hard=False)
    rows[2700][4] = text                     # q1
    path = _write(tmp_path / "bad.csv", rows)
    monkeypatch.setattr(P, "CSV_MIN_BLOCK_BYTES", 1024)
    with pytest.raises(InputError, match=r"bad.csv: line 2702, column 'q1': .* is not a number"):
        list(LogReader(path, ROBOT, chunk_samples=100))
    with pytest.raises(InputError, match=r"line 2702, column 'q1'"):
        list(LogReader(path, ROBOT, chunk_samples=None))


def test_chunk_sizes_and_byte_blocks_do_not_change_the_log(tmp_path, monkeypatch):
    path = _write(tmp_path / "log.csv", _rows(4000, seed=3))
    whole, _, sizes = _read(path, None, "arrow", monkeypatch)
    assert sizes == [4000]
    for chunk, block in ((97, 300), (1025, 4096), (4000, 1 << 20)):
        monkeypatch.setattr(P, "CSV_MIN_BLOCK_BYTES", block)
        part, _, sizes = _read(path, chunk, "arrow", monkeypatch)
        _same(whole, part)


def test_extra_columns_and_crlf(tmp_path, monkeypatch):
    """An extra numeric column is ignored and CRLF line ends read; a non-numeric extra column is
    refused as pandas refuses it."""
    rows = _rows(1500, seed=4)
    ref, _, _ = _read(_write(tmp_path / "ref.csv", rows), 500, "arrow", monkeypatch)
    extra = _write(tmp_path / "extra.csv", [r + ["7.5"] for r in rows], NAMES + ["temp_C"])
    got, _, _ = _read(extra, 500, "arrow", monkeypatch)
    _same(ref, got)
    crlf = tmp_path / "crlf.csv"
    crlf.write_bytes((tmp_path / "ref.csv").read_bytes().replace(b"\n", b"\r\n"))
    got, _, _ = _read(crlf, 500, "arrow", monkeypatch)
    _same(ref, got)
    text = _write(tmp_path / "text.csv", [r + ["ok"] for r in rows], NAMES + ["note"])
    with pytest.raises(InputError, match="text.csv"):
        list(LogReader(text, ROBOT, chunk_samples=500))


def _fixed_rows(rows):
    """The same rows as a fixed-base log (no x, z, theta and their rates)."""
    drop = {1, 2, 3, 6, 7, 8}
    return [[v for i, v in enumerate(r) if i not in drop] for r in rows], log_columns(2, False)


@pytest.mark.parametrize("floating", [True, False], ids=["floating", "fixed"])
def test_compiled_row_split_equals_the_numpy_form(tmp_path, monkeypatch, floating):
    """log_reader.split_rows / check_steps (compiled) against the numpy forms: the same arrays, skipped lines
    and chunk sizes on a log with NaN rows (also at a chunk's first and last row)."""
    from estimator import compiled

    rows = _rows(3000, seed=5)
    for k in (0, 1, 499, 500, 1234, 2999):
        rows[k][10 if k % 2 else 13] = "nan"          # dq2 or Fx
    header = None
    if not floating:
        rows, header = _fixed_rows(rows)
    path = _write(tmp_path / "gaps.csv", rows, header)
    assert compiled.available()
    fast = _read(path, 500, "arrow", monkeypatch)
    monkeypatch.setattr(compiled, "ENABLED", False)
    slow = _read(path, 500, "arrow", monkeypatch)
    _same(fast[0], slow[0])
    assert fast[1] == slow[1] == [2, 3, 501, 502, 1236, 3001] and fast[2] == slow[2]
    if not floating:
        assert np.all(fast[0]["q"][:, :3] == 0) and np.all(fast[0]["dq"][:, :3] == 0)


@pytest.mark.parametrize("use_compiled", [True, False], ids=["compiled", "numpy"])
@pytest.mark.parametrize("edit, message", [
    (lambda rows: rows[1700].__setitem__(0, rows[1699][0]), r"line 1702, column 't': time .* does not increase"),
    (lambda rows: rows[1001].__setitem__(0, repr(1.0014)), r"line 1003, column 't': irregular sampling"),
    (lambda rows: [r.__setitem__(0, repr(float(r[0]) + 5e-4)) for r in rows[500:]], r"line 502, column 't': irregular"),
    (lambda rows: rows[999].__setitem__(0, repr(0.9995)), r"line 1001, column 't': irregular"),  # at a chunk's end
], ids=["repeat", "jitter", "shift", "boundary"])
def test_time_errors_name_the_same_line_compiled_or_not(tmp_path, monkeypatch, use_compiled, edit, message):
    from estimator import compiled

    rows = _rows(2000, seed=6, hard=False)
    edit(rows)
    path = _write(tmp_path / "time.csv", rows)
    monkeypatch.setattr(compiled, "ENABLED", use_compiled)
    with pytest.raises(InputError, match=message):
        list(LogReader(path, ROBOT, chunk_samples=500))


@pytest.mark.parametrize("floating", [True, False], ids=["floating", "fixed"])
def test_compiled_plausibility_sums_match_the_numpy_form(monkeypatch, floating):
    """plausibility.Checker.rows compiled (plausibility.plausibility_rows) against its numpy form, fed
    the same chunks: the same step count, the velocity sums to rounding (summation order), the
    same angle error naming the same column and time."""
    from estimator import compiled
    from estimator.plausibility import Checker

    rng = np.random.default_rng(9)
    T = 5000
    t = np.arange(T) * 1e-3
    q = np.cumsum(rng.normal(0, 1e-3, (T, 5)), axis=0)
    dq = np.gradient(q, t, axis=0) + rng.normal(0, 0.01, (T, 5))
    if not floating:
        q[:, :3] = dq[:, :3] = 0.0
    checkers = []
    for use_compiled in (True, False):
        monkeypatch.setattr(compiled, "ENABLED", use_compiled)
        c = Checker("log.csv", floating, 2)
        for a, b in ((0, 1), (1, 700), (700, 3001), (3001, T)):
            c.rows(t[a:b], q[a:b], dq[a:b])
        checkers.append(c)
    fast, slow = checkers
    assert fast.steps == slow.steps == T - 1
    np.testing.assert_allclose(fast.sums, slow.sums, rtol=1e-12)
    assert fast.scale() == pytest.approx(slow.scale(), rel=1e-12)
    q[3456, 4] = 7.0                                     # q2 beyond 2π
    for use_compiled in (True, False):
        monkeypatch.setattr(compiled, "ENABLED", use_compiled)
        c = Checker("log.csv", floating, 2)
        c.rows(t[:3000], q[:3000], dq[:3000])
        with pytest.raises(InputError, match=r"column 'q2': joint angle 7 rad at t = 3.456 s"):
            c.rows(t[3000:], q[3000:], dq[3000:])


def test_parquet_with_nulls_and_integer_columns_reads_as_the_csv(tmp_path, monkeypatch):
    """Parquet columns read from the Arrow buffers: a null is a skipped row as an empty CSV field
    is, an integer column converts as numpy converts it; sliced batches (chunk 333) included."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    rows = _rows(2000, seed=10, hard=False)
    for r in rows:
        r[1] = str(int(float(r[1]) * 1e6))                 # x as whole numbers
    rows[777][13] = ""
    csv = _write(tmp_path / "log.csv", rows)
    cols = {c: [float(r[i]) if r[i] else None for r in rows] for i, c in enumerate(NAMES)}
    table = pa.table({c: pa.array([int(v) for v in cols[c]], pa.int64()) if c == "x" else
                      pa.array(cols[c], pa.float64()) for c in NAMES})
    parquet = tmp_path / "log.parquet"
    pq.write_table(table, parquet, row_group_size=500)
    a, skipped_a, _ = _read(csv, 333, "arrow", monkeypatch)
    b, skipped_b, _ = _read(parquet, 333, "arrow", monkeypatch)
    _same(a, b)
    assert skipped_a == skipped_b == [779]
    whole = read_log(parquet)                          # four row groups, one log
    assert np.array_equal(whole.t, a["t"]) and whole.skipped_lines.tolist() == [779]
