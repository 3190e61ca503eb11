"""The per-sample estimate written chunk by chunk: ``t,contact,link,alpha,Fx,Fz,px,pz,rnorm``.

CSV (floats rounded to 9–10 significant digits, ``round_significant``, and printed as pyarrow's CSV
writer prints them: in at most as many digits, NaN as ``nan``; a compiled formatter,
``estimator.kernels.format_rows``, writes the same bytes several times faster), or
Parquet (float64, exact) for a ``.parquet`` path. The file is written to a temporary path beside
the target and moved into place on success (``userio.files.atomic_path``): nothing half-written
is left, and an error leaves the old file untouched.
"""

from __future__ import annotations

from contextlib import ExitStack
from pathlib import Path

import numpy as np

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
        compiled formatter (estimator.kernels.format_rows, tested byte for byte against pyarrow)
        where it can, else pyarrow's writer itself."""
        from estimator import kernels

        if self._writer is None:
            self._writer = open(self.tmp, "wb")
            self._writer.write((",".join(COLUMNS) + "\n").encode())
        text = kernels.format_rows(part) if kernels.available() else None
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
    from estimator.pipeline import ContactEstimate

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
