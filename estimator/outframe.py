"""The per-sample estimate written chunk by chunk: ``t,contact,link,alpha,Fx,Fz,px,pz,rnorm``.

CSV (pyarrow's CSV writer; floats rounded to 9 significant digits first, x → rint(x·10^(8−e))/10^(8−e)
with e = ⌊log10|x|⌋, which the writer then prints in at most 9–10 digits, NaN as ``nan``), or
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


def round_significant(x: np.ndarray, digits: int = 9) -> np.ndarray:
    """x rounded to ``digits`` significant decimal digits (NaN/inf/0 kept)."""
    x = np.asarray(x, float)
    a = np.abs(x)
    ok = np.isfinite(a) & (a > 0)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        e = np.floor(np.log10(np.where(ok, a, 1.0)))
        scale = 10.0 ** (digits - 1 - e)
        y = np.rint(x * scale) / scale
    return np.where(ok & np.isfinite(y), y, x)


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
        table = _table(part)
        if not self.parquet:
            import pyarrow as pa

            table = pa.table({c: (round_significant(table[c].to_numpy()) if c in FLOATS else table[c])
                              for c in COLUMNS})
        if self._writer is None:
            if self.parquet:
                import pyarrow.parquet as pq

                self._writer = pq.ParquetWriter(str(self.tmp), table.schema)
            else:
                import pyarrow.csv as pc

                try:
                    opts = pc.WriteOptions(quoting_style="none", quoting_header="none",
                                           batch_size=16384)
                except TypeError:                     # pyarrow < 19: the header is quoted
                    opts = pc.WriteOptions(quoting_style="none", batch_size=16384)
                self._writer = pc.CSVWriter(str(self.tmp), table.schema, write_options=opts)
        self._writer.write_table(table)
        self.rows += table.num_rows

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
