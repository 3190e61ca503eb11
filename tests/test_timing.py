"""Sensor timing declarations (estimator.timing): the observer's quadrature matches how each force
channel was sampled. Reference: inverse dynamics on a 20 kHz grid of an analytic fast base bounce,
read out at 1 kHz as instantaneous states and interval-mean (or delayed) forces."""

import numpy as np
import pytest

from estimator import observer as O
from estimator import log_declarations, timing
from userio.errors import InputError
from estimator.robot import paper_leg
from estimator.synthetic import inverse_dynamics_log

ROBOT = paper_leg()
SUB = 20                      # fine steps per log sample
RATE_HZ = 1000.0


def _bounce(t):
    """Base: damped 10 Hz bounce (z 5 mm, x 2 mm, θ 0.02 rad), joints: slow swing; exact q̇, q̈."""
    w, beta = 2 * np.pi * 10.0, 4.0
    A = np.array([0.002, 0.005, 0.02])
    e, s, c = np.exp(-beta * t)[:, None], np.sin(w * t)[:, None], np.cos(w * t)[:, None]
    q = np.zeros((len(t), 5))
    dq, ddq = np.zeros_like(q), np.zeros_like(q)
    q[:, :3] = A * e * s
    dq[:, :3] = A * e * (w * c - beta * s)
    ddq[:, :3] = A * e * ((beta ** 2 - w ** 2) * s - 2 * beta * w * c)
    wj = 2 * np.pi * 1.0
    q[:, 3:] = np.array([0.9, -1.6]) + 0.2 * np.sin(wj * t)[:, None]
    dq[:, 3:] = 0.2 * wj * np.cos(wj * t)[:, None]
    ddq[:, 3:] = -0.2 * wj ** 2 * np.sin(wj * t)[:, None]
    return q, dq, ddq


@pytest.fixture(scope="module")
def fine():
    """Contact-free truth on the fine grid (0.5 s), generalized force τ_meas (T_fine, 5)."""
    t = np.arange(int(0.5 * RATE_HZ) * SUB + 1) / (RATE_HZ * SUB)
    q, dq, ddq = _bounce(t)
    log, _ = inverse_dynamics_log(ROBOT, t, q, dq, ddq, 2, 0.5, np.zeros(2))
    return t, q, dq, log.tau_meas


def _readout(fine, kind, delay_s=0.0):
    """1 kHz samples: states at t_k; forces instantaneous, interval mean (Simpson on the fine grid
    over (t_{k−1}, t_k]) or delayed by ``delay_s`` (linear interpolation of the fine truth)."""
    t, q, dq, tau = fine
    idx = np.arange(0, len(t), SUB)
    if kind == "instant":
        f = tau[idx]
    elif kind == "mean":
        from scipy.integrate import simpson
        f = tau[idx].copy()
        for k in range(1, len(idx)):
            seg = slice(idx[k - 1], idx[k] + 1)
            f[k] = simpson(tau[seg], x=t[seg], axis=0) * RATE_HZ
    else:
        f = np.stack([np.interp(t[idx] - delay_s, t, tau[:, j]) for j in range(tau.shape[1])], -1)
    return t[idx], q[idx], dq[idx], f


def _rmax(t, q, dq, f, spec):
    r = O.residual_offline(ROBOT, t, q, dq, f, 100.0, timing=spec)
    return np.linalg.norm(r[1:], axis=1).max()


def test_mean_sampled_forces_with_fast_bounce_need_the_mean_declaration(fine):
    t, q, dq, f = _readout(fine, "mean")
    assert np.abs(np.diff(f[:, 1])).max() * RATE_HZ > 100     # a fast transient: > 100 N/s
    wrong = _rmax(t, q, dq, f, None)
    right = _rmax(t, q, dq, f, timing.uniform("mean", 2))
    ref = _rmax(*_readout(fine, "instant"), None)           # instantaneous, declared as such
    print(f"max ||r||: mean read as instant {wrong:.3g}, declared mean {right:.3g}, "
          f"instant/instant {ref:.3g}")
    assert wrong > 0.06                                      # above the paper's ε: false contact
    assert right < 0.1 * wrong and right < 0.01              # model discretization level


def test_group_delay_declaration_realigns(fine):
    d = 0.0013
    t, q, dq, f = _readout(fine, "delay", d)
    wrong = _rmax(t, q, dq, f, None)
    right = _rmax(t, q, dq, f, timing.uniform(f"delay:{d}", 2))
    print(f"1.3 ms delay: undeclared {wrong:.3g}, declared {right:.3g}")
    assert wrong > 0.06 and right < 0.1 * wrong


def test_streaming_mean_equals_offline(fine):
    t, q, dq, f = _readout(fine, "mean")
    spec = [("mean", 0.0)] * 3 + [("instant", 0.0)] * 2
    r_off = O.residual_offline(ROBOT, t, q, dq, f, 100.0, timing=spec)
    obs = O.MomentumObserver(ROBOT, 1 / RATE_HZ, 100.0, timing=spec)
    r_str = np.array([obs.step(q[k], dq[k], f[k]) for k in range(len(t))])
    assert np.abs(r_off - r_str).max() < 1e-12
    with pytest.raises(InputError, match="timing"):
        O.MomentumObserver(ROBOT, 1 / RATE_HZ, 100.0, timing=timing.uniform("delay:0.001", 2))


def test_side_file_declaration_and_bad_values(tmp_path):
    log = tmp_path / "run.csv"
    side = tmp_path / "run.timing.toml"
    assert log_declarations.read_declaration(log, 2) is None
    side.write_text('[timing]\ndefault = "instant"\nwrench = "mean"\ntau2 = "delay:0.0005"\n')
    spec = log_declarations.read_declaration(log, 2)
    assert spec == [("mean", 0.0)] * 3 + [("instant", 0.0), ("delay", 0.0005)]
    assert "Fx=mean" in timing.describe(spec)
    side.write_text('[timing]\nwrenhc = "mean"\n')
    with pytest.raises(InputError, match="did you mean 'wrench'"):
        log_declarations.read_declaration(log, 2)
    side.write_text('[timing]\ntau = "delay:-1"\n')
    with pytest.raises(InputError, match="timing.tau"):
        log_declarations.read_declaration(log, 2)
    with pytest.raises(InputError, match="--timing"):
        timing.uniform("meen", 2)
