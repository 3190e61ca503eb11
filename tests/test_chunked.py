"""The estimator in chunks: the same numbers as the one-shot run, in memory that does not grow
with the log (estimator.stream.EstimatorStream, estimator.log_reader.LogReader, `estimate --out`)."""

import json
import tracemalloc

import numpy as np
import pandas as pd
import pytest

from estimator.detection import DetectorState, debounce_chunk, detect
from userio.errors import InputError
from estimator.estimate import estimate
from estimator.log import write_log
from estimator.log_reader import LogReader, read_log
from estimator.noise import NoiseModel
from estimator.robot import paper_leg
from estimator.synthetic import inverse_dynamics_log, sinusoidal_motion
from torquebench.cli import main

ROBOT = paper_leg()
FIELDS = ["t", "contact", "link", "alpha", "Fx", "Fz", "px", "pz", "rnorm", "condition", "reason",
          "residual"]


def _poked_log(T=1800, seed=0, noise=True):
    """The leg swinging with four pokes on link 2 (α = 0.5), sensor noise of the paper leg."""
    t = np.arange(T) * 1e-3
    q, dq, ddq = sinusoidal_motion(ROBOT, t, frequency_Hz=1.0, base_amplitude=(0.01, 0.01, 0.05))
    active = np.zeros(T, bool)
    for a, b in ((0.50, 0.71), (0.80, 0.87), (1.00, 1.35), (1.60, 1.70)):
        active[(t >= a) & (t < b)] = True
    log, truth = inverse_dynamics_log(ROBOT, t, q, dq, ddq, 2, 0.5, [2.5, -4.0], active=active)
    if noise:
        rng = np.random.default_rng(seed)
        log.wrench = log.wrench + rng.normal(0, [0.1, 0.1, 0.01], log.wrench.shape)
        log.tau_Nm = log.tau_Nm + rng.normal(0, 0.005, log.tau_Nm.shape)
    return log, truth


def _same(a, b):
    for f in FIELDS:
        x, y = getattr(a, f), getattr(b, f)
        assert x.shape == y.shape, f
        assert np.array_equal(x, y, equal_nan=True), f"{f}: max diff {np.nanmax(np.abs(x - y))}"


def _same_intervals(a, b):
    ia, ib = a.intervals(), b.intervals()
    assert len(ia) == len(ib) and ia
    for x, y in zip(ia, ib):
        assert x.keys() == y.keys()
        for k in x:
            if isinstance(x[k], float) and x[k] is not None:
                # interval means are sums in sample order: chunks change only the rounding
                assert x[k] == pytest.approx(y[k], rel=1e-12, abs=1e-15, nan_ok=True), k
            else:
                assert x[k] == y[k], k


@pytest.mark.parametrize("kw", [
    {},                                                         # chi-square, constant covariance
    {"noise": NoiseModel(torque_sigma_Nm=[0.005], ft_sigma=[0.1, 0.1, 0.01],
                         velocity_sigma_rad_per_s=0.01)},       # covariance per posture block
    {"method": "paper"},
    {"threshold": 0.3, "debounce": 3},
    {"expected_contacts": [(2, 1.0)], "threshold": 0.3},
    {"timing": "delay:0.0023"},
    {"timing": "mean", "quiet_window": (0.02, 0.48)},
    {"detector": "cusum"},                                      # sequential test, state carried
    {"detector": "cusum", "quiet_window": (0.02, 0.48)},        # calibrated on the stretch
    {"method": "paper", "quiet_window": (0.02, 0.48)},          # robust isolation thresholds
], ids=["chi2", "chi2-posture", "paper", "debounce", "expected", "delay", "mean-quiet", "cusum",
        "cusum-quiet", "paper-quiet"])
def test_chunks_of_any_size_give_the_one_shot_numbers(kw):
    log, _ = _poked_log()
    ref = estimate(ROBOT, log, stats_samples=400, **kw)
    assert ref.contact.any() and (~ref.contact).any()
    for chunk in (7, 333):           # pokes and noise-floor head straddle the chunk boundaries
        got = estimate(ROBOT, log, stats_samples=400, chunk_samples=chunk, **kw)
        _same(ref, got)
        _same_intervals(ref, got)
        assert got.summary()["flags_during_contact"] == ref.summary()["flags_during_contact"]
        assert {k: v for k, v in got.info.items()} == {k: v for k, v in ref.info.items()}


def test_error_estimates_per_interval_are_streamed():
    log, _ = _poked_log()
    ref = estimate(ROBOT, log)
    got = estimate(ROBOT, log, chunk_samples=11)
    ivs = ref.intervals()
    assert len(ivs) >= 4
    for a, b in zip(ivs, got.intervals()):
        assert a["alpha_error_estimate"] is not None and 0 < a["alpha_error_estimate"] < 0.05
        # the episode's figures are sums over its samples: chunks change only the rounding
        assert a["alpha_error_estimate"] == pytest.approx(b["alpha_error_estimate"], rel=1e-12)
        assert a["px_m_error_estimate"] == pytest.approx(b["px_m_error_estimate"], rel=1e-12)


def test_gaps_from_skipped_rows_across_chunks():
    log, _ = _poked_log()
    keep = np.ones(len(log.t), bool)
    keep[[200, 201, 202, 640, 999]] = False                   # gaps of 4 and 2 periods
    for f in ("t", "q", "dq", "tau_Nm", "wrench"):
        setattr(log, f, getattr(log, f)[keep])
    ref = estimate(ROBOT, log)
    _same(ref, estimate(ROBOT, log, chunk_samples=5))


def test_debounce_state_carries_across_chunks():
    rng = np.random.default_rng(1)
    raw = rng.random(500) < 0.7
    for d in (0, 1, 4):
        want = detect(raw.astype(float), 0.5, d)
        state = DetectorState()
        got = np.concatenate([debounce_chunk(raw[s:s + 3], d, state) for s in range(0, 500, 3)])
        assert np.array_equal(got, want)


def _write_poked_csv(path, T):
    log, _ = _poked_log(T=T, noise=True)
    write_log(log, path)
    return path


def test_reader_chunks_equal_the_whole_log(tmp_path):
    path = _write_poked_csv(tmp_path / "log.csv", 3000)
    whole = read_log(path)
    reader = LogReader(path, ROBOT, chunk_samples=97)
    chunks = list(reader)
    reader.finish()
    assert reader.period_s == pytest.approx(1e-3)
    for f in ("t", "q", "dq", "tau_Nm", "wrench"):
        assert np.array_equal(np.concatenate([getattr(c, f) for c in chunks]), getattr(whole, f))


def test_reader_errors_name_the_line_across_chunks(tmp_path):
    path = _write_poked_csv(tmp_path / "log.csv", 3000)
    frame = pd.read_csv(path)
    frame.loc[2500, "t"] = frame.loc[2499, "t"]
    frame.to_csv(tmp_path / "back.csv", index=False)
    from userio.errors import InputError
    with pytest.raises(InputError, match="line 2502"):
        list(LogReader(tmp_path / "back.csv", ROBOT, chunk_samples=100))
    frame = pd.read_csv(path)
    frame["q2"] = frame["q2"].astype(object)
    frame.loc[2700, "q2"] = "x"
    frame.to_csv(tmp_path / "text.csv", index=False)
    with pytest.raises(InputError, match=r"line 2702, column 'q2'"):
        list(LogReader(tmp_path / "text.csv", ROBOT, chunk_samples=100))


@pytest.mark.parametrize("suffix", [".csv", ".parquet"])
def test_cli_chunked_output_equals_estimate(tmp_path, capsys, suffix):
    path = _write_poked_csv(tmp_path / f"log{suffix}", 2500)
    out = tmp_path / f"est{suffix}"
    code = main(["estimate", str(path), "--out", str(out), "--json", "--chunk-samples", "300"])
    summary = json.loads(capsys.readouterr().out)
    assert code == 0 and summary["chunk_samples"] == 300 and summary["peak_memory_MB"] > 0
    ref = estimate(ROBOT, read_log(path))
    frame = pd.read_csv(out) if suffix == ".csv" else pd.read_parquet(out)
    want = ref.to_frame()
    assert list(frame.columns) == list(want.columns) and len(frame) == len(want)
    for c in want.columns:
        x, y = frame[c].to_numpy(float), want[c].to_numpy(float)
        assert np.array_equal(np.isnan(x), np.isnan(y)), c
        ok = ~np.isnan(y)
        np.testing.assert_allclose(x[ok], y[ok], rtol=1e-8, atol=1e-300, err_msg=c)
    assert summary["contact_samples"] == int(ref.contact.sum())
    assert len(summary["intervals"]) == len(ref.intervals())
    for a, b in zip(summary["intervals"], ref.intervals()):
        alpha = float("nan") if a["alpha"] is None else a["alpha"]          # JSON null = NaN
        assert a["link"] == b["link"] and alpha == pytest.approx(b["alpha"], rel=1e-12, nan_ok=True)
        assert a["alpha_error_estimate"] == b["alpha_error_estimate"]


def _peak_bytes(path, chunk):
    """Peak traced memory of the streaming CLI path over ``path`` (reader → stream → writer)."""
    from estimator.estimate import open_stream
    from estimator.outframe import FrameWriter

    out = path.with_name(path.stem + "_out.csv")
    tracemalloc.start()
    try:
        reader = LogReader(path, ROBOT, chunk_samples=chunk)
        chunks = iter(reader)
        first = next(chunks)
        stream = open_stream(ROBOT, reader, stats_samples=chunk)
        with FrameWriter(out) as writer:
            for part in stream.feed(first):
                writer.write(part)
            for c in chunks:
                for part in stream.feed(c):
                    writer.write(part)
            for part in stream.finish():
                writer.write(part)
        reader.finish()
        return tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()


def test_memory_does_not_grow_with_the_log(tmp_path):
    short = _write_poked_csv(tmp_path / "short.csv", 4000)
    log, _ = _poked_log(T=4000)
    long_log = log
    for f in ("q", "dq", "tau_Nm", "wrench"):
        setattr(long_log, f, np.tile(getattr(log, f), (4, 1)))
    long_log.t = np.arange(16000) * 1e-3
    long = tmp_path / "long.csv"
    write_log(long_log, long)
    chunk = 500
    _peak_bytes(short, chunk)                  # warm-up: imports and compiled kernels are not the log
    p_short, p_long = _peak_bytes(short, chunk), _peak_bytes(long, chunk)
    assert p_long < 1.3 * p_short, (p_short, p_long)
    tracemalloc.start()                        # the same log at once: 4× the log, ≈ 4× the memory
    try:
        estimate(ROBOT, read_log(long))
        p_whole = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert p_whole > 3 * p_long


def test_compiled_kernels_match_the_numpy_reference(monkeypatch):
    """The compiled loops (numba; estimator.compiled) against the numpy forms: same flags and links, numbers to rounding."""
    from estimator import compiled

    assert compiled.available()                  # numba is a dependency (pyproject.toml)
    log, _ = _poked_log()
    fast = estimate(ROBOT, log)
    monkeypatch.setattr(compiled, "ENABLED", False)
    ref = estimate(ROBOT, log)
    for f in ("contact", "link", "reason"):
        assert np.array_equal(getattr(fast, f), getattr(ref, f)), f
    for f in ("alpha", "Fx", "Fz", "px", "pz", "rnorm", "condition", "residual"):
        x, y = getattr(fast, f), getattr(ref, f)
        assert np.array_equal(np.isnan(x), np.isnan(y)), f
        np.testing.assert_allclose(x, y, rtol=1e-9, atol=1e-12, err_msg=f)


def test_cli_error_after_some_chunks_leaves_no_output(tmp_path, capsys):
    """A bad field far into the log: exit 2 and one line naming it, no output, no temp file."""
    path = _write_poked_csv(tmp_path / "log.csv", 3000)
    frame = pd.read_csv(path)
    frame["tau1"] = frame["tau1"].astype(object)
    frame.loc[2700, "tau1"] = "oops"
    bad = tmp_path / "bad.csv"
    frame.to_csv(bad, index=False)
    out = tmp_path / "est.csv"
    code = main(["estimate", str(bad), "--out", str(out), "--chunk-samples", "100"])
    err = capsys.readouterr().err
    assert code == 2 and len(err.strip().splitlines()) == 1
    assert "line 2702" in err and "'tau1'" in err
    assert not out.exists() and not list(tmp_path.glob(".est.csv*"))


def test_round_significant_keeps_nine_digits():
    from estimator.outframe import round_significant

    rng = np.random.default_rng(3)
    x = rng.choice([-1, 1], 20000) * rng.uniform(1, 10, 20000) * 10.0 ** rng.integers(-13, 20, 20000)
    y = round_significant(x)
    assert np.all(np.abs(y - x) <= 5e-9 * np.abs(x))
    digits = [len(repr(abs(float(v))).split("e")[0].replace(".", "").strip("0")) for v in y]
    assert max(digits) <= 10 and np.mean(np.array(digits) <= 9) > 0.5
    special = np.array([np.nan, np.inf, -np.inf, 0.0])
    assert np.array_equal(round_significant(special), special, equal_nan=True)


@pytest.mark.parametrize("kw", [{"method": "paper"}, {"threshold": 0.3}])
def test_cusum_refuses_the_paper_rule(kw):
    """The CUSUM runs on the whitened residual; with the paper's ‖r‖ > ε it would be ignored
    silently, so it is refused by name."""
    log, _ = _poked_log()
    with pytest.raises(InputError, match="detector cusum"):
        estimate(ROBOT, log, detector="cusum", **kw)
