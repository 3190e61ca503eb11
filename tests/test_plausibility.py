"""Log plausibility: readable logs in the wrong units are refused or flagged."""

import math
import warnings

import numpy as np
import pytest

from userio.errors import InputError
from estimator.log import SensorLog, write_log
from estimator.log_reader import read_log
from estimator.plausibility import PlausibilityWarning, check_log, velocity_scale


def _swing(T=2000, dt=1e-3, amp=0.6, f_hz=1.5, noise=0.0, seed=0):
    """Fixed-base 2-link log: q = amp·sin(2πft) (rad), q̇ its exact derivative (rad/s)."""
    rng = np.random.default_rng(seed)
    t = np.arange(T) * dt
    w = 2 * math.pi * f_hz
    q = np.zeros((T, 5))
    dq = np.zeros((T, 5))
    q[:, 3] = amp * np.sin(w * t)
    q[:, 4] = 0.5 * amp * np.cos(w * t)
    dq[:, 3] = amp * w * np.cos(w * t)
    dq[:, 4] = -0.5 * amp * w * np.sin(w * t)
    q += noise * rng.standard_normal(q.shape)
    dq += noise * rng.standard_normal(dq.shape)
    return SensorLog(t=t, q=q, dq=dq, tau_Nm=np.zeros((T, 2)), wrench=np.zeros((T, 3)),
                     floating=False)


def _roundtrip(log, tmp_path):
    path = tmp_path / "log.csv"
    write_log(log, path)
    return read_log(path)


def test_consistent_log_passes_without_warnings(tmp_path):
    with warnings.catch_warnings():
        warnings.simplefilter("error", PlausibilityWarning)
        log = _roundtrip(_swing(), tmp_path)
    assert log.plausibility_warnings == []
    s, r = velocity_scale(log.t, log.q[:, 3:], log.dq[:, 3:])
    assert abs(s - 1) < 0.01 and r > 0.99


def test_static_noisy_log_is_not_a_false_alarm(tmp_path):
    log = _swing(amp=0.0, noise=1e-3)
    with warnings.catch_warnings():
        warnings.simplefilter("error", PlausibilityWarning)
        assert check_log(log) == []


def test_time_in_milliseconds_is_refused(tmp_path):
    log = _swing()
    log.t = log.t * 1e3
    with pytest.raises(InputError, match="milliseconds"):
        _roundtrip(log, tmp_path)


def test_angles_in_degrees_are_refused(tmp_path):
    log = _swing()
    log.q = np.degrees(log.q)
    with pytest.raises(InputError, match="degrees"):
        _roundtrip(log, tmp_path)


def test_large_angle_without_motion_is_refused_as_degrees(tmp_path):
    log = _swing(amp=0.0)
    log.q[:, 3] = 45.0                       # 45° written as 45 "rad"
    with pytest.raises(InputError, match=r"q1.*exceeds 2π.*degrees"):
        _roundtrip(log, tmp_path)


@pytest.mark.parametrize("dt, match", [(3600.0, "outside the plausible"), (1e-12, "µs or ns"),
                                       (2.0, "milliseconds")])
def test_implausible_sampling_period_is_refused(dt, match):
    log = _swing(amp=0.0, T=50)
    log.t = np.arange(50) * dt
    with pytest.raises(InputError, match=match):
        check_log(log)


def test_velocity_off_by_factor_three_is_a_warning():
    log = _swing()
    log.dq = log.dq * 3
    with pytest.warns(PlausibilityWarning, match="factor 0.33"):
        found = check_log(log)
    assert len(found) == 1 and log.plausibility_warnings == found


def test_sampling_period_limits_are_inclusive():
    for dt in (10e-6, 1.0):
        log = _swing(amp=0.0, T=20)
        log.t = np.arange(20) * dt
        assert check_log(log) == []
