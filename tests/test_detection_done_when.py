"""Detection done-when on a simulated log: fast base motion, interval-mean force readings with
the issue's noise (FT σ 0.1 N, 0.1 N, 0.01 N·m; τ σ 0.005 N·m), correctly declared."""

import numpy as np
import pytest

from estimator import timing
from estimator.log import SensorLog
from estimator.estimate import estimate
from estimator.robot import paper_leg
from estimator.synthetic import inverse_dynamics_log, sinusoidal_motion

ROBOT = paper_leg()
SUB, RATE = 10, 1000.0
F_POKE = 3.0 * np.array([np.cos(2.0), np.sin(2.0)])     # the paper-size poke of the sample log


def _log(duration_s, poke_from_s=None, seed=0):
    tf = np.arange(int(duration_s * RATE) * SUB + 1) / (RATE * SUB)
    # base shaking at 10 Hz (z 2 mm, x 1 mm, θ 0.01 rad): the wrench swings ~1000 N/s
    q, dq, ddq = sinusoidal_motion(ROBOT, tf, frequency_Hz=10.0, amplitude_rad=(0.05, 0.05),
                                   base_amplitude=(0.001, 0.002, 0.01))
    active = np.zeros(len(tf), bool) if poke_from_s is None else tf >= poke_from_s
    fine, _ = inverse_dynamics_log(ROBOT, tf, q, dq, ddq, 2, 0.4, F_POKE, active=active)
    f = fine.tau_meas
    idx = np.arange(0, len(tf), SUB)
    c = np.cumsum(np.r_[np.zeros((1, 5)), 0.5 * (f[1:] + f[:-1])], axis=0)   # trapezoid integral
    mean = f[idx].copy()
    mean[1:] = (c[idx[1:]] - c[idx[:-1]]) / SUB
    rng = np.random.default_rng(seed)
    mean += rng.standard_normal(mean.shape) * np.r_[0.1, 0.1, 0.01, 0.005, 0.005]
    log = SensorLog(t=tf[idx], q=q[idx], dq=dq[idx], tau_Nm=mean[:, 3:], wrench=mean[:, :3])
    log.timing = timing.uniform("mean", 2)
    return log


@pytest.fixture(scope="module")
def quiet_log():
    return _log(20.0)


def test_contact_free_fast_motion_flags_under_0p1_percent(quiet_log):
    est = estimate(ROBOT, quiet_log)
    frac = est.contact.mean()
    wrong = estimate(ROBOT, quiet_log, timing="instant").contact.mean()
    paper = estimate(ROBOT, quiet_log, threshold=0.06).contact.mean()
    print(f"flagged: declared mean {frac:.2e}, mis-declared instant {wrong:.2e}, paper ε {paper:.2e}")
    assert est.info["timing_source"] == "log declaration"
    assert frac < 1e-3
    assert wrong > 10 * max(frac, 1e-4)          # what a wrong declaration costs


def test_false_alarm_rate_matches_a_measurable_target(quiet_log):
    a = 2e-2
    est = estimate(ROBOT, quiet_log, false_alarm_rate=(a, "sample"))
    frac = est.contact[200:].mean()
    aa = np.exp(-0.1)
    se = np.sqrt(a / (len(est.t) / ((1 + aa) / (1 - aa))))
    print(f"target {a:g}/sample, flagged {frac:.3g} ± {se:.2g}")
    assert abs(frac - a) < 5 * se


def test_paper_size_poke_detected_within_20ms():
    log = _log(1.0, poke_from_s=0.5, seed=1)
    est = estimate(ROBOT, log)
    first = est.t[np.flatnonzero(est.contact & (est.t >= 0.5))[0]]
    assert not est.contact[est.t < 0.5].any()
    print(f"3 N poke detected after {1e3 * (first - 0.5):.1f} ms; link {est.link[est.t > 0.6][0]}")
    assert first - 0.5 <= 0.020
    assert np.all(est.link[est.t > 0.6] == 2)
