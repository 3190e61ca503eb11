"""Properties of the parsers (Hypothesis): for ANY input they return a value that obeys their
contract or raise InputError (the CLI's one line, exit 2) — never another exception, never a
value outside its declared range. Covered: the log reader (random CSV text and headers), TOML
fields through the schema layer (numbers, vectors with ranges, unknown keys), physical ranges
(userio.ranges.Range), the timing (instant|mean|delay:S), false-alarm-rate and --contact / --quiet-window option parsers."""

import math

import numpy as np
import pytest

hypothesis = pytest.importorskip("hypothesis")
from hypothesis import HealthCheck, given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

from userio.errors import InputError  # noqa: E402
from userio.ranges import Range  # noqa: E402

PROPS = settings(max_examples=60, deadline=None, derandomize=True, database=None,
                 suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])

numbers = st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.integers(-10 ** 30, 10 ** 30),
                    st.booleans(), st.text(max_size=5), st.none(), st.lists(st.floats(), max_size=3))
tokens = st.one_of(st.sampled_from(["nan", "inf", "-inf", "1e999", "-1", "0", "1e-320", "abc", "",
                                    " ", "0x10", "١", "1,5", "1e308", "2e-3", "0.5"]),
                   st.floats(allow_nan=True, allow_infinity=True).map(repr),
                   st.text(max_size=8))


@PROPS
@given(value=numbers, lo=st.one_of(st.none(), st.floats(-1e6, 1e6)), width=st.floats(0, 1e6))
def test_range_check_returns_a_finite_value_inside_or_raises(value, lo, width):
    hi = None if lo is None else lo + width
    rng = Range(lo, hi, "m")
    try:
        v = rng.check(value, "field")
    except InputError as exc:
        assert str(exc).startswith("field:")
        return
    assert math.isfinite(v) and (lo is None or v >= lo) and (hi is None or v <= hi)


@PROPS
@given(text=st.one_of(tokens, tokens.map(lambda t: "delay:" + t), st.sampled_from(
    ["instant", "mean", "MEAN", " delay:0.0005 ", "delay:", "delay:1e300", "delay:100", "delay:-1"])))
def test_timing_parser(text):
    from estimator.timing import parse

    try:
        kind, delay = parse(text, "--timing")
    except InputError as exc:
        assert str(exc).startswith("--timing:")
        return
    assert kind in ("instant", "mean", "delay") and 0 <= delay <= 1.0


@PROPS
@given(value=tokens, unit=st.sampled_from(["/h", "/s", "/sample", "/min", "", "/"]))
def test_false_alarm_rate_parser(value, unit):
    from estimator.noise import parse_rate, per_sample_rate

    try:
        v, u = parse_rate(value + unit)
        alpha = per_sample_rate(v, u, 1e-3)
    except InputError as exc:
        assert str(exc).startswith("--false-alarm-rate:")
        return
    assert 1e-15 <= alpha <= 0.5


@PROPS
@given(text=st.one_of(tokens, st.lists(tokens, min_size=1, max_size=4).map(",".join)))
def test_propagate_contact_option(text):
    """`--contact LINK,ALPHA`: exactly two values, or one line; never a dropped value."""
    import argparse

    from torquebench.commands import propagate

    parser = argparse.ArgumentParser()
    propagate.add_arguments(parser)                    # every option at its default, as the CLI has it
    args = parser.parse_args([])
    args.json, args.contact, args.force, args.grid, args.draws = False, text, "7,-1.0", 0, 0
    try:
        propagate.run(args)
    except InputError as exc:
        msg = str(exc)
        parts = text.split(",")
        if len(parts) != 2:
            assert msg.startswith("--contact:"), msg       # refused for the count, not later
        return
    pytest.fail("grid 0 must be refused")                  # reached only if --contact passed


@PROPS
@given(t0=tokens, t1=tokens, extra=st.sampled_from(["", ":3"]))
def test_quiet_window_option(t0, t1, extra):
    from types import SimpleNamespace

    from torquebench.commands.estimate import _detector_options

    args = SimpleNamespace(false_alarm_rate="1/h", quiet_window=f"{t0}:{t1}{extra}", torque_sigma=None,
                           ft_sigma=None, velocity_sigma=None, encoder_counts=None)
    try:
        _, quiet, _ = _detector_options(args, 2)
    except InputError as exc:
        assert str(exc).startswith("--quiet-window:")
        return
    assert len(quiet) == 2 and not extra


HEADER = "t,q1,q2,dq1,dq2,tau1,tau2,Fx,Fz,My"
cell = st.one_of(st.floats(-1e3, 1e3).map(repr), tokens)


@PROPS
@given(header=st.one_of(st.just(HEADER), st.text(max_size=60),
                        st.lists(st.sampled_from(HEADER.split(",") + ["x", "q3", "tau9", ""]),
                                 min_size=1, max_size=12).map(",".join)),
       rows=st.lists(st.lists(cell, min_size=0, max_size=12), max_size=30),
       regular=st.booleans())
def test_log_reader_returns_a_valid_log_or_one_input_error(tmp_path, header, rows, regular):
    from estimator.log_reader import read_log

    lines = [header]
    for k, r in enumerate(rows):
        if regular and r:
            r = [repr(k * 1e-3)] + r[1:]
        lines.append(",".join(r))
    path = tmp_path / "log.csv"
    path.write_bytes(("\n".join(lines) + "\n").encode("utf-8", "replace"))
    try:
        log = read_log(path)
    except InputError as exc:
        assert str(path) in str(exc) or "chunk" in str(exc), str(exc)
        return
    T = len(log.t)
    assert T >= 1 and np.all(np.isfinite(log.t)) and np.all(np.diff(log.t) > 0)
    assert log.q.shape == (T, log.n_links + 3) and log.tau_Nm.shape == (T, log.n_links)
    assert np.all(np.isfinite(log.q)) and np.all(np.isfinite(log.tau_meas))
    assert np.all(np.abs(log.q[:, 3:]) <= 2 * math.pi)


@PROPS
@given(data=st.binary(max_size=300))
def test_log_reader_on_binary_garbage(tmp_path, data):
    from estimator.log_reader import read_log

    path = tmp_path / "g.csv"
    path.write_bytes(data)
    try:
        read_log(path)
    except InputError:
        pass


# ----------------------------------------------------------------------------- the schema layer
def _schema_model():
    from userio.schema.base import Field, Model, num, vector

    class Table(Model):
        k: num(Range(-5.0, 5.0, "m"), gt=-3.0) = Field(1.0)
        v: vector(2, Range(0.0, 1e3, "N"), ge=0) = Field((0.0, 0.0))

    class File(Model):
        table: Table = Field(Table())

    return File


@PROPS
@given(value=numbers, key=st.sampled_from(["k", "v", "kk", "w"]))
def test_schema_fields_never_pass_nonsense(value, key):
    from userio.schema import parse

    File = _schema_model()
    try:
        t = parse(File, {"table": {key: value}}, "x.toml").table
    except InputError as exc:
        msg = str(exc)
        assert msg.startswith("x.toml: table.") and "\n" not in msg
        if key in ("kk", "w"):
            assert "unknown field" in msg
        return
    assert key in ("k", "v")
    assert isinstance(t.k, float) and math.isfinite(t.k) and -3.0 < t.k <= 5.0
    assert len(t.v) == 2 and all(math.isfinite(x) and 0 <= x <= 1e3 for x in t.v)
