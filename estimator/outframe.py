"""The per-sample estimate written chunk by chunk: ``t,contact,link,alpha,Fx,Fz,px,pz,rnorm``.

CSV (floats rounded to 9–10 significant digits, ``round_significant``, and printed as pyarrow's CSV
writer prints them: in at most as many digits, NaN as ``nan``; a compiled formatter,
``format_rows``, writes the same bytes several times faster), or
Parquet (float64, exact) for a ``.parquet`` path. The file is written to a temporary path beside
the target and moved into place on success (``userio.files.atomic_path``): nothing half-written
is left, and an error leaves the old file untouched.
"""

from __future__ import annotations

from contextlib import ExitStack
from pathlib import Path

import math

import numpy as np

from estimator import compiled

COLUMNS = ["t", "contact", "link", "alpha", "Fx", "Fz", "px", "pz", "rnorm"]
FLOATS = ["t", "alpha", "Fx", "Fz", "px", "pz", "rnorm"]


_POW10 = 10.0 ** np.arange(23)         # exact powers of ten


def round_significant(x: np.ndarray, digits: int = 9) -> np.ndarray:
    """x rounded to ``digits`` (or ``digits`` + 1) significant decimal digits, NaN/inf/0 kept.

    k = digits − 1 − ⌊(e₂ − 1) log₁₀ 2⌋ from the binary exponent e₂ (np.frexp; no log10) is the
    number of decimals to keep (the decimal exponent or one below it); y = rint(x·10^k)/10^k,
    or rint(x/10^−k)·10^−k for k < 0, with exact powers of ten, so y is the double nearest a
    decimal of at most digits + 1 digits and prints as one. |k| > 22 (|x| < 1e−14 or ≥ 1e31 for
    9 digits): x as is (it then prints with up to 17 digits). Relative change ≤ 5·10^−digits."""
    x = np.asarray(x, float)
    _, e2 = np.frexp(x)
    k = (digits - 1) - np.floor((e2 - 1) * 0.30102999566398120).astype(np.int64)
    p = _POW10[np.clip(np.abs(k), 0, 22)]
    with np.errstate(over="ignore", invalid="ignore"):
        y = np.where(k >= 0, np.rint(x * p) / p, np.rint(x / p) * p)
    return np.where(np.isfinite(y) & (x != 0) & (np.abs(k) <= 22), y, x)


_POW10_INT = np.array([10 ** i for i in range(19)], dtype=np.int64)


def _put_uint_py(buf, pos, v, width):
    """Write v ≥ 0 in decimal at buf[pos:], at least ``width`` digits (leading zeros); → new pos."""
    n = 1
    while n < 19 and v >= _POW10_INT[n]:
        n += 1
    if n < width:
        n = width
    end = pos + n
    while n > 0:
        end_i = pos + n - 1
        buf[end_i] = 48 + v % 10
        v //= 10
        n -= 1
    return end


def _put_float_py(buf, pos, x, digits):
    """x rounded to ``digits`` significant digits (round_significant) and printed as
    pyarrow's CSV writer prints that double (its shortest decimal: plain for a decimal exponent
    in [−6, 10), else d.ddde±x; nan, inf, -inf, 0, -0); → new pos, or −1 for the few values
    round_significant leaves as they are (|x| < 1e−14 or ≥ 1e31 at 9 digits)."""
    if x != x:
        buf[pos], buf[pos + 1], buf[pos + 2] = 110, 97, 110            # nan
        return pos + 3
    if x < 0 or (x == 0 and math.copysign(1.0, x) < 0):
        buf[pos] = 45                                                   # -
        pos += 1
    a = abs(x)
    if a == math.inf:
        buf[pos], buf[pos + 1], buf[pos + 2] = 105, 110, 102            # inf
        return pos + 3
    if a == 0:
        buf[pos] = 48
        return pos + 1
    _, e2 = math.frexp(a)
    k = (digits - 1) - int(math.floor((e2 - 1) * 0.30102999566398120))
    if k > 22 or k < -22:
        return -1
    if k >= 0:
        m = np.int64(np.rint(a * _POW10[k]))
    else:
        m = np.int64(np.rint(a / _POW10[-k]))
    # the double nearest m·10^−k prints as m·10^−k without its trailing zeros
    while m % 10 == 0:
        m //= 10
        k -= 1
    nd = 1
    while nd < 19 and m >= _POW10_INT[nd]:
        nd += 1
    e = nd - 1 - k                                                      # decimal exponent
    if -6 <= e < 10:
        if e < 0:
            buf[pos], buf[pos + 1] = 48, 46                             # 0.
            pos += 2
            for _ in range(-e - 1):
                buf[pos] = 48
                pos += 1
            return _put_uint(buf, pos, m, nd)
        if nd <= e + 1:
            pos = _put_uint(buf, pos, m, nd)
            for _ in range(e + 1 - nd):
                buf[pos] = 48
                pos += 1
            return pos
        low = nd - e - 1
        pos = _put_uint(buf, pos, m // _POW10_INT[low], 1)
        buf[pos] = 46
        return _put_uint(buf, pos + 1, m % _POW10_INT[low], low)
    pos = _put_uint(buf, pos, m // _POW10_INT[nd - 1], 1)
    if nd > 1:
        buf[pos] = 46
        pos = _put_uint(buf, pos + 1, m % _POW10_INT[nd - 1], nd - 1)
    buf[pos] = 101                                                      # e
    buf[pos + 1] = 43 if e > 0 else 45
    return _put_uint(buf, pos + 2, abs(e), 1)


def _format_rows_py(t, contact, link, alpha, Fx, Fz, px, pz, rnorm, digits, buf):
    """The rows ``t,contact,link,alpha,Fx,Fz,px,pz,rnorm`` (outframe.COLUMNS) as CSV text in buf;
    → bytes written, or −1 if a value needs pyarrow's writer (``_put_float_py``)."""
    pos = 0
    for i in range(len(t)):
        pos = _put_float(buf, pos, t[i], digits)
        if pos < 0:
            return -1
        buf[pos] = 44
        buf[pos + 1] = 49 if contact[i] else 48
        buf[pos + 2] = 44
        pos += 3
        v = link[i]
        if v < 0:
            buf[pos] = 45
            pos += 1
            v = -v
        pos = _put_uint(buf, pos, v, 1)
        for x in (alpha[i], Fx[i], Fz[i], px[i], pz[i], rnorm[i]):
            buf[pos] = 44
            pos = _put_float(buf, pos + 1, x, digits)
            if pos < 0:
                return -1
        buf[pos] = 10
        pos += 1
    return pos


def format_rows(part, digits: int = 9) -> bytes | None:
    """The CSV rows of an estimate part (no header) as pyarrow's writer prints the part rounded
    by ``round_significant``, or None if a value needs pyarrow's writer (compiled loops only:
    ``compiled.available()``)."""
    k = _LOOPS.get()
    T = len(part.t)
    buf = np.empty(T * (7 * 24 + 30), np.uint8)
    f = [np.ascontiguousarray(a, float) for a in (part.t, part.alpha, part.Fx, part.Fz, part.px,
                                                  part.pz, part.rnorm)]
    n = k["rows"](f[0], np.ascontiguousarray(part.contact, np.bool_),
                  np.ascontiguousarray(part.link, np.int64), *f[1:], int(digits), buf)
    return None if n < 0 else buf[:n].tobytes()


_put_uint = None                # the compiled _put_uint_py and _put_float_py, globals for the rows
_put_float = None


def _build():
    global _put_uint, _put_float
    _put_uint = compiled.jit(_put_uint_py)
    _put_float = compiled.jit(_put_float_py)
    return {"rows": compiled.jit(_format_rows_py)}


_LOOPS = compiled.Loops(_build)


def _table(part):
    import pyarrow as pa

    cols = {"t": part.t, "contact": part.contact.astype(np.int8), "link": part.link.astype(np.int64),
            "alpha": part.alpha, "Fx": part.Fx, "Fz": part.Fz, "px": part.px, "pz": part.pz,
            "rnorm": part.rnorm}
    return pa.table({c: cols[c] for c in COLUMNS})


class FrameWriter:
    """``with FrameWriter(path) as w: w.write(part)`` for each ContactEstimate part, in order."""

    def __init__(self, path, *, overwrite: bool = True):
        self.path = Path(path)
        self.parquet = self.path.suffix.lower() == ".parquet"
        self.overwrite = overwrite
        self._writer = None
        self.rows = 0

    def __enter__(self):
        from userio.files import atomic_path

        self._stack = ExitStack()
        self.tmp = self._stack.enter_context(atomic_path(self.path, overwrite=self.overwrite))
        return self

    def write(self, part) -> None:
        if self.parquet:
            table = _table(part)
            if self._writer is None:
                import pyarrow.parquet as pq

                # dictionary pages only for the small integer columns: on 2 M distinct floats
                # they cost 2.8x the CPU of the whole write and make the file larger
                self._writer = pq.ParquetWriter(str(self.tmp), table.schema,
                                                use_dictionary=["contact", "link"])
            self._writer.write_table(table)
        else:
            self._write_csv(part)
        self.rows += len(part.t)

    def _write_csv(self, part) -> None:
        """The rows as pyarrow's CSV writer prints them rounded by ``round_significant``: the
        compiled formatter (``format_rows``, tested byte for byte against pyarrow) where it can,
        else pyarrow's writer itself."""
        if self._writer is None:
            self._writer = open(self.tmp, "wb")
            self._writer.write((",".join(COLUMNS) + "\n").encode())
        text = format_rows(part) if compiled.available() else None
        if text is not None:
            self._writer.write(text)
            return
        import pyarrow as pa
        import pyarrow.csv as pc

        table = _table(part)
        table = pa.table({c: (round_significant(table[c].to_numpy()) if c in FLOATS else table[c])
                          for c in COLUMNS})
        pc.write_csv(table, self._writer, write_options=pc.WriteOptions(
            include_header=False, quoting_style="none", batch_size=16384))

    def __exit__(self, exc_type, exc, tb):
        try:
            if self._writer is None and exc_type is None:      # an empty estimate: header only
                self.write(_empty_part())
            if self._writer is not None:
                self._writer.close()
        except BaseException as err:                           # noqa: BLE001 — re-raised
            if not self._stack.__exit__(type(err), err, err.__traceback__):
                raise
            return False
        return self._stack.__exit__(exc_type, exc, tb)


def _empty_part():
    from estimator.contact_estimate import ContactEstimate

    e = np.zeros(0)
    return ContactEstimate(t=e, contact=e.astype(bool), link=e.astype(int), alpha=e, Fx=e, Fz=e,
                           px=e, pz=e, rnorm=e, condition=e, reason=e.astype(np.int8),
                           residual=np.zeros((0, 1)))


class BackgroundWriter:
    """Writes a FrameWriter's parts in one background thread (formatting CSV overlaps the next
    chunk's estimate), in order, at most ``depth`` parts queued; ``close()`` waits for the
    last and re-raises a write error."""

    def __init__(self, writer: FrameWriter, depth: int = 2):
        from concurrent.futures import ThreadPoolExecutor

        self.writer = writer
        self.pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="frame-writer")
        self.pending = []
        self.depth = depth

    def write(self, part) -> None:
        self.pending.append(self.pool.submit(self.writer.write, part))
        while len(self.pending) > self.depth:
            self.pending.pop(0).result()

    def close(self) -> None:
        try:
            for f in self.pending:
                f.result()
        finally:
            self.pending = []
            self.pool.shutdown(wait=True, cancel_futures=True)
