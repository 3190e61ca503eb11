"""`estimate --out OUT.csv`: the compiled row formatter (estimator.outframe.format_rows) writes
the bytes pyarrow's CSV writer writes for the same rounded values (the reference)."""

import io

import numpy as np
import pyarrow as pa
import pyarrow.csv as pc

from estimator import compiled
from estimator.outframe import COLUMNS, FLOATS, FrameWriter, format_rows, round_significant
from estimator.contact_estimate import ContactEstimate


def _part(T, seed, lo=-13.5, hi=30.5):
    """Rows with values over 44 decades (every branch of the format: plain, 0.000…, d.ddde±x),
    values with few digits (1.5, 100, 0.001), NaN, ±inf, ±0, and links from −1 to 3."""
    rng = np.random.default_rng(seed)

    def col():
        x = rng.choice([-1.0, 1.0], T) * 10.0 ** rng.uniform(lo, hi, T)
        short = rng.random(T) < 0.2
        x[short] = np.round(rng.normal(size=short.sum()) * 10.0 ** rng.integers(-7, 11, short.sum()), 3)
        for value, share in ((np.nan, 0.05), (0.0, 0.01), (-0.0, 0.01), (np.inf, 0.01), (-np.inf, 0.01)):
            x[rng.random(T) < share] = value
        return x

    cols = [col() for _ in range(7)]
    return ContactEstimate(t=cols[0], contact=rng.random(T) < 0.3, link=rng.integers(-1, 4, T),
                           alpha=cols[1], Fx=cols[2], Fz=cols[3], px=cols[4], pz=cols[5],
                           rnorm=cols[6], condition=cols[1], reason=np.zeros(T, np.int8),
                           residual=np.zeros((T, 5)))


def _pyarrow_rows(part) -> bytes:
    cols = {"t": part.t, "contact": part.contact.astype(np.int8), "link": part.link.astype(np.int64),
            "alpha": part.alpha, "Fx": part.Fx, "Fz": part.Fz, "px": part.px, "pz": part.pz,
            "rnorm": part.rnorm}
    table = pa.table({c: (round_significant(cols[c]) if c in FLOATS else cols[c]) for c in COLUMNS})
    buf = io.BytesIO()
    pc.write_csv(table, buf, pc.WriteOptions(include_header=False, quoting_style="none"))
    return buf.getvalue()


def test_formatter_writes_pyarrows_bytes():
    assert compiled.available()
    for seed in range(3):
        part = _part(100_000, seed)
        mine = format_rows(part)
        assert mine is not None
        ref = _pyarrow_rows(part)
        bad = [(a, b) for a, b in zip(mine.split(b"\n"), ref.split(b"\n")) if a != b]
        assert not bad and mine == ref, bad[:3]
    # halfway and boundary values: 9/10 digits after rounding up, decades, the plain/exponent edges
    edge = np.array([0.9999999995, 9.9999999995, 999999999.5, 9999999999.0, 1e10, 1e-6, 9.999999999e-7,
                     1e-7, 0.1, 0.5, 1.0000000005, 123456789.5, 2.5e-14, 9.9e29, 1e30])
    part = ContactEstimate(t=edge, contact=edge > 1, link=np.arange(len(edge)), alpha=-edge, Fx=edge,
                           Fz=edge, px=edge, pz=edge, rnorm=edge, condition=edge,
                           reason=np.zeros(len(edge), np.int8), residual=np.zeros((len(edge), 5)))
    assert format_rows(part) == _pyarrow_rows(part)


def test_values_round_significant_keeps_go_through_pyarrow(tmp_path, monkeypatch):
    """|x| < 1e-14 or ≥ 1e31 (kept with 17 digits): the formatter declines the part and the
    writer uses pyarrow's, so the file is the same with the compiled loops or without."""
    tiny = _part(2000, 7, lo=-20, hi=40)
    assert format_rows(tiny) is None
    parts = [_part(3000, 8), tiny, _part(500, 9)]
    files = []
    for use_compiled in (True, False):
        monkeypatch.setattr(compiled, "ENABLED", use_compiled)
        path = tmp_path / f"out_{use_compiled}.csv"
        with FrameWriter(path) as w:
            for p in parts:
                w.write(p)
        files.append(path.read_bytes())
    assert files[0] == files[1]
    assert files[0].startswith(b"t,contact,link,alpha,Fx,Fz,px,pz,rnorm\n")
    assert files[0].count(b"\n") == 1 + 5500
    empty = tmp_path / "empty.csv"
    with FrameWriter(empty):
        pass
    assert empty.read_bytes() == b"t,contact,link,alpha,Fx,Fz,px,pz,rnorm\n"
