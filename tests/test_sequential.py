"""CUSUM on the whitened residual (estimator.sequential): the recursion against a plain loop, chunked
runs equal to one-shot runs, the spectral model against the closed-form covariance, the measured
false-alarm rate against its target, and small persistent pokes against the chi-square detector."""

import json

import numpy as np
import pytest

from estimator import cusum_calibration as C
from estimator import noise as Nz
from estimator import sequential as S
from estimator import timing
from userio.errors import InputError
from estimator.estimate import estimate
from estimator.log import SensorLog
from estimator.robot import paper_leg

from test_noise_detection import NOISE, _noisy

ROBOT = paper_leg()
Q0 = np.array([0.0, 0.0, 0.0, 0.9, -1.6])


def _loop(s, n, h, delta):
    """Reference: g = min(h, max(0, g + s − n − δ)), alarm from g = h until g = 0, in floats."""
    g, on, out = 0.0, False, []
    for x in s:
        g = g + x - n - delta
        if not on and g >= h:
            on, g = True, h
        elif on and g <= 0:
            on, g = False, 0.0
        g = min(h, max(0.0, g))
        out.append(on)
    return np.array(out)


def _stat(T, seed, shift_every=None):
    rng = np.random.default_rng(seed)
    s = rng.chisquare(5, T)
    if shift_every:           # persistent shifts so that alarms start and end many times
        s += 12.0 * ((np.arange(T) // shift_every) % 3 == 1)
    return s


def test_cusum_matches_the_plain_recursion():
    s = _stat(20_000, 1, shift_every=700)
    alarm, st = S.cusum(s, 5, 40.0, 5.0)
    ref = _loop(s, 5, 40.0, 5.0)
    onsets = np.count_nonzero(np.diff(ref.astype(int)) == 1)
    assert onsets > 5                  # the comparison exercises starts and ends
    assert np.array_equal(alarm, ref)
    assert st.alarm == ref[-1]


@pytest.mark.parametrize("cuts", [(1,), (7, 8, 9), (333, 5000, 5001, 12_345), tuple(range(0, 20_000, 997))])
def test_cusum_chunked_equals_one_shot(cuts):
    s = _stat(20_000, 2, shift_every=450)
    whole, end = S.cusum(s, 5, 35.0)
    parts, state = [], None
    for a, b in zip((0, *cuts), (*cuts, len(s))):
        al, state = S.cusum(s[a:b], 5, 35.0, state=state)
        parts.append(al)
    assert np.array_equal(np.concatenate(parts), whole)
    assert state == end


def test_cusum_bad_parameters_are_input_errors():
    with pytest.raises(InputError, match="threshold"):
        S.cusum(np.ones(3), 5, 0.0)
    with pytest.raises(InputError, match="drift"):
        S.cusum(np.ones(3), 5, 10.0, drift=-1.0)
    with pytest.raises(InputError, match="detector"):
        t, q, dq, dqm, tau = _noisy(500, 1)
        estimate(ROBOT, SensorLog(t=t, q=q, dq=dqm, tau_Nm=tau[:, 3:], wrench=tau[:, :3]),
                 detector="glr")


@pytest.mark.parametrize("declared", ["instant", "mean"])
def test_spectral_model_integrates_to_the_closed_form_covariance(declared):
    """(1/2π)∫ S_z(ω) dω = I: the transfer-function model of the residual and the closed-form
    Lyapunov covariance are two derivations of the same noise; they must agree on every row."""
    tim = timing.uniform(declared, 2)
    a, b, B0, B1 = Nz.filter_terms(ROBOT, Q0, 0 * Q0, NOISE, 100.0, 1e-3, tim)
    R = Nz.residual_covariance(ROBOT, Q0, 0 * Q0, NOISE, 100.0, 1e-3, tim)[0]
    Sz = C.spectral_matrix(a, b, B0[0], B1[0], R)
    assert np.allclose(Sz.mean(axis=0), np.eye(5), atol=1e-6)
    lam = C.whitened_spectrum(a, b, B0[0], B1[0], R)
    # the correlated residual has a smaller large-deviation exponent than independent samples
    th = C.exponent(lam, 5, 5.0)
    th_iid = C.exponent(np.ones((16, 5)), 5, 5.0)
    # Wald's root for independent χ²_5: −(5/2) log(1 − 2θ) = 10 θ
    assert -2.5 * np.log1p(-2 * th_iid) == pytest.approx(10 * th_iid, rel=1e-9)
    assert th < th_iid / 5


@pytest.mark.slow
def test_cusum_false_alarm_rate_matches_target():
    """600 s of contact-free noise (static leg, velocity noise, instantaneous readings): the number
    of alarm onsets at 0.1/s is the target within 3 Poisson σ."""
    t, q, dq, dqm, tau = _noisy(600_000, 21)
    log = SensorLog(t=t, q=q, dq=dqm, tau_Nm=tau[:, 3:], wrench=tau[:, :3])
    est = estimate(ROBOT, log, noise=NOISE, false_alarm_rate=(0.1, "s"), detector="cusum")
    c = est.contact[200:]
    k = int(np.count_nonzero(np.diff(c.astype(np.int8)) == 1))
    expected = 0.1 * len(c) * 1e-3
    print(f"CUSUM at 0.1/s: {k} alarms, {expected:.1f} expected; h = {est.info['cusum_threshold']:.1f}")
    assert est.info["detector"].startswith("CUSUM")
    assert abs(k - expected) < 3 * np.sqrt(expected)


def _paper_leg_model():
    tim = timing.uniform("mean", 2)
    a, b, B0, B1 = Nz.filter_terms(ROBOT, Q0, 0 * Q0, NOISE, 100.0, 1e-3, tim)
    R = Nz.residual_covariance(ROBOT, Q0, 0 * Q0, NOISE, 100.0, 1e-3, tim)[0]
    return a, b, B0[0], B1[0], R


def test_cusum_threshold_meets_its_rate_on_an_independent_synthetic_run():
    """The threshold for 1e-3 alarm onsets per sample, on 1.5e6 samples of the residual model drawn
    with a seed other than the calibration's: the onset count is the target within 3σ, σ the
    Poisson error of the count and the calibration's own stated error combined."""
    model = _paper_leg_model()
    cal = C.calibrate_model(*model)
    alpha, T = 1e-3, 1_500_000
    h = cal.threshold(alpha)
    assert cal.rate(h) == pytest.approx(alpha, rel=1e-6)
    s = C.synthetic_statistic(*model, T, seed=99)
    alarm, _ = S.cusum(s, 5, h, cal.drift)
    k = int(np.count_nonzero(np.diff(alarm.astype(np.int8)) == 1) + alarm[0])
    expected = alpha * T
    sigma = expected * np.hypot(1 / np.sqrt(expected), cal.rate_rel_error(h))
    print(f"h = {h:.2f}: {k} onsets, {expected:.0f} expected, σ = {sigma:.0f}, "
          f"calibration error {100 * cal.rate_rel_error(h):.1f} %")
    assert cal.rate_rel_error(h) < 0.03
    assert abs(k - expected) < 3 * sigma


def test_cusum_calibration_is_seeded_and_its_rate_decreases_with_the_threshold():
    """Two calibrations of the same model are identical (seeded, cached or not); the rate falls
    monotonically with h over the whole range down to the splitting floor and beyond it
    (θ* extrapolation), and the thresholds for 1e-2 … 1e-9 per sample increase."""
    model = _paper_leg_model()
    a = C.calibrate(model, 5, samples=200_000, particles=4000, rate_floor=1e-6)
    b = C.calibrate(model, 5, samples=200_000, particles=4000, rate_floor=1e-6)
    assert np.array_equal(a.log_nu, b.log_nu) and a.retrigger == b.retrigger
    hs = np.linspace(0.5, 2 * a.h_grid[-1], 400)
    assert np.all(np.diff(a.rate(hs)) <= 0)
    th = [a.threshold(x) for x in (1e-2, 1e-3, 1e-4, 1e-6, 1e-9)]
    assert np.all(np.diff(th) > 0)
    # beyond the floor the slope is θ*
    h1, h2 = a.h_grid[-1] + 10, a.h_grid[-1] + 60
    nu1, nu2 = a._nu(h1), a._nu(h2)
    assert np.log(nu1 / nu2) == pytest.approx(50 * a.theta, rel=1e-9)


def test_compiled_splitting_stage_agrees_with_the_numpy_form():
    """The numba stage (one particle at a time, its own seeded generator) and the vectorized numpy
    form run the same particles from the same states: the fraction reaching the next level, the
    mean steps and the mean alarm duration (capped run) agree within 4 sampling σ."""
    if not C._compiled():
        pytest.skip("numba not installed: only the numpy form exists")
    a, b, B0, B1, R = _paper_leg_model()
    At, C0, C1, _ = C.state_model(a, b, B0, B1, R)
    z, w = C._free_run(a, b, B0, B1, R, 20_000, np.random.default_rng(5))
    idx = np.random.default_rng(6).integers(0, 20_000, 6000)
    g0 = np.full(idx.size, 10.0)
    res = {}
    for name, fn in (("numba", C._run_stage), ("numpy", C._stage)):
        up = fn(z[idx], w[idx], g0, 15.0, At, C0, C1, 5, 5.0, np.random.default_rng(7))
        dur = fn(z[idx], w[idx], g0, np.inf, At, C0, C1, 5, 5.0, np.random.default_rng(8), cap=10.0)
        res[name] = (up[1].mean(), up[5], dur[5])
    p1, p2 = res["numba"][0], res["numpy"][0]
    assert 0.02 < p1 < 0.98
    assert abs(p1 - p2) < 4 * np.sqrt(2 * p1 * (1 - p1) / idx.size)
    for j in (1, 2):
        x1, x2 = res["numba"][j], res["numpy"][j]
        assert abs(x1.mean() - x2.mean()) < 4 * np.hypot(x1.std(), x2.std()) / np.sqrt(idx.size)


def test_warm_compiles_the_calibration_loops():
    assert C.warm() == bool(C._compiled())


def test_onset_counts_equal_the_detector():
    """The compiled onset counter (several thresholds at once) counts what ``cusum`` flags."""
    s = _stat(50_000, 3, shift_every=600)
    hs = np.array([5.0, 20.0, 35.0, 80.0])
    got = C.onset_counts(s, 5, hs, 5.0)
    for hh, k in zip(hs, got):
        alarm, _ = S.cusum(s, 5, hh, 5.0)
        assert k == int(np.count_nonzero(np.diff(alarm.astype(np.int8)) == 1) + alarm[0])
    assert got[0] > got[-1] > 0


def _held_pokes(magnitude, n_pokes=40, on=300, period=800, seed=4):
    from torquebench.reports.detection import simulated_log

    T = period * n_pokes + period // 2
    rng = np.random.default_rng(seed)
    starts = np.arange(period // 2, T - on, period)
    F = np.zeros((T, 2))
    for s0, ang in zip(starts, rng.uniform(0, 2 * np.pi, len(starts))):
        F[s0:s0 + on] = magnitude * np.array([np.cos(ang), np.sin(ang)])
    return simulated_log(ROBOT, T / 1000.0, "static", force_N=F, seed=seed + 1), starts, on


def test_cusum_detects_small_persistent_pokes_sooner_than_chi2():
    """0.02 N held for 300 ms on the paper leg's noise, both at one false alarm per hour: the CUSUM
    detects more of the pokes and its median delay (misses counted as 300 ms) is shorter."""
    log, starts, on = _held_pokes(0.02)
    delays = {}
    for det in ("chi2", "cusum"):
        c = estimate(ROBOT, log, detector=det).contact[starts[:, None] + np.arange(on)[None]]
        delays[det] = np.where(c.any(axis=1), np.argmax(c, axis=1), on)
        print(det, "detected", (delays[det] < on).mean(), "median delay ms", np.median(delays[det]))
    assert (delays["cusum"] < on).mean() > (delays["chi2"] < on).mean()
    assert np.median(delays["cusum"]) < np.median(delays["chi2"])


def test_estimate_command_takes_the_detector(capsys, tmp_path):
    from torquebench.cli import main

    t, q, dq, dqm, tau = _noisy(3000, 5)
    log = SensorLog(t=t, q=q, dq=dqm, tau_Nm=tau[:, 3:], wrench=tau[:, :3], floating=True)
    from estimator.sim.output import log_csv

    path = tmp_path / "quiet.csv"
    path.write_text(log_csv(log))
    code = main(["estimate", str(path), "--detector", "cusum", "--velocity-sigma", "0.002", "--json"])
    out = json.loads(capsys.readouterr().out)
    assert code == 0 and out["detector"].startswith("CUSUM") and out["cusum_threshold"] > 0
    assert out["contact_samples"] == 0
    # the calibration's 1σ on the rate it sets (issue 12's error-estimate convention)
    assert 0 < out["false_alarm_rate_per_s_error_estimate"] < 0.2 * out["false_alarm_rate_per_s"]
    assert "splitting" in out["false_alarm_rate_per_s_error_method"]


@pytest.mark.parametrize("theta", [0.0, 1.0, -0.5])
def test_arma_theta_is_recovered_from_the_lag1_autocorrelation(theta):
    from scipy.signal import lfilter

    a = np.exp(-0.1)
    x = lfilter([1.0, theta], [1.0, -a], np.random.default_rng(3).standard_normal(400_000))[500:]
    rho1 = np.corrcoef(x[1:], x[:-1])[0, 1]
    assert C.arma_theta(a, rho1) == pytest.approx(theta, abs=0.08)


def test_cusum_with_a_quiet_window():
    t, q, dq, dqm, tau = _noisy(60_000, 8)
    log = SensorLog(t=t, q=q, dq=dqm, tau_Nm=tau[:, 3:], wrench=tau[:, :3])
    est = estimate(ROBOT, log, quiet_window=(1.0, 30.0), detector="cusum")
    assert "quiet stretch" in est.info["cusum_calibration"]
    assert est.contact.mean() < 1e-3


def test_cusum_on_an_extreme_statistic_saturates_without_overflow():
    """A 100 N contact gives s ~ 1e12 (and a skipped sample NaN): the increments are clipped to the
    cap, so the fixed-point sums cannot overflow; the alarm starts at the first sample and ends
    about h/δ samples after the contact (the drain at −δ per sample with s = 0)."""
    s = np.r_[np.full(1000, 1e12), np.nan, np.full(999, 1e12), np.zeros(200)]
    alarm, st = S.cusum(s, 5, 100.0, 5.0)
    assert alarm[:2000].all()
    end = 2000 + np.argmin(alarm[2000:])
    assert end - 2000 == 9             # g = 100 − 10 k with s = 0 is back at 0 on the 10th sample
    assert not st.alarm and st.g == 0


def test_cusum_in_chunks_equals_one_shot_on_a_held_poke_log():
    """The CUSUM as estimate() runs it, on a log with held pokes, fed in chunks of 1234 samples
    (state and calibration carried by the stream): the same alarms as in one call."""
    log, starts, on = _held_pokes(0.05, n_pokes=6)
    whole = estimate(ROBOT, log, detector="cusum")
    chunked = estimate(ROBOT, log, detector="cusum", chunk_samples=1234)
    assert whole.contact.any()
    assert np.array_equal(chunked.contact, whole.contact)
    assert chunked.info["cusum_threshold"] == whole.info["cusum_threshold"]
