"""`acquire`: every figure of a load step (mean reading, noise, settling step) carries a standard
error that accounts for the autocorrelation of the samples (effective sample size n/τ)."""

import io
import json
import sys

import numpy as np
import pytest

from calibration.acquire import autocorr_times, window_stats
from pty_device import pty_device
from torquebench.cli import main


def ar1(rng, a: float, n: int, sigma_innov: float = 1.0, burn: int = 2000) -> np.ndarray:
    """x_k = a x_{k−1} + e_k: stationary variance σ²/(1 − a²), τ = (1 + a)/(1 − a)."""
    from scipy.signal import lfilter          # here, not at collection: scipy.signal costs ≈ 1 CPU-s

    return lfilter([1.0], [1.0, -a], rng.normal(0.0, sigma_innov, n + burn))[burn:]


def test_autocorr_time_of_ar1_matches_the_closed_form():
    rng = np.random.default_rng(1)
    for a in (0.0, 0.5, 0.9):
        tau = np.mean([autocorr_times(ar1(rng, a, 20000))[0] for _ in range(20)])
        assert tau == pytest.approx(max((1 + a) / (1 - a), 1.0), rel=0.1)


@pytest.mark.parametrize("a", [0.0, 0.9])
def test_reading_and_noise_standard_errors_are_honest(a):
    """Over 300 windows of 4000 samples the z-scores (estimate − truth)/SE have unit spread; the
    white-noise formula σ/√n would be √19 ≈ 4.4× too small at a = 0.9."""
    rng = np.random.default_rng(2)
    true_sd = 1.0 / np.sqrt(1 - a * a)
    z_mean, z_std, naive = [], [], []
    for _ in range(300):
        x = 1000.0 + ar1(rng, a, 4000)
        s = window_stats(x)
        z_mean.append((s["mean"] - 1000.0) / s["mean_se"])
        z_std.append((s["std"] - true_sd) / s["std_se"])
        naive.append((s["mean"] - 1000.0) / (s["std"] / np.sqrt(x.size)))
        assert s["autocorr_resolved"]
    assert 0.85 < np.std(z_mean) < 1.15
    assert 0.85 < np.std(z_std) < 1.15
    if a > 0:
        assert np.std(naive) > 3.5


def test_settle_test_accepts_correlated_noise_and_still_catches_a_drift():
    rng = np.random.default_rng(3)
    windows = [1000.0 + ar1(rng, 0.9, 4000) for _ in range(200)]
    settled = np.mean([window_stats(x)["settled"] for x in windows])
    # the former white-noise limit 8σ/√W calls a third of these still-settling
    old = np.mean([abs(x[2000:].mean() - x[:2000].mean()) <= 8 * x.std(ddof=1) / np.sqrt(4000) for x in windows])
    assert settled >= 0.98 and old < 0.8
    # a drift of 3 noise σ across the window is not absorbed into a long "correlation time"
    sd = 1.0 / np.sqrt(1 - 0.81)
    ramp = windows[0] + np.linspace(0.0, 3 * sd, 4000)
    s = window_stats(ramp)
    assert not s["settled"] and s["step"] > 4 * s["step_se"]


def test_a_window_too_short_for_the_correlation_is_flagged():
    rng = np.random.default_rng(4)
    s = window_stats(ar1(rng, 0.97, 800))           # τ ≈ 66: 12 independent samples
    assert not s["autocorr_resolved"] and "underestimated" in s["mean_se_method"]


@pytest.fixture
def ar1_device():
    with pty_device(20000.0, a=0.8, block=200) as tty:
        yield tty


def test_acquire_guided_json_carries_error_estimates(ar1_device, tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(sys, "stdin", io.StringIO("\n\n"))
    rc = main(["acquire", "--port", ar1_device, "--out", str(tmp_path / "g.raw"), "--channels", "2",
               "--guided", "0,100", "--rate-hz", "2000", "--settle-s", "0.05", "--window-s", "1.0",
               "--tolerance-counts", "0.01", "--json"])
    assert rc == 0
    res = json.loads(capsys.readouterr().out)
    assert len(res["load_steps"]) == 2
    tau_true = (1 + 0.8) / (1 - 0.8)
    for s in res["load_steps"]:
        for fig in ("reading_counts", "noise_std_counts", "settle_step_counts"):
            assert s[f"{fig}_error_estimate"] > 0 and "1σ" in s[f"{fig}_error_method"]
        assert s["settled"] and s["n_samples"] == 2000
        assert abs(s["reading_counts"] - 20000.0) < 5 * s["reading_counts_error_estimate"]
        # the standard error is √τ (= 3) times the white-noise one σ/√n
        white = s["noise_std_counts"] / np.sqrt(s["n_samples"])
        assert 0.8 * np.sqrt(tau_true) < s["reading_counts_error_estimate"] / white < 1.2 * np.sqrt(tau_true)
        assert s["noise_std_counts"] == pytest.approx(20.0 / np.sqrt(1 - 0.64), rel=4 * s["noise_std_counts_error_estimate"] / s["noise_std_counts"])
    assert sum("exceeds --tolerance-counts 0.01" in w for w in res["warnings"]) == 2


def test_acquire_guided_text_shows_plus_minus(ar1_device, tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(sys, "stdin", io.StringIO("\n\n"))
    rc = main(["acquire", "--port", ar1_device, "--out", str(tmp_path / "g.raw"), "--channels", "2",
               "--guided", "0,100", "--rate-hz", "2000", "--settle-s", "0.05", "--window-s", "1.0"])
    assert rc == 0
    out = capsys.readouterr().out
    lines = [ln for ln in out.splitlines() if ln.startswith(("0 g load", "100 g load"))]
    assert len(lines) == 2 and all(ln.count("±") == 3 and "settled" in ln for ln in lines)
